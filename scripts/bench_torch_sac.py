#!/usr/bin/env python3
"""PyTorch's SAC update beside dhrl's, measured on the same machine and thread count.

One update as in CleanRL's sac_continuous_action.py (twin critics with Polyak targets, a
tanh-Gaussian actor and a learned temperature, all updated every step; Adam lr 3e-4, 256-256
MLPs, batch 256) on random batches at a task's sizes, then `dhrl bench update` with the same
sizes. PyTorch is not part of dhrl's set-up: install it into the venv first,
`.deps/venv/bin/pip install torch`.

    .deps/venv/bin/python scripts/bench_torch_sac.py [--obs 17 --act 6 --task half-cheetah --threads 2]

On a GPU machine, `--torch-device cuda --dhrl-device wgpu` sets PyTorch's CUDA update beside
dhrl's burn-wgpu one (dhrl built with `--features wgpu-learner`).
"""
import argparse
import json
import os
import subprocess
import time

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


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--obs", type=int, default=17)
    parser.add_argument("--act", type=int, default=6)
    parser.add_argument("--task", default="half-cheetah")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--dhrl", default="target/release/dhrl")
    parser.add_argument("--torch-device", default="cpu", help="cpu or cuda")
    parser.add_argument("--dhrl-device", default="cpu", help="cpu or wgpu")
    args = parser.parse_args()
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
    dhrl = json.loads(subprocess.run(
        [args.dhrl, "bench", "update", "--algo", "sac", "--task", args.task, "--batch-size", str(b), "--updates", str(args.updates),
         "--device", args.dhrl_device, "--json"],
        check=True, capture_output=True, text=True, env={**os.environ, "RAYON_NUM_THREADS": str(args.threads)}).stdout)
    print(json.dumps({"task": args.task, "batch": b, "threads": args.threads, "torch": torch.__version__,
                      "torch_device": args.torch_device, "dhrl_device": args.dhrl_device,
                      "torch_updates_per_sec": round(torch_rate, 1), "dhrl_updates_per_sec": round(dhrl["updates_per_sec"], 1),
                      "ratio": round(dhrl["updates_per_sec"] / torch_rate, 3)}))


if __name__ == "__main__":
    main()
