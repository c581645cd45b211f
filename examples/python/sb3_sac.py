"""Stable-Baselines3's SAC, unchanged, on a delayed dhrl task: the policy sees the augmented
states x_t, so this is augmented SAC (one of the paper's baselines).

    python examples/python/sb3_sac.py --out docs/python/sb3_sac

The networks default to two hidden layers of 64 (SB3's own default is 256 × 256): on a 2-core
CPU that is 4× faster per gradient step and is plenty for InvertedPendulum's 9-dimensional
augmented state at Δ = 5.

Needs ``pip install './python[sb3]'``.
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np
from stable_baselines3 import SAC

import dhrl.sb3
from curves import evaluate, write_curve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="InvertedPendulum-v4")
    parser.add_argument("--delay", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--eval-every", type=int, default=5_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--net-arch", type=lambda text: [int(width) for width in text.split(",")], default=[64, 64],
                        help="hidden layer widths of actor and critics, comma-separated (default 64,64)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/python/sb3_sac"))
    args = parser.parse_args()

    env = dhrl.sb3.make_vec(args.task, 1, delay=args.delay, seed=args.seed)
    # The temperature starts at 0.2 and is tuned to −dim(A), as in dhrl's own SAC (SB3's "auto"
    # would start it at 1.0).
    model = SAC("MlpPolicy", env, learning_starts=5_000, ent_coef="auto_0.2",
                policy_kwargs=dict(net_arch=args.net_arch), seed=args.seed, device="cpu", verbose=0)

    def greedy(x: np.ndarray) -> np.ndarray:
        return model.predict(x, deterministic=True)[0]

    curve, started = [], time.time()
    for steps in range(0, args.steps + 1, args.eval_every):
        if steps:
            model.learn(args.eval_every, reset_num_timesteps=False)
        returns = evaluate(greedy, args.task, args.delay, episodes=10, seed=10_000 + steps)
        curve.append((steps, float(np.mean(returns)), float(np.std(returns))))
        print(f"{steps:>7} steps  eval return {curve[-1][1]:8.1f} ± {curve[-1][2]:6.1f}  ({time.time() - started:.0f} s)", flush=True)
        write_curve(args.out, f"SB3 SAC on dhrl.sb3.make_vec: {args.task}, Δ = {args.delay}", curve)  # after every evaluation: an interrupted run keeps its curve
    print(f"curve: {args.out.with_suffix('.csv')}, {args.out.with_suffix('.svg')}")


if __name__ == "__main__":
    main()
