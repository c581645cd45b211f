"""What both examples share: the evaluation of a policy on a delayed task and its learning
curve, written as CSV and as a small SVG (no plotting library needed)."""

from __future__ import annotations

import csv
import pathlib
from typing import Callable

import numpy as np

import dhrl


def evaluate(policy: Callable[[np.ndarray], np.ndarray], task: str, delay: int, episodes: int, seed: int) -> list[float]:
    """Returns of ``episodes`` episodes, one per copy of a fresh env, ``policy`` mapping the
    augmented states ``[N, obs + Δ·act]`` to actions deterministically."""
    env = dhrl.make_vec(task, episodes, delay=delay, seed=seed, episode_statistics=True)
    obs, _ = env.reset()
    returns = np.full(episodes, np.nan)
    while np.isnan(returns).any():
        obs, _, _, _, info = env.step(policy(obs))
        if "episode" in info:
            first = info["_episode"] & np.isnan(returns)
            returns[first] = info["episode"]["r"][first]
    env.close()
    return returns.tolist()


def write_curve(out: pathlib.Path, title: str, rows: list[tuple[int, float, float]]) -> None:
    """``rows`` of (env steps, mean return, std) to ``out``.csv and ``out``.svg."""
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_suffix(".csv.partial")
    with open(partial, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["env_steps", "mean_return", "std_return"])
        writer.writerows(rows)
    partial.replace(out.with_suffix(".csv"))  # atomic: a reader never sees half a file
    width, height, pad = 640, 400, 56
    steps = [r[0] for r in rows]
    top = max(1000.0, max(r[1] + r[2] for r in rows))
    x = lambda s: pad + (width - 2 * pad) * s / max(max(steps), 1)  # noqa: E731
    y = lambda v: height - pad - (height - 2 * pad) * max(v, 0.0) / top  # noqa: E731
    band = [(x(s), y(m + d)) for s, m, d in rows] + [(x(s), y(m - d)) for s, m, d in reversed(rows)]
    line = " ".join(f"{x(s):.1f},{y(m):.1f}" for s, m, _ in rows)
    ticks = "".join(
        f'<text x="{pad - 8}" y="{y(v) + 4:.1f}" text-anchor="end">{v:.0f}</text>'
        f'<line x1="{pad}" x2="{width - pad}" y1="{y(v):.1f}" y2="{y(v):.1f}" stroke="#ddd"/>'
        for v in np.linspace(0, top, 5)
    )
    svg = f"""<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>{ticks}
<polygon points="{' '.join(f'{a:.1f},{b:.1f}' for a, b in band)}" fill="#1f77b4" fill-opacity="0.2"/>
<polyline points="{line}" fill="none" stroke="#1f77b4" stroke-width="2"/>
<text x="{width / 2}" y="24" text-anchor="middle" font-size="14">{title}</text>
<text x="{width / 2}" y="{height - 16}" text-anchor="middle">environment steps (0 to {max(steps):,})</text>
<text x="16" y="{height / 2}" transform="rotate(-90 16 {height / 2})" text-anchor="middle">evaluation return (mean ± std)</text>
</svg>
"""
    partial = out.with_suffix(".svg.partial")
    partial.write_text(svg)
    partial.replace(out.with_suffix(".svg"))
