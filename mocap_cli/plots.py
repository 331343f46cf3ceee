"""Plots for `mocap eval` (PNG, like the thesis's Figures 4.2-4.12)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mocap_core.skeleton import INDEX  # noqa: E402

COLOURS = {"ccd": "tab:blue", "fabrik": "tab:red", "jacobian_transpose": "tab:green", "dls": "tab:purple"}


def error_plot(runs, rate_hz: float, path: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=110)
    for r in runs:
        frames = np.arange(r.frames[0], r.frames[-1] + 1)
        error = np.full(len(frames), np.nan)  # NaN between short gaps breaks the line there
        error[r.frames - r.frames[0]] = r.error_m[:, 0]
        ax.plot(frames / rate_hz, error, label=f"{r.solver}", color=COLOURS.get(r.solver), lw=1.2)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"distance to true {runs[0].joints[0]} (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def trajectory_plot(runs, reference: np.ndarray, start: int, stop: int, path: Path, title: str) -> None:
    fig = plt.figure(figsize=(6, 5.5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    j = INDEX[runs[0].joints[0]]
    ref = reference[start:stop, j]
    ax.plot(*ref.T, color="black", lw=2, label="true (localized)")
    for r in runs:
        est = r.estimate[start:stop, 0]
        ax.plot(*est.T, color=COLOURS.get(r.solver), lw=1, label=r.solver)
    ax.set_title(title)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def move_ratio_plot(ratios: dict[str, np.ndarray], path: Path, title: str) -> None:
    """How many moves exceed each multiple of the normal per-frame motion, one line per fill."""
    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=110)
    for name, r in ratios.items():
        x = np.sort(r)[::-1]
        ax.step(x, np.arange(1, len(x) + 1), where="post", label=name, lw=1.4)
    ax.axvline(1.5, color="grey", ls="--", lw=1, label="1.5x (the targets' bound)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("move / normal per-frame motion")
    ax.set_ylabel("moves at least this large")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def targets_plot(checks, path: Path) -> None:
    """Each case's figure as a share of its target's limit (`mocap eval targets`): a bar a case under its target's
    name, the limit at 1."""
    rows = []  # (label, check or None for a target's name), top to bottom
    for i, c in enumerate(checks):
        if i == 0 or checks[i - 1].target != c.target:
            rows.append((c.target, None))
        rows.append((c.case, c))
    y = np.arange(len(rows))[::-1]
    fig, ax = plt.subplots(figsize=(8, 0.16 * len(rows) + 1.0), dpi=110)
    for yi, (label, c) in zip(y, rows):
        if c is None:
            ax.text(0.0, yi, label, fontsize=7, weight="bold", va="center", transform=ax.get_yaxis_transform())
        else:
            ax.barh(yi, np.nan_to_num(c.of_limit), color="tab:green" if c.met else "tab:red", height=0.7)
    ax.axvline(1.0, color="black", lw=1)
    ax.set_yticks([yi for yi, (_, c) in zip(y, rows) if c is not None],
                  [label for label, c in rows if c is not None], fontsize=6)
    ax.set_xlabel("figure / limit (met at 1 or under)")
    ax.set_title(f"the gap-filling targets: {sum(c.met for c in checks)} of {len(checks)} cases met", fontsize=9)
    ax.set_ylim(-0.6, len(rows) - 0.4)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def spacing_plot(rec, faults, path: Path, title: str, most: int = 8) -> None:
    """Each faulty pair's distance over time (`mocap check`): its usual spacing dashed, the stretches off shaded; the
    ``most`` pairs with the most frames off."""
    frames_off = {}
    for f in faults:
        frames_off[f.pair] = frames_off.get(f.pair, 0) + f.frames
    pairs = sorted(frames_off, key=lambda p: -frames_off[p])[:most]
    times = rec.times()
    fig, axes = plt.subplots(len(pairs), 1, figsize=(9, 1.5 * len(pairs) + 0.8), dpi=100, sharex=True, squeeze=False)
    for ax, pair in zip(axes[:, 0], pairs):
        d = np.linalg.norm(rec.positions[:, pair.ia] - rec.positions[:, pair.ib], axis=1) * 1000
        ax.plot(times, d, lw=0.8, color="tab:blue")
        stretches = [f for f in faults if f.pair == pair]
        ax.axhline(stretches[0].usual_m * 1000, color="black", lw=0.8, ls="--")
        for f in stretches:
            ax.axvspan(f.start_s, f.end_s + 1 / rec.rate_hz, color="tab:red", alpha=0.25, lw=0)
        ax.set_ylabel("mm", fontsize=7)
        ax.set_title(f"{pair.bone}: {pair.a} to {pair.b}", fontsize=8, loc="left")
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
