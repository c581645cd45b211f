"""Drive a real Gymnasium task under observation delay with a policy that `dhrl export` wrote.

    python examples/deploy_gymnasium.py EXPORT_DIR [--episodes 10] [--seed 0] [--dhrl BIN --run RUN]

The environment is Gymnasium's own (`gymnasium.make(<the manifest's id>)`, e.g.
`InvertedPendulum-v4`) wrapped in Gymnasium's `DelayObservation(env, delay=Δ)`: after `reset`
and each `step` it returns the observation of Δ steps before (zeros while there is none). The
agent is the exported policy through `dhrl.deploy.DelayedPolicy` alone (numpy and
onnxruntime): at decision `t ≥ Δ` the observation just returned is `s_{t-Δ}`, observed as such;
the runtime executes the warm-up for `t < Δ` and keeps the action history. With `--dhrl` and
`--run`, `dhrl eval` of the run the policy came from is printed beside (the same policy in
dhrl's own simulator; the episodes' initial states differ, so the returns agree as far as the
policy is consistent across them).

A run trained under random delays is deployed at its bound Δ_max (the conservative agent acts
on every observation exactly Δ_max old, which is what the wrapper delivers); a run with an
action delay is refused, since Gymnasium's wrapper delays observations only.
"""

from __future__ import annotations

import argparse
import subprocess
import sys

import gymnasium
import numpy as np
from gymnasium.wrappers import DelayObservation

from dhrl.deploy import DelayedPolicy, read_manifest


def play(env: gymnasium.Env, policy: DelayedPolicy, seed: int) -> tuple[float, int]:
    """One episode: its return (every step's reward, the warm-up's included) and length."""
    policy.reset()
    observation, _ = env.reset(seed=seed)
    total, t = 0.0, 0
    while True:
        if t >= policy.delay:
            policy.observe(t - policy.delay, observation)
        observation, reward, terminated, truncated, _ = env.step(policy.act())
        total += float(reward)
        t += 1
        if terminated or truncated:
            return total, t


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("export", help="a folder written by `dhrl export`")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0, help="the first episode's reset seed (then +1 each)")
    parser.add_argument("--dhrl", help="the dhrl program, to print `dhrl eval` of --run beside")
    parser.add_argument("--run", help="the run folder the export came from (with --dhrl)")
    args = parser.parse_args(argv)
    if (args.dhrl is None) != (args.run is None):
        parser.error("--dhrl and --run go together")
    if args.episodes < 1:
        parser.error(f"--episodes {args.episodes}: accepted is a whole number ≥ 1")

    manifest = read_manifest(args.export)
    if manifest["delay"]["action_delay"] > 0:
        parser.error(
            f"the policy was trained with an action delay of {manifest['delay']['action_delay']}; "
            "Gymnasium's DelayObservation delays observations only"
        )
    delay = manifest["delay"]["total"]
    env = DelayObservation(gymnasium.make(manifest["gymnasium_id"]), delay=delay)
    policy = DelayedPolicy(args.export, seed=args.seed)
    played = [play(env, policy, args.seed + k) for k in range(args.episodes)]
    returns = np.array([r for r, _ in played])
    lengths = np.array([n for _, n in played])
    print(
        f"gymnasium {manifest['gymnasium_id']} + DelayObservation(delay={delay}), {manifest['algorithm']} policy: "
        f"return {returns.mean():.2f} ± {returns.std():.2f} over {args.episodes} episodes "
        f"(mean length {lengths.mean():.1f})"
    )
    if args.dhrl:
        done = subprocess.run(
            [args.dhrl, "eval", args.run, "--episodes", str(args.episodes)], capture_output=True, text=True
        )
        if done.returncode != 0:
            print(done.stderr, file=sys.stderr)
            return done.returncode
        print(f"dhrl eval {args.run}: {done.stdout.strip()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
