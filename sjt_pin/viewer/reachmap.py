"""The page of a reachability map (:class:`~sjt_pin.reach.ReachMap`): the robot at its
reference configuration and the grid points it reaches, each coloured by the fraction of the
orientations reached there, with a colour legend.

Built on :class:`~.viewer.Viewer` (its ``meshcat`` scene and :meth:`~.viewer.Viewer.static_html`):
the cloud is one meshcat ``Points`` object with a colour per point, and the legend a block of
HTML added to the page's side panel. Points where no orientation was reached are not drawn.
"""

from __future__ import annotations

import html
from pathlib import Path

import meshcat.geometry as mg
import numpy as np

from ..robot import Robot
from .viewer import Viewer

#: the colour scale (viridis' ends and three stops between): fraction 0 ... 1
SCALE = np.array([[0x44, 0x01, 0x54], [0x3b, 0x52, 0x8b], [0x21, 0x91, 0x8c],
                  [0x5e, 0xc9, 0x62], [0xfd, 0xe7, 0x25]]) / 255.0
NODE = "reach/points"
LEGEND_CLASS = "reach-legend"


def colors(fraction: np.ndarray) -> np.ndarray:
    """RGB in [0, 1] (N, 3) of fractions in [0, 1] on :data:`SCALE`."""
    x = np.clip(np.asarray(fraction, dtype=float), 0.0, 1.0) * (len(SCALE) - 1)
    low = np.minimum(np.floor(x).astype(int), len(SCALE) - 2)
    t = (x - low)[:, None]
    return (1.0 - t) * SCALE[low] + t * SCALE[low + 1]


def _css(rgb) -> str:
    r, g, b = (int(round(255 * c)) for c in rgb)
    return f"rgb({r},{g},{b})"


def legend_html(reach_map) -> str:
    """The legend: the colour scale, what a point is, and the map's numbers."""
    fraction = reach_map.fraction
    stops = ", ".join(f"{_css(c)} {100 * k / (len(SCALE) - 1):.0f}%" for k, c in enumerate(SCALE))
    drawn = int(np.count_nonzero(fraction > 0))
    state = ("" if reach_map.complete else
             f" Partial map: {reach_map.done:,} of {reach_map.poses:,} poses solved so far.")
    return (f'<section class="{LEGEND_CLASS}">'
            f"<h2>Fraction of orientations reached</h2>"
            f'<div class="bar" style="height:14px;border-radius:3px;'
            f'background:linear-gradient(to right, {stops})"></div>'
            '<div style="display:flex;justify-content:space-between;font-size:12px">'
            "<span>0 %</span><span>50 %</span><span>100 %</span></div>"
            f'<p class="guide">Each dot is a point of a {100 * reach_map.step:g} cm grid where '
            f"<b>{html.escape(reach_map.frame)}</b> reaches at least one of "
            f"{len(reach_map.orientations)} orientations (evenly spread over all rotations), "
            "coloured by the fraction it reaches; points reached in no orientation are not "
            f"drawn. {drawn:,} of {len(fraction):,} points within {reach_map.radius:.2f} m of "
            f"the shoulder; {100 * reach_map.reached.mean():.1f} % of all "
            f"{reach_map.poses:,} poses reached.{state}</p></section>")


def reach_viewer(reach_map, robot: Robot, size: float | None = None) -> Viewer:
    """A viewer (no live server) with ``robot`` at ``q0`` and the map's cloud; ``size``: the
    dots' size (three.js units; default 0.4 of the grid's step)."""
    viewer = Viewer(robot, live=False, label=robot.name)
    fraction = reach_map.fraction
    shown = fraction > 0
    points = reach_map.positions[shown]
    if len(points) == 0:
        return viewer
    geometry = mg.PointsGeometry(points.T, color=colors(fraction[shown]).T)
    viewer.meshcat[NODE].set_object(mg.Points(
        geometry, mg.PointsMaterial(size=size or 0.4 * reach_map.step)))
    return viewer


def reach_page(reach_map, robot: Robot) -> str:
    """The self-contained page of ``reach_map`` (works offline)."""
    viewer = reach_viewer(reach_map, robot)
    title = f"sjt-pin reach: {reach_map.robot}"
    description = (f"Reachability of {reach_map.frame} by solve() within the joint limits: "
                   f"{reach_map.poses:,} poses, {reach_map.budget} iterations each.")
    page = viewer.static_html(title, description)
    # under the title and the description, at the top of the side panel
    at = page.index("</p>", page.index("</h1>")) + len("</p>")
    return page[:at] + "\n" + legend_html(reach_map) + page[at:]


def save_reach_page(reach_map, robot: Robot, path: str | Path) -> Path:
    """Write :func:`reach_page` to ``path``; returns the path."""
    path = Path(path)
    path.write_text(reach_page(reach_map, robot), encoding="utf-8")
    return path
