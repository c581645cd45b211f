#!/usr/bin/env python3
"""Every relative link in the given Markdown files resolves: the file or folder exists and a
``#anchor`` names one of the target's headings (GitHub's slugs). Links in code blocks and to
URLs are skipped. Standard library only.

    python3 scripts/check_doc_links.py README.md docs/*.md    # exit 1, listing each broken link
    python3 scripts/check_doc_links.py $(git ls-files '*.md')
"""
import os, re, sys, unicodedata

def slugify(heading):
    # GitHub's: lower-case, drop punctuation except - and _, spaces to -
    h = re.sub(r"<[^>]+>", "", heading).strip().lower()
    h = "".join(c for c in h if c.isalnum() or c in " -_" or unicodedata.category(c).startswith("L"))
    return h.replace(" ", "-")

def anchors(path):
    out, seen = set(), {}
    in_code = False
    for line in open(path, encoding="utf-8"):
        if line.startswith("```"):
            in_code = not in_code
        if in_code:
            continue
        m = re.match(r"#{1,6} (.*)", line)
        if m:
            s = slugify(m.group(1)); n = seen.get(s, 0); seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out

bad = 0
for md in sys.argv[1:]:
    text = open(md, encoding="utf-8").read()
    text = re.sub(r"```.*?```", "", text, flags=re.S)          # no links in fenced code
    text = re.sub(r"(?m)^(    |\t).*$", "", text)               # nor in indented code
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, frag = target.partition("#")
        full = os.path.normpath(os.path.join(os.path.dirname(md), path)) if path else md
        if not os.path.exists(full):
            print(f"{md}: {target}: no {full}"); bad += 1; continue
        if frag and full.endswith(".md") and frag not in anchors(full):
            print(f"{md}: {target}: no anchor #{frag} in {full}"); bad += 1
print(f"{len(sys.argv) - 1} files, {bad} broken links")
sys.exit(1 if bad else 0)
