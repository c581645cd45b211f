#!/usr/bin/env python3
"""Checks that each crate of the workspace packages completely, without publishing anything:
`cargo package --list` of every publishable crate must hold its manifest, README and licence
files, every source file under src/, every file the sources pull in at compile time
(include_str!, include_bytes!, include_wgsl!), every declared bench, test and example, and
nothing of the checkout's own state (.deps/, runs/, target/, docs/); and that the library
without its default `cli` feature (what the Python extension and library users build) depends on
none of the command line's crates. Exits 1 with one line per problem. (The packaged tests that
play Gymnasium through `scripts/` and the set-up's venv run only in the repository.)"""

import pathlib
import re
import subprocess
import sys
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[1]
INCLUDE = re.compile(r'include_(?:str|bytes|wgsl)!\(\s*"([^"]+)"\s*\)')
NEVER = (".deps/", "runs/", "target/", "docs/", "python/")
# The `cli` feature's crates: none may reach the library built without it, even indirectly.
CLI_ONLY = {"anyhow", "clap", "clap_derive", "indicatif", "plotters", "resvg", "signal-hook", "dhrl-charts", "dhrl-tabular"}


def packaged(crate: pathlib.Path) -> set[str]:
    done = subprocess.run(
        ["cargo", "package", "--list", "--allow-dirty", "--manifest-path", str(crate / "Cargo.toml")],
        capture_output=True, text=True, cwd=ROOT,
    )
    if done.returncode != 0:
        sys.exit(f"check_package: cargo package --list failed for {crate.name}:\n{done.stderr}")
    return set(done.stdout.split())


def problems(crate: pathlib.Path) -> list[str]:
    manifest = tomllib.loads((crate / "Cargo.toml").read_text())
    package = manifest["package"]
    files = packaged(crate)
    name = package["name"]
    found: list[str] = []
    for key in ("description", "license", "readme", "keywords", "categories"):
        if key not in package:
            found.append(f"{name}: Cargo.toml sets no `{key}`")
    # crates.io's rules: at most five keywords, each at most 20 ASCII characters.
    keywords = package.get("keywords", [])
    if len(keywords) > 5:
        found.append(f"{name}: {len(keywords)} keywords; crates.io takes at most 5")
    found += [f"{name}: keyword {k!r} is longer than crates.io's 20 characters" for k in keywords if len(k) > 20]
    needed = {"Cargo.toml", "LICENSE-MIT", "LICENSE-APACHE", package.get("readme", "README.md")}
    if (crate / "build.rs").is_file():
        needed.add("build.rs")
    for source in (crate / "src").rglob("*.rs"):
        needed.add(source.relative_to(crate).as_posix())
    for source in [*(crate / "src").rglob("*.rs"), *(crate / "tests").rglob("*.rs"), *(crate / "benches").rglob("*.rs")]:
        for target in INCLUDE.findall(source.read_text()):
            path = (source.parent / target).resolve()
            needed.add(path.relative_to(crate.resolve()).as_posix())
    for kind, folder in (("bench", "benches"), ("test", "tests"), ("example", "examples")):
        for target in manifest.get(kind, []):
            needed.add(target.get("path", f"{folder}/{target['name']}.rs"))
    for test in (crate / "tests").glob("*.rs"):
        needed.add(test.relative_to(crate).as_posix())
    found += [f"{name}: {path} is not in the package" for path in sorted(needed - files)]
    found += [f"{name}: {path} should not be in the package" for path in sorted(files) if path.startswith(NEVER)]
    print(f"check_package: {name}: {len(files)} files", file=sys.stderr)
    return found


def lean_library() -> list[str]:
    done = subprocess.run(
        ["cargo", "tree", "-p", "dhrl", "--no-default-features", "--edges", "normal", "--prefix", "none"],
        capture_output=True, text=True, cwd=ROOT,
    )
    if done.returncode != 0:
        sys.exit(f"check_package: cargo tree failed:\n{done.stderr}")
    crates = {line.split()[0] for line in done.stdout.splitlines() if line.strip()}
    print(f"check_package: dhrl without `cli`: {len(crates)} crates", file=sys.stderr)
    return [f"dhrl without `cli` still depends on {name}" for name in sorted(crates & CLI_ONLY)]


def main() -> None:
    crates = [ROOT, ROOT / "crates" / "dhrl-charts", ROOT / "crates" / "dhrl-tabular"]
    found = [p for crate in crates for p in problems(crate)] + lean_library()
    for problem in found:
        print(f"check_package: {problem}", file=sys.stderr)
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
