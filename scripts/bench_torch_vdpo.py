#!/usr/bin/env python3
"""PyTorch's VDPO update beside dhrl's, measured on the same machine and thread count.

The same networks and losses as `src/algos/vdpo.rs` with its `Config` defaults, one "update"
meaning exactly what one call of dhrl's `Agent::update` does when `dhrl bench update` drives it:

1. the delay-free SAC reference on the true state s (twin 256-256 ReLU critics with Polyak
   targets, τ = 0.005, γ = 0.99; a tanh-squashed Gaussian 256-256 actor, log σ clamped to
   [−20, 2]; a learned temperature from α = 0.2 toward −dim(A)): the critics every update
   (Adam lr 1e-3), the actor (lr 3e-4) and the temperature (lr 1e-3) `actor_every` = 2 steps on
   every second update, the targets every update;
2. one step of the belief network on the reconstruction loss (Adam lr 3e-4): Δ tokens, token i
   = Linear(2w → w)([Linear(s_{t−Δ}); Linear(a_{t−Δ+i})]) + position embedding i, LayerNorm,
   dropout 0.1, then 3 causal pre-LN transformer blocks (width w = 256, 1 head, GELU
   feed-forward of width 256, dropout 0.1), a final LayerNorm, and a linear decoder
   reconstructing s_{t−Δ+1+i} at position i (mean squared error over positions and dimensions);
3. the cloning stage on its schedule: on the first update after the environment-step count
   crosses a multiple of `bc_every` = 1000, `bc_updates` = 1000 Adam steps (lr 3e-4) of the
   policy head (a 2×256 ReLU Gaussian on the transformer's features) on
   KL(π_Δ(·|x) ‖ π_ref(·|s)) between the Gaussians before the squash, at every position i
   against the reference actor at s_{t−Δ+1+i}, the transformer run without dropout and off the
   graph, the features and the reference's Gaussians recomputed at every step (in training
   each step draws a fresh batch).

`dhrl bench update` calls update k with environment step k (an untimed update at step 0, then
k = 1..N timed), so a cloning burst runs inside updates 1000, 2000, …: the timed N updates
hold ⌊N / bc_every⌋ bursts. This script times the same N updates with the same schedule and
requires N to be a whole number of `bc_every` periods, so that each side's mean carries
exactly one burst per `bc_every` updates, as training does: one update averages one reference
step, one belief step and bc_updates / bc_every = 1 cloning step. The default N is one period,
1000 updates (1001 with the warm-up, one burst of 1000 cloning steps): a few minutes for
PyTorch on one thread, and longer for dhrl (docs/results/update-costs.md measured 373–791 ms
per VDPO update on one thread, so 6–13 minutes). `--bc-every 10 --bc-updates 10 --updates 100`
keeps the same ratio of one cloning step per update at a tenth of the cost, as that table does.

Batches are fixed and random at the task's sizes (as `random_batch` in src/algos/mod.rs):
uniform in [−1, 1), terminations on every fifth row, the augmented state x = (s_{t−Δ},
a_{t−Δ..t−1}) of width obs + Δ·act, and the Δ intermediate states. The cloning stage reuses
that batch at every step, as dhrl's bench does (UpdateContext::fixed).

Where the PyTorch version necessarily differs from dhrl's (none changes the arithmetic's
amount; the work per update is the same):
  * the transformer is PyTorch's nn.TransformerEncoder(Layer) (batch_first, norm_first,
    activation "gelu"): the same pre-LN block as burn's TransformerEncoderLayer with
    norm_first (x + drop(MHA(LN(x))), then x + drop(FF(LN(x))), FF = Linear, GELU, dropout,
    Linear; dropout on the attention weights), but its attention packs the Q, K, V projections
    into one matrix and runs through scaled_dot_product_attention with a causal (−∞) mask,
    whereas burn multiplies three matrices, fills the masked scores with its min_float, and
    materialises the softmax;
  * in the cloning stage the transformer runs in eval mode under no_grad, where PyTorch may
    take its fused inference path ("fast path"; `--no-torch-fastpath` turns it off); burn's
    `valid()` module runs the same operators as in training, without dropout;
  * Gaussian noise comes from torch.randn; dhrl draws it on the host from a seeded ChaCha8
    stream and uploads it, and reseeds burn's generator before each belief step (dropout);
  * the batch's tensors are built once; dhrl clones the batch (Vec<f32>s) on every draw and
    builds its tensors from them on every update and every cloning step;
  * weights are drawn by PyTorch's initialisers (burn's Kaiming-uniform variants in dhrl);
  * the reference actor's step holds the critics fixed by switching off their parameters'
    requires_grad (burn differentiates through `critic.valid()`): neither computes the
    critics' weight gradients there;
  * Adam is PyTorch's default (single-tensor, betas 0.9/0.999, ε 1e-8), dhrl's is burn's
    with ε 1e-8; PyTorch's Adam updates in place, burn's returns new parameter tensors.

PyTorch is not part of dhrl's set-up: install it into the venv first,
`.deps/venv/bin/pip install torch`.

    .deps/venv/bin/python scripts/bench_torch_vdpo.py [--task half-cheetah --delay 5 --threads 1 --updates 1000]
    .deps/venv/bin/python scripts/bench_torch_vdpo.py --torch-only --updates 20 --bc-every 10 --bc-updates 10

It prints one JSON line: both rates (updates per second, the cloning bursts averaged in) and
the ratio dhrl / torch. `--torch-only` skips dhrl (when target/release/dhrl is not built).

`--products` also measures what the update's matrix products alone cost on this core: it records
one more `bc_every` period of PyTorch updates (one burst) with torch.profiler, counts the
products' FLOPs (mm, addmm, bmm, baddbmm), then runs exactly those products again, back to back
on operands of the recorded shapes (contiguous) and nothing else, best of five. So the same
update cannot run faster than `products_ms` at PyTorch's sgemm rate on this core whatever the
framework, and `torch_ms_per_update / products_ms` is the most any implementation of the same
arithmetic at that rate could beat PyTorch by; `other_ms_at_1_5x` is what a 1.5× implementation
may spend on everything that is not a product (layer norms, activations, softmax, dropout,
losses, Adam, allocation), against PyTorch's `torch_other_ms` and dhrl's `dhrl_other_ms` (its
total less the same products at PyTorch's rate). dhrl's gemm runs at about that rate on the
Xeon (docs/results/performance-xeon.md) and faster on the EPYC, where `dhrl_other_ms` comes out
negative; there PyTorch's products alone also take more than its update time / 1.5, so
`other_ms_at_1_5x` is negative too: 1.5× needs faster products than PyTorch's.
"""
import argparse
import json
import math
import os
import subprocess
import time

import torch
import torch.nn as nn
from torch.profiler import ProfilerActivity, profile
import torch.nn.functional as F

# Observation size, action size and action bound (|a_j| ≤ bound) of dhrl's tasks.
TASKS = {
    "half-cheetah": (17, 6, 1.0),
    "hopper": (11, 3, 1.0),
    "walker2d": (17, 6, 1.0),
    "ant": (27, 8, 1.0),
    "humanoid": (376, 17, 0.4),
    "inverted-pendulum": (4, 1, 3.0),
}

HIDDEN = 256
LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0
HALF_LN_TWO_PI = 0.5 * math.log(2 * math.pi)
LN_2 = math.log(2.0)


def trunk(inputs):
    return nn.Sequential(nn.Linear(inputs, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, HIDDEN), nn.ReLU())


class QNet(nn.Module):
    """Q(input, a): 256-256 ReLU on the concatenation."""

    def __init__(self, inputs, act):
        super().__init__()
        self.trunk, self.out = trunk(inputs + act), nn.Linear(HIDDEN, 1)

    def forward(self, x, a):
        return self.out(self.trunk(torch.cat([x, a], 1)))


class GaussianPolicy(nn.Module):
    """The Gaussian before the tanh squash: 256-256 ReLU, mean and clamped log σ heads."""

    def __init__(self, inputs, act):
        super().__init__()
        self.trunk = trunk(inputs)
        self.mean, self.log_std = nn.Linear(HIDDEN, act), nn.Linear(HIDDEN, act)

    def distribution(self, x):
        h = self.trunk(x)
        return self.mean(h), self.log_std(h).clamp(LOG_STD_MIN, LOG_STD_MAX)


def squashed_sample(mean, log_std, bound):
    """a = bound·tanh(μ + σε) and its log-density, in dhrl's form (src/learn/losses.rs)."""
    eps = torch.randn_like(mean)
    u = mean + log_std.exp() * eps
    gaussian = -0.5 * eps.square() - log_std - HALF_LN_TWO_PI
    log_det_tanh = 2.0 * (LN_2 - u - F.softplus(-2.0 * u))
    log_prob = (gaussian - log_det_tanh).sum(1, keepdim=True) - mean.shape[1] * math.log(bound)
    return torch.tanh(u) * bound, log_prob


class Belief(nn.Module):
    """Tokens (s_{t−Δ}, a_{t−Δ+i}, i) → causal pre-LN transformer → LayerNorm; decoder → ŝ."""

    def __init__(self, obs, act, delay, width, blocks, heads, dropout):
        super().__init__()
        self.obs, self.act, self.delay, self.width = obs, act, delay, width
        self.state_embedding = nn.Linear(obs, width)
        self.action_embedding = nn.Linear(act, width)
        self.token = nn.Linear(2 * width, width)
        self.position = nn.Embedding(delay, width)
        self.input_norm = nn.LayerNorm(width)
        self.input_dropout = nn.Dropout(dropout)
        layer = nn.TransformerEncoderLayer(width, heads, dim_feedforward=width, dropout=dropout,
                                           activation="gelu", batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, blocks, enable_nested_tensor=False)
        self.output_norm = nn.LayerNorm(width)
        self.decoder = nn.Linear(width, obs)
        self.register_buffer("causal", nn.Transformer.generate_square_subsequent_mask(delay))

    def features(self, augmented):
        """[B, obs + Δ·act] → [B, Δ, width]; position i attends to 0..=i."""
        rows = augmented.shape[0]
        state = self.state_embedding(augmented[:, :self.obs]).unsqueeze(1)
        actions = augmented[:, self.obs:self.obs + self.delay * self.act].reshape(rows, self.delay, self.act)
        tokens = self.token(torch.cat([state.expand(rows, self.delay, self.width),
                                       self.action_embedding(actions)], 2)) + self.position.weight.unsqueeze(0)
        tokens = self.input_dropout(self.input_norm(tokens))
        return self.output_norm(self.encoder(tokens, mask=self.causal, is_causal=True))


def gaussian_kl(mean, log_std, ref_mean, ref_log_std):
    """KL(N(μ, σ) ‖ N(μ_ref, σ_ref)) per dimension, averaged over dimensions and rows."""
    return (ref_log_std - log_std + ((2 * log_std).exp() + (mean - ref_mean).square())
            / (2 * (2 * ref_log_std).exp()) - 0.5).mean()


class Vdpo:
    def __init__(self, args, obs, act, bound):
        self.args, self.obs, self.act, self.bound = args, obs, act, bound
        self.actor = GaussianPolicy(obs, act)
        self.q1, self.q2 = QNet(obs, act), QNet(obs, act)
        self.t1, self.t2 = QNet(obs, act), QNet(obs, act)
        self.t1.load_state_dict(self.q1.state_dict())
        self.t2.load_state_dict(self.q2.state_dict())
        for p in list(self.t1.parameters()) + list(self.t2.parameters()):
            p.requires_grad_(False)
        self.critic_params = list(self.q1.parameters()) + list(self.q2.parameters())
        self.target_params = list(self.t1.parameters()) + list(self.t2.parameters())
        self.log_alpha = torch.tensor([math.log(0.2)], requires_grad=True)
        self.target_entropy = -float(act)
        self.q_opt = torch.optim.Adam(self.critic_params, lr=args.critic_lr)
        self.pi_opt = torch.optim.Adam(self.actor.parameters(), lr=args.actor_lr)
        self.a_opt = torch.optim.Adam([self.log_alpha], lr=args.temperature_lr)
        self.belief = Belief(obs, act, args.delay, args.belief_width, args.belief_blocks, args.belief_heads,
                             args.dropout)
        self.belief_opt = torch.optim.Adam(self.belief.parameters(), lr=args.belief_lr)
        self.head = GaussianPolicy(args.belief_width, act)
        self.head_opt = torch.optim.Adam(self.head.parameters(), lr=args.bc_lr)
        self.last_env_steps = None
        self.bc_seconds, self.bc_bursts = 0.0, 0

    def update_reference(self, b, updates_before):
        a = self.args
        alpha = self.log_alpha.exp().item()
        with torch.no_grad():
            next_action, next_log_prob = squashed_sample(*self.actor.distribution(b["next_state"]), self.bound)
            next_q = torch.min(self.t1(b["next_state"], next_action), self.t2(b["next_state"], next_action))
            y = b["reward"] + a.gamma * (1 - b["done"]) * (next_q - alpha * next_log_prob)
        q_loss = (self.q1(b["state"], b["action"]) - y).square().mean() \
            + (self.q2(b["state"], b["action"]) - y).square().mean()
        self.q_opt.zero_grad()
        q_loss.backward()
        self.q_opt.step()
        q_loss.item()
        if (updates_before + 1) % a.actor_every == 0:
            for p in self.critic_params:
                p.requires_grad_(False)
            for _ in range(a.actor_every):
                alpha = self.log_alpha.exp().item()
                action, log_prob = squashed_sample(*self.actor.distribution(b["state"]), self.bound)
                mean_log_prob = log_prob.mean().item()
                q = torch.min(self.q1(b["state"], action), self.q2(b["state"], action))
                pi_loss = (alpha * log_prob - q).mean()
                self.pi_opt.zero_grad()
                pi_loss.backward()
                self.pi_opt.step()
                pi_loss.item()
                alpha_loss = -self.log_alpha.exp() * (mean_log_prob + self.target_entropy)
                self.a_opt.zero_grad()
                alpha_loss.backward()
                self.a_opt.step()
                alpha_loss.item()
            for p in self.critic_params:
                p.requires_grad_(True)
        with torch.no_grad():
            for target, online in zip(self.target_params, self.critic_params):
                target.lerp_(online, a.tau)

    def update_belief(self, b):
        self.belief.train()
        predicted = self.belief.decoder(self.belief.features(b["augmented"]))
        loss = (predicted - b["intermediate"]).square().mean()
        self.belief_opt.zero_grad()
        loss.backward()
        self.belief_opt.step()
        loss.item()

    def clone_reference(self, b, steps):
        rows, delay, width = b["augmented"].shape[0], self.args.delay, self.args.belief_width
        self.belief.eval()
        for _ in range(steps):
            with torch.no_grad():
                features = self.belief.features(b["augmented"]).reshape(rows * delay, width)
                ref_mean, ref_log_std = self.actor.distribution(b["intermediate"].reshape(rows * delay, self.obs))
            loss = gaussian_kl(*self.head.distribution(features), ref_mean, ref_log_std)
            self.head_opt.zero_grad()
            loss.backward()
            self.head_opt.step()
            loss.item()
        self.belief.train()

    def update(self, b, env_steps, updates_before):
        """One `Agent::update` of dhrl's VDPO at `env_steps` after `updates_before` updates."""
        self.update_reference(b, updates_before)
        self.update_belief(b)
        due = self.last_env_steps is not None and env_steps // self.args.bc_every > self.last_env_steps // self.args.bc_every
        self.last_env_steps = env_steps
        if due:
            start = time.perf_counter()
            self.clone_reference(b, self.args.bc_updates)
            self.bc_seconds += time.perf_counter() - start
            self.bc_bursts += 1


def random_batch(n, obs, act, delay):
    u = lambda *shape: torch.rand(*shape) * 2 - 1
    return {
        "augmented": u(n, obs + delay * act),
        "state": u(n, obs),
        "action": u(n, act),
        "reward": u(n, 1),
        "next_augmented": u(n, obs + delay * act),
        "next_state": u(n, obs),
        "done": (torch.arange(n) % 5 == 0).float().unsqueeze(1),
        "intermediate": u(n, delay, obs),
    }


PRODUCTS = {"aten::mm": torch.mm, "aten::addmm": torch.addmm, "aten::bmm": torch.bmm,
            "aten::baddbmm": torch.baddbmm}


def products_alone(agent, batch, first_update, period):
    """The matrix products of `period` more updates (from `first_update`): (GFLOP per update,
    their best time per update run alone, back to back, on operands of the recorded shapes)."""
    with profile(activities=[ProfilerActivity.CPU], record_shapes=True, with_flops=True) as recorded:
        for k in range(first_update, first_update + period):
            agent.update(batch, k, k)
    calls = [(e.name, tuple(tuple(shape) for shape in e.input_shapes if shape), e.flops)
             for e in recorded.events() if e.name in PRODUCTS]
    operands = {}
    for name, shapes, _ in calls:
        operands.setdefault((name, shapes), [torch.randn(*shape) for shape in shapes])
    sequence = [(PRODUCTS[name], operands[(name, shapes)]) for name, shapes, _ in calls]
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        for product, arguments in sequence:
            product(*arguments)
        best = min(best, time.perf_counter() - start)
    return sum(flops for _, _, flops in calls) / period / 1e9, 1e3 * best / period


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="half-cheetah", choices=sorted(TASKS))
    parser.add_argument("--obs", type=int, help="observation size (default: the task's)")
    parser.add_argument("--act", type=int, help="action size (default: the task's)")
    parser.add_argument("--delay", type=int, default=5, help="total delay Δ (tokens per state)")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--updates", type=int, default=None,
                        help="timed updates, a multiple of --bc-every (default: one period, bc_every)")
    parser.add_argument("--warmup", type=int, default=20, help="untimed PyTorch updates before timing")
    # vdpo.rs's Config defaults (and SAC's shared ones).
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--tau", type=float, default=0.005)
    parser.add_argument("--actor-lr", type=float, default=3e-4)
    parser.add_argument("--critic-lr", type=float, default=1e-3)
    parser.add_argument("--temperature-lr", type=float, default=1e-3)
    parser.add_argument("--actor-every", type=int, default=2)
    parser.add_argument("--belief-width", type=int, default=256)
    parser.add_argument("--belief-blocks", type=int, default=3)
    parser.add_argument("--belief-heads", type=int, default=1)
    parser.add_argument("--dropout", type=float, default=0.1)
    parser.add_argument("--belief-lr", type=float, default=3e-4)
    parser.add_argument("--bc-every", type=int, default=1000)
    parser.add_argument("--bc-updates", type=int, default=1000)
    parser.add_argument("--bc-lr", type=float, default=3e-4)
    parser.add_argument("--no-torch-fastpath", action="store_true",
                        help="turn off PyTorch's fused inference path for the cloning stage's transformer")
    parser.add_argument("--dhrl", default="target/release/dhrl")
    parser.add_argument("--torch-only", action="store_true", help="time PyTorch alone (no dhrl run)")
    parser.add_argument("--products", action="store_true",
                        help="also time the update's matrix products alone (one more bc_every period, recorded)")
    args = parser.parse_args()
    if args.updates is None:
        args.updates = args.bc_every
    if args.updates < args.bc_every or args.updates % args.bc_every:
        parser.error(f"--updates {args.updates} must be a positive multiple of --bc-every {args.bc_every}, "
                     "so that the cloning bursts are averaged in as in training")
    obs, act, bound = TASKS[args.task]
    obs, act = args.obs or obs, args.act or act
    torch.set_num_threads(args.threads)
    if args.no_torch_fastpath:
        torch.backends.mha.set_fastpath_enabled(False)
    torch.manual_seed(0)
    agent = Vdpo(args, obs, act, bound)
    batch = random_batch(args.batch, obs, act, args.delay)

    # Warm-up, untimed: updates at environment step 0 (no burst) and a few cloning steps.
    for k in range(args.warmup):
        agent.update(batch, 0, k)
    agent.clone_reference(batch, 3)
    # As after dhrl's untimed update(0): the schedule has seen step 0 and 0 updates.
    agent.last_env_steps, agent.bc_seconds, agent.bc_bursts = 0, 0.0, 0
    start = time.perf_counter()
    for k in range(1, args.updates + 1):
        agent.update(batch, k, k)
    seconds = time.perf_counter() - start
    torch_rate = args.updates / seconds
    torch_ms = 1e3 * seconds / args.updates
    expected_bursts = args.updates // args.bc_every
    assert agent.bc_bursts == expected_bursts, (agent.bc_bursts, expected_bursts)

    report = {"algo": "vdpo", "task": args.task, "obs": obs, "act": act, "delay": args.delay, "batch": args.batch,
              "threads": args.threads, "updates": args.updates, "bc_every": args.bc_every,
              "bc_updates": args.bc_updates, "bc_bursts": agent.bc_bursts, "torch": torch.__version__,
              "torch_updates_per_sec": round(torch_rate, 2),
              "torch_ms_per_update": round(torch_ms, 3),
              "torch_bc_share": round(agent.bc_seconds / seconds, 3)}
    if args.products:
        gflop, products_ms = products_alone(agent, batch, args.updates + 1, args.bc_every)
        report.update({"products_gflop_per_update": round(gflop, 3), "products_ms": round(products_ms, 2),
                       "products_gflop_per_sec": round(gflop / products_ms * 1e3, 1),
                       "torch_other_ms": round(torch_ms - products_ms, 2),
                       "torch_over_products": round(torch_ms / products_ms, 3),
                       "other_ms_at_1_5x": round(torch_ms / 1.5 - products_ms, 2)})
    if not args.torch_only:
        settings = {"critic_learning_rate": args.critic_lr, "learning_rate": args.actor_lr,
                    "temperature_learning_rate": args.temperature_lr, "actor_every": args.actor_every,
                    "belief_width": args.belief_width, "belief_blocks": args.belief_blocks,
                    "belief_heads": args.belief_heads, "dropout": args.dropout,
                    "belief_learning_rate": args.belief_lr, "bc_every": args.bc_every,
                    "bc_updates": args.bc_updates, "bc_learning_rate": args.bc_lr,
                    "gamma": args.gamma, "tau": args.tau}
        command = [args.dhrl, "bench", "update", "--algo", "vdpo", "--task", args.task, "--delay", str(args.delay),
                   "--batch-size", str(args.batch), "--updates", str(args.updates), "--threads", str(args.threads),
                   "--json"]
        for field, value in settings.items():
            command += ["--set", f"{field}={value!r}"]
        dhrl = json.loads(subprocess.run(
            command, check=True, capture_output=True, text=True,
            env={**os.environ, "RAYON_NUM_THREADS": str(args.threads)}).stdout)
        report.update({"dhrl_updates_per_sec": round(dhrl["updates_per_sec"], 2),
                       "dhrl_ms_per_update": round(dhrl["ms_per_update"], 3),
                       "ratio": round(dhrl["updates_per_sec"] / torch_rate, 3)})
        if args.products:
            report["dhrl_other_ms"] = round(dhrl["ms_per_update"] - report["products_ms"], 2)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
