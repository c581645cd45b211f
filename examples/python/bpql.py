"""BPQL (Kim et al., 2023, "Belief projection-based reinforcement learning for environments
with delayed feedback") in PyTorch, learning from the time-aligned transitions that
``dhrl.make_vec`` puts in ``info["transitions"]``: the actor acts on augmented states x, the
critic is a delay-free Q(s, a) on the true states — no replay bookkeeping of its own.

    python examples/python/bpql.py --steps 30000 --out docs/python/bpql

Needs ``pip install ./python torch``.
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np
import torch
from torch import nn

import dhrl
from curves import evaluate, write_curve


def mlp(inputs: int, outputs: int, hidden: int = 256) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, outputs)
    )


class Actor(nn.Module):
    """π(a | x): a tanh-squashed Gaussian on the augmented state."""

    def __init__(self, aug_dim: int, act_dim: int, scale: np.ndarray):
        super().__init__()
        self.body = mlp(aug_dim, 2 * act_dim)
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def forward(self, x: torch.Tensor):
        mean, log_std = self.body(x).chunk(2, dim=-1)
        std = log_std.clamp(-20, 2).exp()
        u = mean + std * torch.randn_like(mean)
        a = torch.tanh(u)
        # log π of the squashed sample (SAC, Haarnoja et al. 2018, eq. 21)
        log_prob = (torch.distributions.Normal(mean, std).log_prob(u) - torch.log(1 - a.pow(2) + 1e-6)).sum(-1)
        return a * self.scale, log_prob, torch.tanh(mean) * self.scale


class Replay:
    """Transitions (x, s, a, r, x', s', terminated) as info["transitions"] hands them over."""

    KEYS = ("augmented", "state", "action", "reward", "next_augmented", "next_state", "terminated")

    def __init__(self, capacity: int):
        self.capacity, self.size, self.at, self.data = capacity, 0, 0, {}

    def add(self, batch: dict) -> None:
        n = len(batch["reward"])
        for key in self.KEYS:
            value = np.asarray(batch[key], np.float32)
            store = self.data.setdefault(key, np.zeros((self.capacity, *value.shape[1:]), np.float32))
            rows = (self.at + np.arange(n)) % self.capacity
            store[rows] = value
        self.at = (self.at + n) % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> dict:
        rows = rng.integers(0, self.size, batch)
        return {key: torch.as_tensor(self.data[key][rows]) for key in self.KEYS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="InvertedPendulum-v4")
    parser.add_argument("--delay", type=int, default=5)
    parser.add_argument("--envs", type=int, default=1)
    parser.add_argument("--steps", type=int, default=30_000, help="environment steps (all copies)")
    parser.add_argument("--start", type=int, default=5_000, help="random-action steps before learning")
    parser.add_argument("--eval-every", type=int, default=2_500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/python/bpql"))
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(args.seed)
    gamma, tau, batch_size, lr = 0.99, 0.005, 256, 3e-4

    env = dhrl.make_vec(args.task, args.envs, delay=args.delay, seed=args.seed)
    aug_dim, obs_dim, act_dim = env.single_observation_space.shape[0], env.obs_dim, env.act_dim
    scale = env.single_action_space.high
    actor = Actor(aug_dim, act_dim, scale)
    critics = [mlp(obs_dim + act_dim, 1) for _ in range(2)]
    targets = [mlp(obs_dim + act_dim, 1) for _ in range(2)]
    for target, critic in zip(targets, critics):
        target.load_state_dict(critic.state_dict())
        target.requires_grad_(False)
    log_alpha = torch.zeros(1, requires_grad=True)
    target_entropy = -float(act_dim)
    actor_opt = torch.optim.Adam(actor.parameters(), lr=lr)
    critic_opt = torch.optim.Adam([p for c in critics for p in c.parameters()], lr=lr)
    alpha_opt = torch.optim.Adam([log_alpha], lr=lr)
    replay = Replay(1_000_000)

    def q(nets, s, a):
        sa = torch.cat([s, a], -1)
        return torch.min(nets[0](sa), nets[1](sa)).squeeze(-1)

    def update() -> None:
        b = replay.sample(rng, batch_size)
        alpha = log_alpha.exp().detach()
        with torch.no_grad():
            # BPQL's critic target: the delay-free Q on s_{τ+1}, the action from π(·|x_{τ+1})
            next_a, next_logp, _ = actor(b["next_augmented"])
            y = b["reward"] + gamma * (1 - b["terminated"]) * (q(targets, b["next_state"], next_a) - alpha * next_logp)
        sa = torch.cat([b["state"], b["action"]], -1)
        critic_loss = sum(((c(sa).squeeze(-1) - y) ** 2).mean() for c in critics)
        critic_opt.zero_grad()
        critic_loss.backward()
        critic_opt.step()
        # The actor on x_τ, judged by the critic on the true s_τ (BPQL's projection)
        a, logp, _ = actor(b["augmented"])
        actor_loss = (alpha * logp - q(critics, b["state"], a)).mean()
        actor_opt.zero_grad()
        actor_loss.backward()
        actor_opt.step()
        alpha_loss = -(log_alpha * (logp.detach() + target_entropy)).mean()
        alpha_opt.zero_grad()
        alpha_loss.backward()
        alpha_opt.step()
        with torch.no_grad():
            for target, critic in zip(targets, critics):
                for tp, p in zip(target.parameters(), critic.parameters()):
                    tp.mul_(1 - tau).add_(tau * p)

    def greedy(x: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return actor(torch.as_tensor(x))[2].numpy()

    obs, info = env.reset()
    curve, steps, started = [], 0, time.time()
    next_eval = 0
    while steps <= args.steps:
        if steps >= next_eval:
            returns = evaluate(greedy, args.task, args.delay, episodes=10, seed=10_000 + steps)
            curve.append((steps, float(np.mean(returns)), float(np.std(returns))))
            print(f"{steps:>7} steps  eval return {curve[-1][1]:8.1f} ± {curve[-1][2]:6.1f}  ({time.time() - started:.0f} s)", flush=True)
            write_curve(args.out, f"BPQL from dhrl.make_vec: {args.task}, Δ = {args.delay}", curve)  # after every evaluation: an interrupted run keeps its curve
            next_eval += args.eval_every
        if steps < args.start:
            actions = rng.uniform(-scale, scale, (args.envs, act_dim)).astype(np.float32)
        else:
            with torch.no_grad():
                actions = actor(torch.as_tensor(obs))[0].numpy()
        obs, _, _, _, info = env.step(actions)
        replay.add(info["transitions"])
        steps += args.envs
        if steps >= args.start:
            for _ in range(args.envs):
                update()
    print(f"curve: {args.out.with_suffix('.csv')}, {args.out.with_suffix('.svg')}")


if __name__ == "__main__":
    main()
