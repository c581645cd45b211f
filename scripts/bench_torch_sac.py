#!/usr/bin/env python3
"""PyTorch's SAC update beside dhrl's, measured on the same machine and thread count.

One update as in CleanRL's sac_continuous_action.py (twin critics with Polyak targets, a
tanh-Gaussian actor and a learned temperature, all updated every step; Adam lr 3e-4, 256-256
MLPs, batch 256) on random batches at a task's sizes, then `dhrl bench update` with the same
sizes. PyTorch is not part of dhrl's set-up: install it into the venv first,
`.deps/venv/bin/pip install torch`.

    .deps/venv/bin/python scripts/bench_torch_sac.py [--obs 17 --act 6 --task half-cheetah --threads 2]
    .deps/venv/bin/python scripts/bench_torch_sac.py --torch-only --updates 20

On a GPU machine, `--torch-device cuda --dhrl-device wgpu` sets PyTorch's CUDA update beside
dhrl's burn-wgpu one (dhrl built with `--features wgpu-learner`).

`--end-to-end` times whole training instead, on one environment and one thread
(torch.set_num_threads(1), RAYON_NUM_THREADS=1, unless --threads says otherwise):

    .deps/venv/bin/python scripts/bench_torch_sac.py --end-to-end [--steps 3000 --learning-starts 1000]

PyTorch runs a CleanRL-style SAC loop (the schedule of CleanRL's sac_continuous_action.py:
uniform random actions for the first --learning-starts steps, then the actor's sampled action;
from then on the critics step every environment step, the actor and the temperature step twice
on every second step (policy_frequency = 2), the Polyak targets (τ = 0.005) every step; batch
256, 256-256 ReLU networks, Adam lr 3e-4 for the actor and 1e-3 for the critics and α, α
learned from 1 toward −dim(A), log σ squashed into [−5, 2]) on Gymnasium's InvertedPendulum-v4,
and times the environment steps after learning starts (steps --learning-starts … --steps − 1:
acting, stepping MuJoCo, the replay and the updates). As CleanRL does, the actor acts without
torch.no_grad, its loss back-propagates into the (unused) critic weight gradients, and α's loss
takes one more actor pass. Unlike CleanRL, the environment is one plain gym.make (with
RecordEpisodeStatistics) reset by hand, not a SyncVectorEnv (Gymnasium 1.x's vector autoreset
differs from the 0.29 CleanRL was written for), and the replay is a small NumPy ring (CleanRL
uses Stable-Baselines3's): the transitions stored are the same (the true next observation,
termination but not truncation as done).

Beside it, `dhrl train --task inverted-pendulum --algo sac --steps S --warmup-steps W --envs 1
--threads 1` (dhrl's own SAC: every network and α at lr 3e-4, α from 0.2, the actor every
step), with evaluation and checkpoints only at the end (--eval-every S --checkpoint-every S
--eval-episodes 1) and `log_every` (--log-every, default 100) updates between rows of its
train.csv (set through a --config file). dhrl's rates are read from train.csv over the rows
after the first (the first row's window holds the warm-up): env steps and updates per second
over that span of its step, updates and wall_seconds columns, i.e. the time-weighted mean of
the rows' env_steps_per_sec and updates_per_sec. One JSON line gives both rates and the ratios
dhrl / torch. `--torch-only` (either mode) skips dhrl.
"""
import argparse
import csv
import json
import os
import subprocess
import tempfile
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F


class QNet(nn.Module):
    def __init__(self, obs, act):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(obs + act, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 1))

    def forward(self, x, a):
        return self.net(torch.cat([x, a], 1))


class Actor(nn.Module):
    def __init__(self, obs, act):
        super().__init__()
        self.trunk = nn.Sequential(nn.Linear(obs, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU())
        self.mean = nn.Linear(256, act)
        self.log_std = nn.Linear(256, act)

    def sample(self, x):
        h = self.trunk(x)
        mean, log_std = self.mean(h), self.log_std(h).clamp(-20, 2)
        u = mean + log_std.exp() * torch.randn_like(mean)
        log_prob = (-0.5 * ((u - mean) / log_std.exp()) ** 2 - log_std - 0.9189385332).sum(1, keepdim=True)
        log_prob -= (2 * (torch.log(torch.tensor(2.0)) - u - F.softplus(-2 * u))).sum(1, keepdim=True)
        return torch.tanh(u), log_prob


def update_only(args):
    args.threads = 2 if args.threads is None else args.threads
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    dev = torch.device(args.torch_device)
    torch.set_default_device(dev)
    actor, q1, q2 = Actor(args.obs, args.act), QNet(args.obs, args.act), QNet(args.obs, args.act)
    t1, t2 = QNet(args.obs, args.act), QNet(args.obs, args.act)
    t1.load_state_dict(q1.state_dict())
    t2.load_state_dict(q2.state_dict())
    log_alpha = torch.zeros(1, requires_grad=True)
    q_opt = torch.optim.Adam(list(q1.parameters()) + list(q2.parameters()), lr=3e-4)
    pi_opt = torch.optim.Adam(actor.parameters(), lr=3e-4)
    a_opt = torch.optim.Adam([log_alpha], lr=3e-4)
    b = args.batch
    obs, act, rew = torch.randn(b, args.obs), torch.rand(b, args.act) * 2 - 1, torch.randn(b, 1)
    nxt, done = torch.randn(b, args.obs), torch.zeros(b, 1)

    def update():
        alpha = log_alpha.exp().item()
        with torch.no_grad():
            a2, lp2 = actor.sample(nxt)
            y = rew + 0.99 * (1 - done) * (torch.min(t1(nxt, a2), t2(nxt, a2)) - alpha * lp2)
        q_loss = F.mse_loss(q1(obs, act), y) + F.mse_loss(q2(obs, act), y)
        q_opt.zero_grad()
        q_loss.backward()
        q_opt.step()
        a, lp = actor.sample(obs)
        pi_loss = (alpha * lp - torch.min(q1(obs, a), q2(obs, a))).mean()
        pi_opt.zero_grad()
        pi_loss.backward()
        pi_opt.step()
        alpha_loss = (-log_alpha.exp() * (lp.detach() + (-args.act))).mean()
        a_opt.zero_grad()
        alpha_loss.backward()
        a_opt.step()
        with torch.no_grad():
            for target, online in ((t1, q1), (t2, q2)):
                for p_t, p in zip(target.parameters(), online.parameters()):
                    p_t.mul_(0.995).add_(0.005 * p)

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize()

    for _ in range(20):
        update()
    sync()
    start = time.perf_counter()
    for _ in range(args.updates):
        update()
    sync()
    torch_rate = args.updates / (time.perf_counter() - start)
    if args.torch_only:
        print(json.dumps({"task": args.task, "batch": b, "threads": args.threads, "torch": torch.__version__,
                          "torch_device": args.torch_device, "torch_updates_per_sec": round(torch_rate, 1)}))
        return
    dhrl = json.loads(subprocess.run(
        [args.dhrl, "bench", "update", "--algo", "sac", "--task", args.task, "--batch-size", str(b), "--updates", str(args.updates),
         "--device", args.dhrl_device, "--threads", str(args.threads), "--json"],
        check=True, capture_output=True, text=True, env={**os.environ, "RAYON_NUM_THREADS": str(args.threads)}).stdout)
    print(json.dumps({"task": args.task, "batch": b, "threads": args.threads, "torch": torch.__version__,
                      "torch_device": args.torch_device, "dhrl_device": args.dhrl_device,
                      "torch_updates_per_sec": round(torch_rate, 1), "dhrl_updates_per_sec": round(dhrl["updates_per_sec"], 1),
                      "ratio": round(dhrl["updates_per_sec"] / torch_rate, 3)}))


class CleanRLActor(nn.Module):
    """CleanRL's SAC actor: 256-256 ReLU, mean and log σ heads, log σ squashed into [−5, 2]."""

    LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0

    def __init__(self, env):
        super().__init__()
        obs, act = env.observation_space.shape[0], env.action_space.shape[0]
        self.fc1, self.fc2 = nn.Linear(obs, 256), nn.Linear(256, 256)
        self.fc_mean, self.fc_logstd = nn.Linear(256, act), nn.Linear(256, act)
        high = torch.tensor(env.action_space.high, dtype=torch.float32)
        low = torch.tensor(env.action_space.low, dtype=torch.float32)
        self.register_buffer("action_scale", (high - low) / 2.0)
        self.register_buffer("action_bias", (high + low) / 2.0)

    def get_action(self, x):
        h = F.relu(self.fc2(F.relu(self.fc1(x))))
        mean = self.fc_mean(h)
        log_std = torch.tanh(self.fc_logstd(h))
        log_std = self.LOG_STD_MIN + 0.5 * (self.LOG_STD_MAX - self.LOG_STD_MIN) * (log_std + 1)
        normal = torch.distributions.Normal(mean, log_std.exp())
        u = normal.rsample()
        y = torch.tanh(u)
        action = y * self.action_scale + self.action_bias
        log_prob = normal.log_prob(u) - torch.log(self.action_scale * (1 - y.pow(2)) + 1e-6)
        return action, log_prob.sum(1, keepdim=True), torch.tanh(mean) * self.action_scale + self.action_bias


class Replay:
    """A NumPy ring of (s, a, r, s', terminated), sampled uniformly with replacement."""

    def __init__(self, capacity, obs, act, seed):
        self.obs, self.next_obs = np.zeros((capacity, obs), np.float32), np.zeros((capacity, obs), np.float32)
        self.actions, self.rewards = np.zeros((capacity, act), np.float32), np.zeros((capacity, 1), np.float32)
        self.dones = np.zeros((capacity, 1), np.float32)
        self.capacity, self.size, self.pos = capacity, 0, 0
        self.rng = np.random.default_rng(seed)

    def add(self, obs, next_obs, action, reward, terminated):
        i = self.pos
        self.obs[i], self.next_obs[i], self.actions[i] = obs, next_obs, action
        self.rewards[i], self.dones[i] = reward, float(terminated)
        self.pos, self.size = (i + 1) % self.capacity, min(self.size + 1, self.capacity)

    def sample(self, n):
        idx = self.rng.integers(0, self.size, n)
        return tuple(torch.from_numpy(a[idx]) for a in (self.obs, self.actions, self.rewards, self.next_obs, self.dones))


def torch_end_to_end(args):
    """CleanRL's sac_continuous_action.py schedule; env steps and updates per second after learning starts."""
    import gymnasium as gym

    env = gym.wrappers.RecordEpisodeStatistics(gym.make(args.env_id))
    env.action_space.seed(args.seed)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    actor = CleanRLActor(env)
    q1, q2 = QNet(obs_dim, act_dim), QNet(obs_dim, act_dim)
    t1, t2 = QNet(obs_dim, act_dim), QNet(obs_dim, act_dim)
    t1.load_state_dict(q1.state_dict())
    t2.load_state_dict(q2.state_dict())
    q_opt = torch.optim.Adam(list(q1.parameters()) + list(q2.parameters()), lr=1e-3)
    pi_opt = torch.optim.Adam(actor.parameters(), lr=3e-4)
    target_entropy = -float(act_dim)
    log_alpha = torch.zeros(1, requires_grad=True)
    alpha = log_alpha.exp().item()
    a_opt = torch.optim.Adam([log_alpha], lr=1e-3)
    gamma, tau, batch, policy_frequency = 0.99, 0.005, args.batch, 2
    rb = Replay(args.steps, obs_dim, act_dim, args.seed)
    obs, _ = env.reset(seed=args.seed)
    updates, start = 0, None
    for global_step in range(args.steps):
        if global_step == args.learning_starts:
            start = time.perf_counter()
        if global_step < args.learning_starts:
            action = env.action_space.sample()
        else:
            action, _, _ = actor.get_action(torch.Tensor(obs).unsqueeze(0))
            action = action.detach().cpu().numpy()[0]
        next_obs, reward, terminated, truncated, _ = env.step(action)
        rb.add(obs, next_obs, action, reward, terminated)
        obs = next_obs
        if terminated or truncated:
            obs, _ = env.reset()
        if global_step > args.learning_starts:
            s, a, r, s2, d = rb.sample(batch)
            with torch.no_grad():
                next_a, next_log_pi, _ = actor.get_action(s2)
                min_next = torch.min(t1(s2, next_a), t2(s2, next_a)) - alpha * next_log_pi
                y = r.flatten() + (1 - d.flatten()) * gamma * min_next.view(-1)
            q_loss = F.mse_loss(q1(s, a).view(-1), y) + F.mse_loss(q2(s, a).view(-1), y)
            q_opt.zero_grad()
            q_loss.backward()
            q_opt.step()
            if global_step % policy_frequency == 0:
                for _ in range(policy_frequency):
                    pi, log_pi, _ = actor.get_action(s)
                    pi_loss = (alpha * log_pi - torch.min(q1(s, pi), q2(s, pi))).mean()
                    pi_opt.zero_grad()
                    pi_loss.backward()
                    pi_opt.step()
                    with torch.no_grad():
                        _, log_pi, _ = actor.get_action(s)
                    alpha_loss = (-log_alpha.exp() * (log_pi + target_entropy)).mean()
                    a_opt.zero_grad()
                    alpha_loss.backward()
                    a_opt.step()
                    alpha = log_alpha.exp().item()
            with torch.no_grad():
                for target, online in ((t1, q1), (t2, q2)):
                    for p_t, p in zip(target.parameters(), online.parameters()):
                        p_t.mul_(1 - tau).add_(tau * p)
            updates += 1
    seconds = time.perf_counter() - start
    env.close()
    return (args.steps - args.learning_starts) / seconds, updates / seconds


def dhrl_end_to_end(args):
    """`dhrl train` on one copy and one thread; its rates over train.csv's rows after the first."""
    with tempfile.TemporaryDirectory(prefix="dhrl-bench-") as tmp:
        config, run = os.path.join(tmp, "log.toml"), os.path.join(tmp, "run")
        with open(config, "w") as f:
            f.write(f"log_every = {args.log_every}\n")
        subprocess.run(
            [args.dhrl, "train", "--task", "inverted-pendulum", "--algo", "sac", "--config", config,
             "--steps", str(args.steps), "--warmup-steps", str(args.learning_starts), "--envs", "1",
             "--threads", "1", "--batch-size", str(args.batch), "--seed", str(args.seed),
             "--eval-every", str(args.steps), "--checkpoint-every", str(args.steps), "--eval-episodes", "1",
             "--out", run],
            check=True, capture_output=True, text=True, env={**os.environ, "RAYON_NUM_THREADS": str(args.threads)})
        with open(os.path.join(run, "train.csv")) as f:
            rows = list(csv.DictReader(f))
    if len(rows) < 2:
        raise SystemExit(f"dhrl's train.csv has {len(rows)} row(s); the learning phase needs two: "
                         "lower --log-every or raise --steps")
    first, last = rows[0], rows[-1]
    seconds = float(last["wall_seconds"]) - float(first["wall_seconds"])
    return ((int(last["step"]) - int(first["step"])) / seconds,
            (int(last["updates"]) - int(first["updates"])) / seconds, len(rows) - 1)


def end_to_end(args):
    args.threads = 1 if args.threads is None else args.threads
    if args.learning_starts < 1 or args.steps <= args.learning_starts + 1:
        raise SystemExit("--steps must exceed --learning-starts + 1, and --learning-starts be at least 1")
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    env_rate, update_rate = torch_end_to_end(args)
    report = {"mode": "end-to-end", "env": args.env_id, "steps": args.steps, "learning_starts": args.learning_starts,
              "batch": args.batch, "threads": args.threads, "torch": torch.__version__,
              "torch_env_steps_per_sec": round(env_rate, 1), "torch_updates_per_sec": round(update_rate, 1)}
    if not args.torch_only:
        dhrl_env_rate, dhrl_update_rate, windows = dhrl_end_to_end(args)
        report.update({"dhrl_env_steps_per_sec": round(dhrl_env_rate, 1),
                       "dhrl_updates_per_sec": round(dhrl_update_rate, 1), "dhrl_train_rows_timed": windows,
                       "ratio_env_steps": round(dhrl_env_rate / env_rate, 3),
                       "ratio_updates": round(dhrl_update_rate / update_rate, 3)})
    print(json.dumps(report))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--obs", type=int, default=17)
    parser.add_argument("--act", type=int, default=6)
    parser.add_argument("--task", default="half-cheetah")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--threads", type=int, default=None,
                        help="PyTorch and rayon threads (default: 2 for updates, 1 with --end-to-end)")
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--dhrl", default="target/release/dhrl")
    parser.add_argument("--torch-device", default="cpu", help="cpu or cuda")
    parser.add_argument("--dhrl-device", default="cpu", help="cpu or wgpu")
    parser.add_argument("--torch-only", action="store_true", help="time PyTorch alone (no dhrl run)")
    parser.add_argument("--end-to-end", action="store_true",
                        help="time whole training on InvertedPendulum (CleanRL-style loop vs dhrl train)")
    parser.add_argument("--steps", type=int, default=3000, help="--end-to-end: environment steps in total")
    parser.add_argument("--learning-starts", type=int, default=1000,
                        help="--end-to-end: uniform random steps before learning (dhrl's --warmup-steps)")
    parser.add_argument("--log-every", type=int, default=100,
                        help="--end-to-end: dhrl's updates between train.csv rows (its log_every)")
    parser.add_argument("--env-id", default="InvertedPendulum-v4", help="--end-to-end: PyTorch's Gymnasium task")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.end_to_end:
        end_to_end(args)
    else:
        update_only(args)


if __name__ == "__main__":
    main()
