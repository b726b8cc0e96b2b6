"""The self-contained page of a scene: the 3-D view and, beside it, what it shows.

The page has a title, a short guide to what the lines and spheres are, and one block per robot:
its label, a legend of its runs (method, colour, largest error) and a plot of each run's error
over time (:mod:`.plot`). Under the view are a play/pause button, a time slider and a button
that puts the camera back. The animation plays when the page opens. The camera frames every
robot, and a tag over each robot names it and the method being replayed (:mod:`.page_script`).

Everything is inline: meshcat's viewer script, the scene's packed commands (base64), the style,
the plots and the page's script. The page loads nothing else and works offline.
"""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import meshcat

from ..tracking import TrackingLog
from .page_script import SCRIPT
from .plot import Series, error_plot
from .style import DESIRED_COLOR, METHOD_NAMES, css

MESHCAT_JS = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"


@dataclass(frozen=True)
class Run:
    """One animated run: ``log`` replayed from ``start`` to ``end`` s of the timeline, shown as
    ``label`` (its method's name by default) in its ``color``."""

    label: str
    method: str
    color: int
    start: float
    end: float
    log: TrackingLog


@dataclass(frozen=True)
class RobotEntry:
    """A robot of the scene: its node name, the label shown for it, its runs in order,
    further plots (SVG markup) shown under its error plot, and notes (plain text) on what its
    drawing shows, under its label."""

    node: str
    label: str
    runs: tuple[Run, ...]
    plots: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


#: Height (px) of a robot's error plot: the demo's four robots' blocks and the guide fit a
#: 900 px window.
PLOT_HEIGHT = 76
#: Width (px) of each of two plots side by side (a robot with a closest-distance plot).
PLOT_WIDTH_BESIDE = 190

STYLE = """
html, body { margin: 0; height: 100%; }
body { display: flex; font: 14px/1.4 system-ui, -apple-system, "Segoe UI", sans-serif;
       color: #1d1d1f; background: #fff; }
#view { position: relative; flex: 1 1 auto; min-width: 0; height: 100vh; overflow: hidden;
        display: flex; flex-direction: column; }
#meshcat-pane { flex: 1 1 auto; min-height: 0; }
#panel { flex: 0 0 420px; height: 100vh; overflow-y: auto; box-sizing: border-box;
         padding: 14px 16px; border-left: 1px solid #d8dbe0; background: #fafbfc; }
h1 { font-size: 16px; margin: 0 0 4px; }
h2 { font-size: 15px; margin: 10px 0 2px; }
p { margin: 4px 0; }
.guide { color: #444; font-size: 13px; }
.guide b { color: #1d1d1f; }
.guide span.key { display: inline-block; vertical-align: middle; margin: 0 3px 0 1px; }
.robot { border-top: 1px solid #e1e4e8; margin-top: 8px; }
.robot .head { display: flex; flex-wrap: wrap; align-items: baseline; gap: 0 10px; }
.methods, .legend { list-style: none; margin: 4px 0; padding: 0; font-size: 13px; }
.methods { display: flex; flex-wrap: wrap; gap: 0 12px; }
.methods li { white-space: nowrap; }
h1 + p { font-size: 13px; }  /* the description */
.legend { display: flex; flex-wrap: wrap; gap: 2px 2px; }
.legend li { padding: 1px 4px; border-radius: 4px; white-space: nowrap;
             font-variant-numeric: tabular-nums; }
.legend li.playing { background: #ffe9a8; }
.methods .name, .legend .num { color: #555; }
.swatch { display: inline-block; width: 14px; height: 4px; border-radius: 2px;
          vertical-align: middle; margin-right: 3px; }
.dot { display: inline-block; width: 10px; height: 10px; border-radius: 50%;
       vertical-align: middle; }
.dot.halo { width: 14px; height: 14px; background: rgba(34, 34, 34, 0.3); }
.dots { font-size: 16px; line-height: 1; letter-spacing: 1px; }
.plots { display: flex; gap: 8px; }
svg.error-plot { display: block; margin-top: 2px; font-size: 10px; fill: #444; }
svg.error-plot .frame { fill: #fff; stroke: #c9ced6; }
svg.error-plot .grid { stroke: #eceef1; }
svg.error-plot .axis { stroke: #888; }
svg.error-plot polyline { fill: none; stroke-width: 1.6; }
svg.error-plot .cursor { stroke-width: 1.5; stroke-dasharray: 3 2; }
#controls { display: flex; gap: 10px; align-items: center; padding: 8px 12px;
            background: #fafbfc; border-top: 1px solid #d8dbe0; }
#controls button { font: inherit; padding: 4px 12px; border: 1px solid #8a94a3;
                   border-radius: 4px; background: #fff; cursor: pointer; }
#controls button#play { min-width: 84px; font-weight: 600; }
#controls input { flex: 1 1 auto; }
#clock { min-width: 92px; font-variant-numeric: tabular-nums; }
.tag { position: absolute; transform: translate(-50%, -100%); padding: 2px 8px;
       border-radius: 10px; background: rgba(255, 255, 255, 0.9); border: 1px solid #c9ced6;
       font-size: 13px; white-space: nowrap; pointer-events: none; }
@media (max-width: 800px) {
  body { flex-direction: column; }
  #view { height: 65vh; flex: 0 0 auto; }
  #panel { flex: 1 0 auto; height: auto; border-left: 0; }
}
"""


def page_html(commands: Sequence[bytes], robots: Sequence[RobotEntry], title: str,
              description: str, view: Sequence[float] | None,
              dots: Sequence[str] = ()) -> str:
    """The page of a scene rebuilt by ``commands`` (packed meshcat commands) with ``robots``.

    ``description`` is a paragraph of text under the title. ``view`` is the direction (world)
    the camera frames the scene from; None keeps the camera the scene sets. ``dots`` are the
    nodes of desired paths' dots, sized in pixels once the view is framed.
    """
    meta = {
        "view": None if view is None else [float(v) for v in view],
        "dots": list(dots),
        "robots": [{"node": r.node, "label": r.label,
                    "runs": [{"method": run.label, "color": css(run.color), "start": run.start,
                              "end": run.end} for run in r.runs]} for r in robots],
    }
    scene = [base64.b64encode(c).decode("ascii") for c in commands]
    duration = max((run.end for r in robots for run in r.runs), default=0.0)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{html.escape(title)}</title>
<style>{STYLE}</style>
</head>
<body>
<div id="view">
<div id="meshcat-pane"></div>
{_controls(duration, reset=view is not None)}
</div>
<aside id="panel">
<h1>{html.escape(title)}</h1>
{f"<p>{html.escape(description)}</p>" if description else ""}
{_guide(robots)}
{"".join(_robot(r) for r in robots)}
<p class="guide">Drag to turn the view, scroll to zoom, right-drag to pan.</p>
</aside>
<script>{MESHCAT_JS.read_text(encoding="utf-8")}</script>
<script type="application/json" id="sjt-meta">{_json(meta)}</script>
<script type="application/json" id="sjt-scene">{_json(scene)}</script>
<script>{SCRIPT}</script>
</body>
</html>
"""


#: Characters written as JSON escapes inside a ``<script>`` element: with ``<`` and ``>`` as
#: ``\u003c`` and ``\u003e``, no ``</script``, ``<script`` or ``<!--`` in a name can end the
#: element or switch the HTML parser into a state that swallows the scripts after it.
_SCRIPT_ESCAPES = str.maketrans({"<": "\\u003c", ">": "\\u003e", "&": "\\u0026",
                                 "\u2028": "\\u2028", "\u2029": "\\u2029"})


def _json(value) -> str:
    """JSON that is safe inside a ``<script>`` element, whatever strings ``value`` holds."""
    return json.dumps(value, separators=(",", ":")).translate(_SCRIPT_ESCAPES)


def _controls(duration: float, reset: bool) -> str:
    """Play/pause, a time slider to ``duration`` s, and (if ``reset``) a button to reframe."""
    if duration <= 0:
        return ""
    button = '<button id="reset-view" type="button">Reset view</button>' if reset else ""
    return (f'<div id="controls"><button id="play" type="button">Pause</button>'
            f'<input id="time" type="range" min="0" max="{duration:.3f}" step="0.01" value="0" '
            f'aria-label="animation time (s)"><span id="clock">0.0 s</span>{button}</div>')


def _guide(robots: Sequence[RobotEntry]) -> str:
    """What the colours, dots and spheres stand for: the methods, the desired path, the target."""
    runs = {run.label: (run.method, run.color) for r in robots for run in r.runs}  # first of each
    if not runs:
        return ""
    methods = "".join(
        f'<li><span class="swatch" style="background:{css(color)}"></span>'
        f'<b>{html.escape(label.upper())}</b> '
        f'<span class="name">{html.escape(METHOD_NAMES.get(method, ""))}</span></li>'
        for label, (method, color) in runs.items())
    return (f'<ul class="methods">{methods}</ul>'
            f'<p class="guide"><span class="key dots" style="color:{css(DESIRED_COLOR)}">'
            "&#8226;&#8226;&#8226;</span> desired path, <span class=\"key dot halo\"></span> "
            "target; in a method's colour: its path and end effector; highlighted: the run on "
            "screen; numbers: largest errors.</p>")


def _robot(robot: RobotEntry) -> str:
    """The robot's label, its runs (method, colour, largest error) and their error plot."""
    node = html.escape(robot.node, quote=True)
    parts = [f'<section class="robot" data-robot="{node}">',
             f'<div class="head"><h2>{html.escape(robot.label)}</h2>']
    if robot.runs:
        items = "".join(
            f'<li data-method="{html.escape(run.label, quote=True)}">'
            f'<span class="swatch" style="background:{css(run.color)}"></span>'
            f'<b>{html.escape(run.label.upper())}</b> <span class="num">'
            f'{"diverged" if run.log.diverged else _short(run.log.max_error)}</span></li>'
            for run in robot.runs)
        parts.append(f'<ul class="legend">{items}</ul>')
    parts.append("</div>")  # the label and its legend on one line where they fit
    parts.extend(f'<p class="guide">{html.escape(note)}</p>' for note in robot.notes)
    if robot.runs:
        series = [Series(run.label, run.color, run.log.t - run.log.t[0], run.log.error_norm)
                  for run in robot.runs]
        # a robot with further plots (the closest distance) shows them beside its error plot
        width = 388 if not robot.plots else PLOT_WIDTH_BESIDE
        parts.append('<div class="plots">' + error_plot(
            series, width=width, height=PLOT_HEIGHT, ylabel="tracking error (m, rad)"))
        parts.extend(robot.plots)
        parts.append("</div>")
    else:
        parts.extend(robot.plots)
    parts.append("</section>")
    return "\n".join(parts)


def _short(value: float) -> str:
    """``value`` with two significant digits, e.g. 3.3e-5."""
    mantissa, exponent = f"{value:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"
