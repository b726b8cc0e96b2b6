"""Matplotlib figures of the paper's experiments (Figs. 2/3, 6 and 7), from the results of
:mod:`sjt_pin.paper.experiments`.

This module leaves matplotlib's backend alone: a notebook keeps its inline backend (the figures
show under the cell that makes them), and :func:`save` writes PNG files with whatever backend the
process has (``savefig`` renders with Agg for PNG whatever the backend; with no display,
matplotlib picks Agg by itself).
"""

from __future__ import annotations

from pathlib import Path

from ..extras import require

require("matplotlib")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..tracking import TrackingLog  # noqa: E402
from .experiments import PAPER_GAINS, Sweep  # noqa: E402

COLORS = {"sjt": "tab:blue", "jt": "tab:red", "jp": "tab:green", "dls": "tab:purple"}
TASK_TITLES = {1: "task 1: line inside the workspace", 2: "task 2: line leaving the workspace",
               3: "task 3: circle touching the reach"}


def ellipsoid_figure(postures: list[dict]) -> plt.Figure:
    """Figs. 2 and 3: motion ellipsoids of J^T and D J^T on the 2-link arm, and their sigmas."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    for ax, key, title in [(axes[0], "jt", "T1 = J^T (JT)"), (axes[1], "sjt", "T2 = D J^T (SJT)")]:
        for k, posture in enumerate(postures):
            elbow, hand = posture["elbow"], posture["hand"]
            ax.plot([0, elbow[0], hand[0]], [0, elbow[1], hand[1]], "-o", color="0.6", lw=1,
                    ms=3)
            outline = hand + 0.25 * posture[key].outline()
            ax.plot(outline[:, 0], outline[:, 1], color=COLORS[key])
            ax.annotate(str(k), hand, textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_title(f"{title}, ellipses x0.25", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    index = np.arange(len(postures))
    ax = axes[2]
    for key, marker in [("jt", "o"), ("sjt", "s")]:
        ax.plot(index, [p[key].sigma_max for p in postures], marker + "-", color=COLORS[key],
                label=f"sigma_max {key.upper()}")
        ax.plot(index, [p[key].sigma_min for p in postures], marker + "--", color=COLORS[key],
                label=f"sigma_min {key.upper()}")
    ax.set_xticks(index)
    ax.set_xlabel("posture (4 = stretched, singular)")
    ax.set_title("singular values (Fig. 3)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def sweep_figure(sweeps: dict[tuple[str, int], Sweep], number: int) -> plt.Figure:
    """Fig. 6 (a-c): max tracking error against the gain, one curve per method."""
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for (method, task), sweep in sweeps.items():
        if task != number:
            continue
        ok = sweep.stable
        ax.loglog(sweep.gains[ok], sweep.max_errors[ok], "o-", ms=3, color=COLORS[method],
                  label=f"{method.upper()} (largest stable {sweep.largest_stable_gain:.4g})")
        ax.axvline(sweep.k_lin, color=COLORS[method], ls=":", lw=1)
        if method in PAPER_GAINS:
            ax.axvline(PAPER_GAINS[method][number - 1], color=COLORS[method], ls="--", lw=1,
                       alpha=0.6)
    ax.set_xlabel("gain k [1/s]  (dotted: k_lin; dashed: paper's limit)")
    ax.set_ylabel("max error [m]" + (" (while reachable)" if number == 2 else ""))
    ax.set_title(TASK_TITLES[number])
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def error_series_figure(logs: dict[str, TrackingLog], number: int = 3) -> plt.Figure:
    """Fig. 7: position error norm over time at each method's largest stable gain."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for method, log in logs.items():
        ax.semilogy(log.t, np.maximum(log.error_norm, 1e-12), color=COLORS[method],
                    label=f"{method.upper()}, k = {log.gain:.4g}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|e| [m]")
    ax.set_title(f"{TASK_TITLES[number]}, each method at its largest stable gain")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def save(fig: plt.Figure, path: str | Path, dpi: int = 90) -> Path:
    """Write ``fig`` as PNG and close it."""
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
