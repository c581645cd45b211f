#!/usr/bin/env python3
"""Turns the logs of the paper authors' released code (GitHub JongsooLee/DHRL, run outside this
repository) into dhrl run folders, so that `dhrl report` and `dhrl plot` put them beside dhrl's
own runs (docs/results/authors-side-by-side.md).

Their code writes, per run, `{mode}_{agent}_{env}_delay{Δ}_seed{s}.txt` (one
`<total_step> <mean eval return>` line per evaluation) and a `.summary.json` beside it
(`environment_steps`, `gradient_updates`, `wall_clock_seconds`, `agent_type`, `env_name`,
`obs_delayed_steps`, `random_seed`). Each becomes OUT/<task>-d2hpg-d<Δ>-s<seed>/ with

  config.toml         the run as dhrl's authors protocol describes it: task, Δ, seed, steps,
                      the random phase (--start-step) and evaluation interval given here, and
                      the algorithm their agent type is (bpql -> d2hpg, sac -> d2hpg-sac,
                      naive -> d2hpg-naive, principled -> d2hpg-principled, whose authors'
                      protocol is their form: identity g, clamped-exp σ, mean NLL, clipping);
  evals.csv           step, wall seconds, mean return; their code logs neither the return's
                      spread over episodes (written nan) nor per-evaluation times (the run's
                      wall seconds spread over the evaluations in proportion to their step);
  implementation.txt  the code they came from, which `dhrl report` keeps apart from dhrl's.

Usage: scripts/authors_logs_to_runs.py LOG_DIR... --out OUT --start-step N --eval-every N
       --max-step N [--commit 296ac7b]

`steps` is what the run reached (a run stopped early by SIGINT still writes its summary), the
λ schedule's budget (`lifting_budget`) the --max-step it was started with.
"""
import argparse
import json
import pathlib
import re
import sys

TASKS = {
    "InvertedPendulum-v4": "inverted-pendulum",
    "HalfCheetah-v4": "half-cheetah",
    "Hopper-v4": "hopper",
    "Walker2d-v4": "walker2d",
    "Ant-v4": "ant",
    "Humanoid-v4": "humanoid",
}
AGENTS = {"bpql": "d2hpg", "sac": "d2hpg-sac", "naive": "d2hpg-naive",
          "principled": "d2hpg-principled"}
LOG = re.compile(r"^(?P<mode>[a-z]+)_(?P<agent>[a-z]+)_(?P<env>.+)_delay(?P<delay>\d+)_seed(?P<seed>\d+)\.txt$")


def convert(log: pathlib.Path, out: pathlib.Path, args) -> pathlib.Path:
    name = LOG.match(log.name)
    if not name:
        sys.exit(f"{log}: not a log of the authors' code ({{mode}}_{{agent}}_{{env}}_delay{{Δ}}_seed{{s}}.txt)")
    env, agent = name["env"], name["agent"]
    if env not in TASKS:
        sys.exit(f"{log}: task {env} is not one of {', '.join(TASKS)}")
    if agent not in AGENTS:
        sys.exit(f"{log}: agent type {agent} has no dhrl counterpart under the authors' protocol "
                 f"(accepted: {', '.join(AGENTS)})")
    summary_path = log.with_suffix(".summary.json")
    if not summary_path.is_file():
        sys.exit(f"{log}: no {summary_path.name} beside it (the run did not finish)")
    summary = json.loads(summary_path.read_text())
    rows = []
    for line in log.read_text().splitlines():
        if line.strip():
            step, mean = line.split()
            rows.append((int(step), float(mean)))
    if not rows:
        sys.exit(f"{log}: no evaluation")
    steps = int(summary["environment_steps"])
    wall = float(summary["wall_clock_seconds"])
    task, delay, seed = TASKS[env], int(name["delay"]), int(name["seed"])
    run = out / f"{task}-{AGENTS[agent]}-d{delay}-s{seed}"
    run.mkdir(parents=True, exist_ok=False)
    (run / "config.toml").write_text(
        "\n".join([
            'protocol = "authors"',
            f'task = "{task}"',
            f"steps = {steps}",
            f"seed = {seed}",
            f"warmup_steps = {args.start_step}",
            f"eval_every = {args.eval_every}",
            "",
            "[delay]",
            f"observation_delay = {delay}",
            "",
            "[algo]",
            f'name = "{AGENTS[agent]}"',
            *([f"lifting_budget = {args.max_step}"] if agent != "naive" else []),
            "",
        ])
    )
    with open(run / "evals.csv", "w") as evals:
        evals.write("step,wall_seconds,return_mean,return_std,length_mean,episodes\n")
        for step, mean in rows:
            evals.write(f"{step},{wall * step / steps:.1f},{mean},nan,nan,nan\n")
    (run / "implementation.txt").write_text(
        f"authors' code, JongsooLee/DHRL {args.commit}\n"
        f"converted from {log.name}: {summary['gradient_updates']} updates, "
        f"{summary['episodes']} episodes, {wall:.0f} s\n"
    )
    return run


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="+", type=pathlib.Path, help="log folders (their --log-dir)")
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--start-step", required=True, type=int, help="the runs' --start-step")
    parser.add_argument("--eval-every", required=True, type=int, help="the runs' --eval-freq")
    parser.add_argument("--max-step", required=True, type=int,
                        help="the runs' --max-step: the budget their λ schedule spans, also for a run cut short")
    parser.add_argument("--commit", default="296ac7b", help="the commit of their code that ran")
    args = parser.parse_args()
    logs = sorted(p for d in args.logs for p in d.glob("*.txt") if LOG.match(p.name))
    if not logs:
        sys.exit(f"no log of the authors' code under {', '.join(map(str, args.logs))}")
    for log in logs:
        print(convert(log, args.out, args))


if __name__ == "__main__":
    main()
