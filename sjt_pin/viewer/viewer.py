"""Meshcat viewer: robots, animated tracking runs, paths, frames, ellipsoids, static HTML.

The viewer knows robots and :class:`~sjt_pin.tracking.TrackingLog` objects, nothing of solvers.
Its meshcat server listens on 127.0.0.1 only and stops when the viewer is closed, when the
program exits, or when the program is killed (see :mod:`.server`).

Several robots can share one scene (``add_robot`` with an ``offset``); every drawing method takes
``robot=`` to pick one (default: the first). Animations of all robots share one timeline.
"""

from __future__ import annotations

import contextlib
import io
import webbrowser
from collections.abc import Mapping, Sequence
from pathlib import Path

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from pinocchio.visualize import MeshcatVisualizer

from .server import LoopbackServer
from ..robot import Robot
from ..tracking import TrackingLog

#: Colours of the methods (as in the figures) and of the desired path.
METHOD_COLORS = {"sjt": 0x1F77B4, "jt": 0xD62728, "jp": 0x2CA02C, "dls": 0x9467BD}
DESIRED_COLOR = 0x222222
_NAMED = {"blue": 0x1F77B4, "red": 0xD62728, "green": 0x2CA02C, "purple": 0x9467BD,
          "orange": 0xFF7F0E, "black": 0x000000, "gray": 0x7F7F7F, "white": 0xFFFFFF}


def _color(color) -> int:
    """``0xRRGGBB``, a name in ``_NAMED``, or an (r, g, b) triple in [0, 1], as an int."""
    if isinstance(color, str):
        if color not in _NAMED:
            raise ValueError(f"color must be one of {sorted(_NAMED)}, an int or an RGB triple")
        return _NAMED[color]
    if isinstance(color, (int, np.integer)):
        return int(color)
    rgb = np.clip(np.asarray(color, dtype=float)[:3], 0.0, 1.0)
    return int(rgb[0] * 255) << 16 | int(rgb[1] * 255) << 8 | int(rgb[2] * 255)


def _points(points, name: str = "points") -> np.ndarray:
    """``points`` as a finite (N, 3) array (meshcat wants its transpose)."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 2:
        raise ValueError(f"{name} must have shape (N, 3) with N >= 2, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


class _Rig:
    """One robot in the scene: its Pinocchio visualizer under the node ``name``."""

    def __init__(self, viewer: meshcat.Visualizer, robot: Robot, name: str, offset, color):
        if robot.visual_model is None:
            raise ValueError(f"robot {robot.name!r} has no visual model to draw")
        self.robot, self.name = robot, name
        self.viz = MeshcatVisualizer(robot.model, None, robot.visual_model)
        self.viz.initViewer(viewer=viewer)
        self.viz.loadViewerModel(rootNodeName=name, visual_color=color)
        self.offset = np.asarray(offset, dtype=float)
        viewer[name].set_transform(pin.SE3(np.eye(3), self.offset).homogeneous)
        self.nodes = [self.viz.getViewerNodeName(g, pin.GeometryType.VISUAL)
                      for g in robot.visual_model.geometryObjects]
        self.data = robot.model.createData()
        self.geometry_data = pin.GeometryData(robot.visual_model)

    def placements(self, q: np.ndarray) -> list[np.ndarray]:
        """4x4 world placements of every visual geometry at ``q`` (rotation and translation)."""
        pin.forwardKinematics(self.robot.model, self.data, q)
        pin.updateGeometryPlacements(self.robot.model, self.data, self.robot.visual_model,
                                     self.geometry_data)
        return [M.homogeneous for M in self.geometry_data.oMg]


class Viewer:
    """A meshcat scene with one or more robots.

    Args:
        robot: the first robot, added under the node ``name`` with its base at ``offset`` (m).
        open: open the scene in the default web browser.
    Use as a context manager (or call :meth:`close`) to stop the server.
    """

    def __init__(self, robot: Robot, open: bool = False, *, name: str = "robot",
                 offset=(0.0, 0.0, 0.0)):
        self._server = LoopbackServer()
        with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL on connect
            self.meshcat = meshcat.Visualizer(zmq_url=self._server.zmq_url)
        self._rigs: dict[str, _Rig] = {}
        self._animation = Animation()
        self._animated = False
        self.add_robot(robot, name, offset)
        self.set_camera([1.8, 1.1, 0.9])
        if open:
            webbrowser.open(self.url, new=2)

    # -- scene -----------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The live viewer's address (on 127.0.0.1)."""
        return self._server.web_url

    def add_robot(self, robot: Robot, name: str, offset=(0.0, 0.0, 0.0), color=None) -> None:
        """Add ``robot`` under node ``name``, its base moved by ``offset`` (m, world axes).

        ``color`` (RGBA in [0, 1]) overrides the URDF colours, e.g. for a ghost.
        """
        if name in self._rigs:
            raise ValueError(f"name {name!r} is already in the scene")
        self._rigs[name] = _Rig(self.meshcat, robot, name, offset, color)
        self.show(robot.q0, robot=name)

    def _rig(self, robot: str | None) -> _Rig:
        if robot is None:
            return next(iter(self._rigs.values()))
        if robot not in self._rigs:
            raise ValueError(f"robot must be one of {list(self._rigs)}, got {robot!r}")
        return self._rigs[robot]

    def set_camera(self, position) -> None:
        """Put the camera at ``position`` (world, m); it looks at the world origin.

        Pinocchio's camera helpers fail with meshcat 0.3.2; this sets the camera node directly.
        """
        x, y, z = np.asarray(position, dtype=float)
        # the camera lives in three.js' y-up frame: world (x, y, z) is (x, z, -y) there
        self.meshcat["/Cameras/default/rotated/<object>"].set_property("position", [x, z, -y])

    def show(self, q, robot: str | None = None) -> None:
        """Place ``robot`` at configuration ``q``."""
        rig = self._rig(robot)
        rig.viz.display(rig.robot.check_q(q))

    # -- drawings ----------------------------------------------------------------------------
    def draw_path(self, points, color="blue", name: str = "path", robot: str | None = None,
                  linewidth: float = 2.0) -> None:
        """A polyline through ``points`` (N, 3) in m, in the frame of ``robot``'s base."""
        pts = _points(points)
        material = mg.LineBasicMaterial(color=_color(color), linewidth=linewidth)
        node = f"{self._rig(robot).name}/paths/{name}"
        self.meshcat[node].set_object(mg.Line(mg.PointsGeometry(pts.T), material))

    def draw_frame(self, pose, name: str = "frame", robot: str | None = None,
                   length: float = 0.1) -> None:
        """A triad (x red, y green, z blue) of ``length`` m at ``pose`` (``pin.SE3`` or 4x4)."""
        T = pose.homogeneous if isinstance(pose, pin.SE3) else np.asarray(pose, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("pose must be a pin.SE3 or a finite 4x4 matrix")
        node = self.meshcat[f"{self._rig(robot).name}/frames/{name}"]
        node.set_object(mg.triad(length))
        node.set_transform(T)

    def draw_ellipsoid(self, center, transform, name: str = "ellipsoid", color="blue",
                       opacity: float = 0.4, scale: float = 1.0, robot: str | None = None) -> None:
        """The motion ellipsoid ``{T u : |u| <= 1}`` of ``transform`` (2 or 3 rows) at ``center``.

        For instance T = J^T or D J^T of a planar arm (paper Figs. 2-3), or the task-space loop
        ``J M`` of a method. ``scale`` multiplies the semi-axes (drawing units); 2-row transforms
        are drawn as flat ellipses in the x-y plane.
        """
        T = np.asarray(transform, dtype=float)
        if T.ndim != 2 or T.shape[0] not in (2, 3) or not np.all(np.isfinite(T)):
            raise ValueError(f"transform must be a finite matrix with 2 or 3 rows, got {T.shape}")
        U, sigma, _ = np.linalg.svd(T)
        radii = np.full(3, 1e-3)
        rotation = np.eye(3)
        k = min(T.shape)
        radii[:k] = np.maximum(scale * sigma[:k], 1e-4)
        rotation[: T.shape[0], : T.shape[0]] = U
        if np.linalg.det(rotation) < 0:
            rotation[:, -1] *= -1
        node = self.meshcat[f"{self._rig(robot).name}/ellipsoids/{name}"]
        node.set_object(mg.Ellipsoid(radii), mg.MeshLambertMaterial(
            color=_color(color), opacity=opacity, transparent=opacity < 1.0))
        node.set_transform(pin.SE3(rotation, np.asarray(center, dtype=float)).homogeneous)

    # -- animations --------------------------------------------------------------------------
    def animate(self, log: TrackingLog, fps: float = 30.0, robot: str | None = None,
                color=None, start: float = 0.0) -> float:
        """Play ``log`` on ``robot`` from ``start`` s of the timeline; returns its end time.

        Draws the desired path (dark) and the path followed (``color``, default the method's);
        the target and the end effector are drawn as spheres that move with the animation.
        """
        if not isinstance(log, TrackingLog) or len(log) == 0:
            raise ValueError("log must be a non-empty TrackingLog")
        rig = self._rig(robot)
        color = METHOD_COLORS.get(log.method, 0x1F77B4) if color is None else color
        label = log.method or "run"
        self.draw_path(log.target, DESIRED_COLOR, "desired", robot=rig.name)
        self.draw_path(log.position, color, label, robot=rig.name)
        target_node = f"{rig.name}/markers/target"
        ee_node = f"{rig.name}/markers/ee"
        self.meshcat[target_node].set_object(
            mg.Sphere(0.012), mg.MeshLambertMaterial(color=DESIRED_COLOR))
        self.meshcat[ee_node].set_object(mg.Sphere(0.01), mg.MeshLambertMaterial(color=_color(
            color)))
        self._animation.default_framerate = fps
        frames = np.arange(0.0, log.t[-1] + 0.5 / fps, 1.0 / fps)
        indices = np.minimum(np.searchsorted(log.t, frames), len(log) - 1)
        first = int(round(start * fps))
        for k, i in enumerate(indices):
            with self._animation.at_frame(self.meshcat, first + k) as frame:
                for node, T in zip(rig.nodes, rig.placements(log.q[i]), strict=True):
                    frame[node].set_transform(T)
                frame[target_node].set_transform(_translation(log.target[i]))
                frame[ee_node].set_transform(_translation(log.position[i]))
        self.meshcat.set_animation(self._animation, play=True, repetitions=1000)
        return start + frames[-1] + 1.0 / fps

    def compare(self, logs: Mapping[str, TrackingLog] | Sequence[TrackingLog], fps: float = 30.0,
                robot: str | None = None) -> None:
        """Several methods' runs on ``robot``, one after another on the timeline.

        Each run's followed path stays drawn in its method's colour, so the paths can be
        compared side by side while the robot replays the runs in turn.
        """
        runs = list(logs.values()) if isinstance(logs, Mapping) else list(logs)
        if not runs:
            raise ValueError("logs must hold at least one TrackingLog")
        start = 0.0
        for log in runs:
            start = self.animate(log, fps=fps, robot=robot, start=start)

    # -- output ------------------------------------------------------------------------------
    def static_html(self) -> str:
        """One self-contained HTML page of the scene and its animation (works offline)."""
        return self.meshcat.static_html()

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path``."""
        path = Path(path)
        path.write_text(self.static_html(), encoding="utf-8")
        return path

    def jupyter_cell(self, height: int = 400):
        """The live viewer in a Jupyter cell (an iframe on :attr:`url`)."""
        return self.meshcat.jupyter_cell(height=height)

    def close(self) -> None:
        """Stop the meshcat server (idempotent)."""
        self._server.close()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Viewer({list(self._rigs)}, url={self.url!r})"


def _translation(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T
