#!/usr/bin/env python3
"""Gymnasium oracle for dhrl's task parity test.

For one task it plays episodes in `gymnasium.make("<Task>-v4")` from states set with
`env.unwrapped.set_state` and uniformly random float64 actions, and writes, per episode,
the inputs of `dhrl rollout` and what Gymnasium returned:

    OUT/episode-K/state.json      {"qpos": [...], "qvel": [...]}
    OUT/episode-K/actions.csv     one action per line, comma-separated, shortest round-trip repr
    OUT/episode-K/expected.jsonl  {"t":0,"obs":[...]} then {"t":k,"obs","reward","terminated","truncated"}

Episodes continue until at least --min-steps steps were played and, for a task that can
terminate, at least one episode terminated (Ant, which rarely falls under random actions,
gets a last episode started above its healthy height, so it terminates at once).
"""
import argparse
import json
import pathlib

import gymnasium as gym
import numpy as np

CAN_TERMINATE = {"Ant-v4", "Hopper-v4", "Walker2d-v4", "Humanoid-v4", "InvertedPendulum-v4"}


def play(env, qpos, qvel, rng, max_steps, out):
    base = env.unwrapped
    env.reset(seed=int(rng.integers(2**31)))
    base.set_state(qpos, qvel)
    out.mkdir(parents=True, exist_ok=True)
    (out / "state.json").write_text(json.dumps({"qpos": qpos.tolist(), "qvel": qvel.tolist()}))
    low, high = env.action_space.low.astype(np.float64), env.action_space.high.astype(np.float64)
    lines = [{"t": 0, "obs": base._get_obs().tolist()}]
    actions = []
    terminated = truncated = False
    for t in range(1, max_steps + 1):
        action = rng.uniform(low, high)
        actions.append(action)
        obs, reward, terminated, truncated, _ = env.step(action)
        lines.append({"t": t, "obs": np.asarray(obs, dtype=np.float64).tolist(), "reward": float(reward),
                      "terminated": bool(terminated), "truncated": bool(truncated)})
        if terminated or truncated:
            break
    (out / "actions.csv").write_text("".join(",".join(repr(float(a)) for a in row) + "\n" for row in actions))
    (out / "expected.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))
    return len(actions), terminated


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", required=True, help="Gymnasium id, e.g. HalfCheetah-v4")
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--min-steps", type=int, default=250)
    parser.add_argument("--max-episode-steps", type=int, default=1000)
    args = parser.parse_args()

    env = gym.make(args.task)
    rng = np.random.default_rng(args.seed)
    steps, episodes, any_terminated = 0, 0, False
    while steps < args.min_steps or (args.task in CAN_TERMINATE and not any_terminated):
        env.reset(seed=args.seed + episodes)
        qpos, qvel = env.unwrapped.data.qpos.copy(), env.unwrapped.data.qvel.copy()
        if args.task == "Ant-v4" and steps >= args.min_steps:
            qpos[2] = 1.05  # above the healthy range: terminates on the first step
        n, terminated = play(env, qpos, qvel, rng, args.max_episode_steps, args.out / f"episode-{episodes}")
        steps, episodes, any_terminated = steps + n, episodes + 1, any_terminated or terminated
    print(json.dumps({"task": args.task, "episodes": episodes, "steps": steps, "terminated": any_terminated}))


if __name__ == "__main__":
    main()
