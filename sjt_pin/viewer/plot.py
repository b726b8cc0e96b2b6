"""Tracking errors over time as a small inline SVG plot: one line per method, log scale.

The plot is plain SVG markup with no script and no external resource. It draws each series'
largest error in each of ``points`` time bins, so a peak shows however many samples a run has.
A hidden ``line.cursor`` can be moved by the page's script: the ``svg`` carries the pixel
positions of t = 0 and of the last time (``data-x0``, ``data-x1``) and that time
(``data-t1``, s).
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .style import css

_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
_LEFT, _RIGHT, _TOP, _BOTTOM = 44, 10, 18, 30  # margins, px


@dataclass(frozen=True)
class Series:
    """One line: ``values`` (e.g. the error norm, m or rad) at times ``t`` (s)."""

    label: str
    color: int
    t: np.ndarray
    values: np.ndarray


def error_plot(series: Sequence[Series], width: int = 330, height: int = 160,
               points: int = 200, ylabel: str = "error") -> str:
    """An SVG element plotting ``series`` against time, ``width`` x ``height`` px."""
    if not series:
        raise ValueError("series must hold at least one Series")
    t_end = max(float(s.t[-1]) for s in series) or 1.0
    lo, hi = _decades(np.concatenate([s.values for s in series]))
    x0, x1, y0, y1 = _LEFT, width - _RIGHT, height - _BOTTOM, _TOP

    def x(t):
        return x0 + (x1 - x0) * np.asarray(t) / t_end

    def y(v):
        logs = np.log10(np.clip(np.nan_to_num(v, nan=10.0**hi, posinf=10.0**hi), 10.0**lo,
                                10.0**hi))
        return y0 + (y1 - y0) * (logs - lo) / (hi - lo)

    out = [f'<svg class="error-plot" viewBox="0 0 {width} {height}" width="{width}" '
           f'height="{height}" role="img" data-x0="{x0}" data-x1="{x1}" data-t1="{t_end:g}">',
           f'<rect x="{x0}" y="{y1}" width="{x1 - x0}" height="{y0 - y1}" class="frame"/>']
    step = 1 if hi - lo <= 4 else 2
    for k in range(lo, hi + 1):
        yk = y(10.0**k)
        out.append(f'<line x1="{x0}" x2="{x1}" y1="{yk:.1f}" y2="{yk:.1f}" class="grid"/>')
        if (hi - k) % step == 0:
            label = f"10{str(k).translate(_SUPERSCRIPT)}"
            out.append(f'<text x="{x0 - 4}" y="{yk + 4:.1f}" text-anchor="end">{label}</text>')
    for tick in _ticks(t_end):
        xt = x(tick)
        out.append(f'<line x1="{xt:.1f}" x2="{xt:.1f}" y1="{y0}" y2="{y0 + 4}" class="axis"/>')
        out.append(f'<text x="{xt:.1f}" y="{y0 + 15}" text-anchor="middle">{tick:g}</text>')
    out.append(f'<text x="{(x0 + x1) / 2:.1f}" y="{height - 2}" text-anchor="middle">'
               "time in the run (s)</text>")
    out.append(f'<text x="{x0}" y="{y1 - 5}">{html.escape(ylabel)}</text>')
    for s in series:
        ts, vs = _peaks(np.asarray(s.t, float), np.asarray(s.values, float), points)
        coords = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(x(ts), y(vs), strict=True))
        name = html.escape(s.label)
        out.append(f'<polyline points="{coords}" stroke="{css(s.color)}" data-label="{name}">'
                   f"<title>{name}: max {np.nanmax(s.values):.2g}</title></polyline>")
    out.append(f'<line class="cursor" x1="{x0}" x2="{x0}" y1="{y1}" y2="{y0}" '
               'visibility="hidden"/>')
    out.append("</svg>")
    return "\n".join(out)


def _decades(values: np.ndarray) -> tuple[int, int]:
    """Powers of ten that bound the values: below, the 1st percentile of the positive ones
    (a run starts on its path, so its first errors are zero or round-off), at most 7 decades."""
    finite = values[np.isfinite(values) & (values > 0)]
    if finite.size == 0:
        return -9, -8
    hi = math.ceil(math.log10(finite.max()))
    lo = math.floor(math.log10(np.percentile(finite, 1)))
    return max(min(lo, hi - 1), hi - 7), hi


def _ticks(t_end: float) -> np.ndarray:
    """Round times from 0 to ``t_end`` s, 3 to 8 of them."""
    for step in (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0):
        if t_end / step <= 7:
            return np.arange(0.0, t_end + 1e-9, step)
    return np.linspace(0.0, t_end, 5)


def _peaks(t: np.ndarray, v: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """The largest value of each of ``points`` equal slices of the samples, at its time."""
    if len(t) <= points:
        return t, v
    picked = [i[np.argmax(np.nan_to_num(v[i], nan=np.inf))]
              for i in np.array_split(np.arange(len(t)), points)]
    return t[picked], v[picked]
