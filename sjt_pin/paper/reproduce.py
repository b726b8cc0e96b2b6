"""``sjt-pin reproduce``: run the paper's experiments, write the figures and ``results.md``."""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from . import experiments as paper
from . import figures


def _gain(value: float) -> str:
    return "none" if value == 0 else f"{value:.4g}"


def _task_table(sweeps: dict[tuple[str, int], paper.Sweep]) -> list[str]:
    lines = []
    for number in paper.TASKS:
        lines += [
            f"### {figures.TASK_TITLES[number].capitalize()}",
            "",
            "| method | largest stable gain, simulated [1/s] | k_lin [1/s] | simulated / k_lin | "
            "max error at that gain [m] | paper's largest gain |",
            "|---|---|---|---|---|---|",
        ]
        for method in paper.METHODS:
            sw = sweeps[(method, number)]
            ratio = sw.largest_stable_gain / sw.k_lin
            theirs = paper.PAPER_GAINS.get(method, (None,) * 3)[number - 1]
            lines.append(
                f"| {method.upper()} | {_gain(sw.largest_stable_gain)} | {sw.k_lin:.4g} | "
                f"{ratio:.3f} | {sw.error_at_largest:.3g} | {theirs if theirs else '-'} |"
            )
        lines.append("")
    return lines


def _study_table(table: dict, labels: list[str], title: str) -> list[str]:
    lines = [f"| {title} | " + " | ".join(
        f"{m.upper()} task {t} (sim / k_lin)" for m in ("jt", "sjt") for t in (1, 3)) + " |",
        "|---|" + "---|" * 4]
    for label in labels:
        cells = [f"{_gain(table[(m, t, label)][0])} / {table[(m, t, label)][1]:.4g}"
                 for m in ("jt", "sjt") for t in (1, 3)]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines + [""]


def reproduce(out: str | Path, processes: int | None = None, progress: bool = True,
              grid: int = 30) -> Path:
    """Run every experiment of :mod:`sjt_pin.paper.experiments`; write PNG figures and
    ``results.md`` into ``out``.

    ``grid`` is the number of gains per sweep (Fig. 6); fewer is quicker, with the same code.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    settings = paper.PaperSettings()

    postures = paper.ellipsoids()
    figures.save(figures.ellipsoid_figure(postures), out / "fig2_3_ellipsoids.png")
    sweeps = paper.gain_sweeps(settings=settings, processes=processes, progress=progress,
                               grid=grid)
    for number, letter in zip(paper.TASKS, "abc", strict=True):
        figures.save(figures.sweep_figure(sweeps, number), out / f"fig6{letter}_task{number}.png")
    logs = paper.error_series(sweeps, 3)
    figures.save(figures.error_series_figure(logs, 3), out / "fig7_task3_errors.png")
    units = paper.stable_gain_table(paper.unit_variants(settings), processes=processes,
                                    progress="length units" if progress else None)
    dts = paper.stable_gain_table(paper.dt_variants(settings), processes=processes,
                                  progress="control periods" if progress else None)

    jt_m = [sweeps[("jt", n)].largest_stable_gain for n in paper.TASKS]
    unit_for_paper = [np.sqrt(g / p) for g, p in zip(jt_m, paper.PAPER_GAINS["jt"], strict=True)]
    lines = [
        "# The paper's simulations, reproduced",
        "",
        f"Written by `sjt-pin reproduce` in {time.perf_counter() - start:.0f} s "
        f"(Python {platform.python_version()}, Pinocchio {pin.__version__}, "
        f"{platform.machine()}).",
        "",
        "## Settings (the paper gives none of these)",
        "",
        paper.settings_table(settings),
        "- start: elbow up at (60, 45, 30) deg, refined onto the path's first point",
        "- tasks 1 and 2: lines from (-0.293, 0.986) in `line_duration`, then `hold`; task 2's "
        f"target leaves the reach at t = {paper.paper_task(2, settings).reachable_until:.3f} s "
        "and its max error counts only before that",
        "- task 3: circle of radius 0.194 m about (0, 0.986) from (-0.194, 0.986), "
        "counter-clockwise, in `circle_duration`, then `hold`",
        "- errors: x-y position error norm in m; SJT's alpha_i from the 2 rows of the x-y task",
        "- stability: see `sjt_pin.paper.stability` (divergence, a joint above `speed_bound`, or a "
        "period-2 oscillation above `oscillation_tol` that does not die out); the largest stable "
        "gain is bisected to 0.5 %",
        "- k_lin = 2 / (dt max_t lambda_max(J M)) along the path of an accurate DLS run",
        "",
        "## Largest stable gains (Fig. 6)",
        "",
        *_task_table(sweeps),
        "## Length units: what JT's limit depends on",
        "",
        "Every length (arm, paths, errors) multiplied by the unit's factor. `none`: unstable at "
        "every gain (JT's feed-forward J^T x_dot_d alone moves the joints at thousands of rad/s).",
        "",
        *_study_table(units, list(paper.LENGTH_UNITS), "unit"),
        "Length unit that would bring JT's metre limits to the paper's 36 / 25 / 33: "
        + " / ".join(f"{1 / s:.3f} m" for s in unit_for_paper)
        + " (scale " + " / ".join(f"{s:.2f}" for s in unit_for_paper) + ").",
        "",
        "## Control period",
        "",
        *_study_table(dts, list(paper.dt_variants(settings)), "dt"),
        "## Motion ellipsoids of the unit 2-link arm (Figs. 2-3)",
        "",
        "| posture | q [rad] | sigma_max(J^T) | sigma_min(J^T) | sigma_max(D J^T) | "
        "sigma_min(D J^T) |",
        "|---|---|---|---|---|---|",
        *[f"| {k} | ({p['q'][0]:.3f}, {p['q'][1]:.3f}) | {p['jt'].sigma_max:.4f} | "
          f"{p['jt'].sigma_min:.4f} | {p['sjt'].sigma_max:.4f} | {p['sjt'].sigma_min:.4f} |"
          for k, p in enumerate(postures)],
        "",
        "## Fig. 7: task 3 at each method's largest stable gain",
        "",
        "| method | gain [1/s] | max error [m] | RMS error [m] |",
        "|---|---|---|---|",
        *[f"| {m.upper()} | {log.gain:.4g} | {log.max_error:.3g} | {log.rms_error:.3g} |"
          for m, log in logs.items()],
        "",
        "Figures: `fig2_3_ellipsoids.png`, `fig6a_task1.png`, `fig6b_task2.png`, "
        "`fig6c_task3.png`, `fig7_task3_errors.png`.",
        "",
    ]
    path = out / "results.md"
    path.write_text("\n".join(lines))
    return path
