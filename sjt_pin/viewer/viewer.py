"""Meshcat viewer: robots, animated tracking runs, paths, frames, ellipsoids, a static page.

The viewer knows robots and :class:`~sjt_pin.tracking.TrackingLog` objects, nothing of solvers.
The scene is kept in this process (:mod:`.scene`). :meth:`Viewer.save_html` writes it as one
self-contained page, with a legend, error plots and play controls (:mod:`.page`). With
``live=True`` (the default) each change also goes to a meshcat server, whose page shows the
scene as it is built. That server listens on 127.0.0.1 only and stops when the viewer is closed,
when the program exits, or when the program is killed (see :mod:`.server`). Each request to it
waits at most ``timeout`` s: a server that died raises :class:`.ServerTimeout`, and
:meth:`Viewer.restart` starts a new one with the scene so far.

Several robots can share one scene (``add_robot`` with an ``offset``); every drawing method takes
``robot=`` to pick one (default: the first). Animations of all robots share one timeline.
"""

from __future__ import annotations

import html
import webbrowser
from collections.abc import Mapping, Sequence
from pathlib import Path

import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation, AnimationClip, AnimationTrack

from ..robot import Robot
from ..tracking import TrackingLog
from .meshes import visual_parts
from .obstacles import (
    OBSTACLE_COLOR,
    OBSTACLE_OPACITY,
    draw_obstacle,
    key_geometry,
    key_segments,
    show_geometry,
    show_segments,
)
from .page import PLOT_HEIGHT, PLOT_WIDTH_BESIDE, RobotEntry, Run, page_html
from .page_script import DOT_PIXELS
from .plot import Series, error_plot
from .scene import SceneRecord
from .server import LiveWindow, LoopbackServer
from .style import (
    DESIRED_COLOR,
    EXTRA_COLORS,
    METHOD_COLORS,
    OTHER_COLOR,
    SUPPORT_COLOR,
    to_int,
)

#: Direction (world, from the scene's centre) the page's camera looks from unless it is set.
VIEW_DIRECTION = (1.0, 0.3, 0.4)
#: Points drawn of a run's paths (a 0.2 m circle with 500 points is off by 3 um).
PATH_POINTS = 500
#: Dots drawn of a run's desired path, at most.
DESIRED_DOTS = 60
#: Least spacing of those dots along the path, as a fraction of the robot's size (its largest
#: frame distance from its base): a short path gets few dots, far enough apart that the path
#: followed shows between them. They are :data:`.page_script.DOT_PIXELS` wide whatever the
#: distance (the page makes them smaller where they would crowd).
DOT_SPACING = 0.03
#: Radius and thickness (m) of the disc that marks the centre of mass's ground projection, and
#: the height (m) over the contacts at which it and the support polygon are drawn (above the
#: grid, which would hide them).
COM_DISC = (0.025, 0.004)
GROUND_LIFT = 0.002
_NOT_LIVE = ("this viewer has no live server (it was made with live=False, or closed); "
             "restart() starts one")
_GRID_SCALE = 0.25
_BACKGROUND = ([0.97, 0.97, 0.98], [0.80, 0.83, 0.87])  # top and bottom colours, RGB in [0, 1]


def _points(points, name: str = "points") -> np.ndarray:
    """``points`` as a finite (N, 3) array (meshcat wants its transpose)."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 2:
        raise ValueError(f"{name} must have shape (N, 3) with N >= 2, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def _placement(offset) -> np.ndarray:
    """A robot base's 4x4 placement: from a ``pin.SE3``, a 4x4 matrix or a translation (m)."""
    if isinstance(offset, pin.SE3):
        return offset.homogeneous
    arr = np.asarray(offset, dtype=float)
    if arr.shape == (3,):
        return pin.SE3(np.eye(3), arr).homogeneous
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise ValueError("offset must be a translation (3,), a 4x4 matrix or a pin.SE3")
    return arr


class _Rig:
    """One robot in the scene: its visual meshes under the node ``name``, and its runs."""

    def __init__(self, scene: meshcat.Visualizer, robot: Robot, name: str, label: str,
                 placement: np.ndarray, color):
        if robot.visual_model is None:
            raise ValueError(f"robot {robot.name!r} has no visual model to draw")
        self.robot, self.name, self.label = robot, name, label
        self.runs: list[Run] = []
        self.distances: list[Series] = []  # closest distance over each run with a collision
        self.dots: list[str] = []  # nodes of the desired paths' dots
        self.notes: list[str] = []  # what the page says under the robot's label
        self.nodes: list[str] = []
        self.geometries: list[int] = []
        for index, geometry in enumerate(robot.visual_model.geometryObjects):
            parts = visual_parts(geometry, folders=robot.mesh_roots)
            if not parts:
                continue
            node = f"{name}/visuals/{geometry.name}"
            for k, part in enumerate(parts):
                rgba = part.rgba if color is None else tuple(color)
                material = mg.MeshPhongMaterial(color=to_int(rgba[:3]), opacity=float(rgba[3]),
                                                shininess=20.0)
                scene[f"{node}/{k}"].set_object(
                    mg.TriangularMeshGeometry(part.vertices, part.faces), material)
            self.nodes.append(node)
            self.geometries.append(index)
        scene[name].set_transform(placement)
        self.data = robot.model.createData()
        self.geometry_data = pin.GeometryData(robot.visual_model)
        pin.framesForwardKinematics(robot.model, self.data, robot.q0)
        #: The robot's size (m): its farthest frame from its base at ``q0``, at least 5 cm.
        self.size = max(0.05, max(float(np.linalg.norm(f.translation)) for f in self.data.oMf))

    def placements(self, q: np.ndarray) -> list[np.ndarray]:
        """4x4 placements of the drawn geometries at ``q``, in the frame of the robot's base."""
        pin.forwardKinematics(self.robot.model, self.data, q)
        pin.updateGeometryPlacements(self.robot.model, self.data, self.robot.visual_model,
                                     self.geometry_data)
        return [self.geometry_data.oMg[i].homogeneous for i in self.geometries]


class Viewer:
    """A meshcat scene with one or more robots.

    Args:
        robot: the first robot, added under the node ``name`` (shown as ``label``) with its base
            at ``offset`` (see :meth:`add_robot`).
        open: open the live scene in the default web browser.
        live: start a meshcat server that shows the scene as it is built (:attr:`url`);
            without it the scene only goes to :meth:`save_html`.
        timeout: the longest wait (s) for the server's answer to one request; a server that
            died or hangs raises :class:`~sjt_pin.viewer.server.ServerTimeout` (then
            :meth:`restart`).
    Use as a context manager (or call :meth:`close`) to stop the server. The server lives as
    long as this process (whichever thread made the viewer) or until :meth:`close`.
    """

    def __init__(self, robot: Robot, open: bool = False, *, name: str = "robot",
                 offset=(0.0, 0.0, 0.0), label: str | None = None, live: bool = True,
                 timeout: float = 10.0):
        if not isinstance(timeout, (int, float)) or not 0 < timeout < float("inf"):
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        self.timeout = float(timeout)
        self._server: LoopbackServer | None = None
        self._record = SceneRecord(None)
        if live:
            self._record.live = self._start_server()
        self.meshcat = meshcat.Visualizer(window=self._record)
        self._rigs: dict[str, _Rig] = {}
        self._animation = Animation()
        self._camera: np.ndarray | None = None
        self.meshcat["/Background"].set_property("top_color", _BACKGROUND[0])
        self.meshcat["/Background"].set_property("bottom_color", _BACKGROUND[1])
        self.meshcat["/Axes"].set_property("visible", False)
        # meshcat's grid is 20 m wide, cells of 0.5 m: make it 5 m, cells of 12.5 cm
        self.meshcat["/Grid"].set_transform(np.diag([_GRID_SCALE] * 3 + [1.0]))
        self.add_robot(robot, name, offset, label=label)
        self._send_camera([1.8, 1.1, 0.9])
        if open:
            webbrowser.open(self.url, new=2)

    def _start_server(self) -> LiveWindow:
        self._server = LoopbackServer()
        server = self._server
        return LiveWindow(server.zmq_url, server.web_url, self.timeout,
                          alive=lambda: server.running)

    def restart(self) -> str:
        """Start a new meshcat server (after a :class:`ServerTimeout`, or to go live), send it
        the scene so far, and return its page's address (a new :attr:`url`)."""
        self.close()
        window = self._start_server()
        for command in self._record.lowered():
            window.send_lowered(command)
        self._record.live = window
        return self.url

    # -- scene -----------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The live viewer's address (on 127.0.0.1); only with ``live=True``."""
        if self._server is None:
            raise RuntimeError(_NOT_LIVE)
        return self._server.web_url

    def add_robot(self, robot: Robot, name: str, offset=(0.0, 0.0, 0.0), color=None,
                  label: str | None = None) -> None:
        """Add ``robot`` under node ``name``, shown as ``label`` (default ``name``) on the page.

        ``offset`` places its base: a translation (m, world axes), a 4x4 matrix or a
        ``pin.SE3`` (e.g. to stand a planar arm up). ``color`` (RGBA in [0, 1]) overrides the
        meshes' colours, e.g. for a ghost.
        """
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"name must be a non-empty string without '/' (a meshcat node), "
                             f"got {name!r}")
        if name in self._rigs:
            raise ValueError(f"name {name!r} is already in the scene")
        self._rigs[name] = _Rig(self.meshcat, robot, name, label or name, _placement(offset),
                                color)
        self.show(robot.q0, robot=name)

    def _rig(self, robot: str | None) -> _Rig:
        if robot is None:
            return next(iter(self._rigs.values()))
        if robot not in self._rigs:
            raise ValueError(f"robot must be one of {list(self._rigs)}, got {robot!r}")
        return self._rigs[robot]

    def set_camera(self, position) -> None:
        """Put the camera at ``position`` (world, m), looking at the world origin.

        Without it the saved page frames the whole scene, seen from :data:`VIEW_DIRECTION`.
        """
        self._camera = np.asarray(position, dtype=float)
        self._send_camera(self._camera)

    def _send_camera(self, position) -> None:
        # Pinocchio's camera helpers fail with meshcat 0.3.2; this sets the camera node directly.
        # The camera lives in three.js' y-up frame: world (x, y, z) is (x, z, -y) there.
        x, y, z = np.asarray(position, dtype=float)
        self.meshcat["/Cameras/default/rotated/<object>"].set_property("position", [x, z, -y])

    def show(self, q, robot: str | None = None, collision=None, segments: int = 4,
             geometry: bool = False) -> None:
        """Place ``robot`` at configuration ``q``.

        With ``collision`` (a :class:`~sjt_pin.CollisionLimit` of this robot), also draw the
        closest-point segments of its ``segments`` closest pairs within its ``influence``, and
        with ``geometry`` the collision geometry it measures (translucent).
        """
        rig = self._rig(robot)
        placements = rig.placements(rig.robot.check_q(q))
        for node, T in zip(rig.nodes, placements, strict=True):
            self.meshcat[node].set_transform(T)
        if collision is not None:
            show_segments(self.meshcat, f"{rig.name}/segments", collision, q, segments)
            if geometry:
                show_geometry(self.meshcat, f"{rig.name}/collision", collision, q)

    def add_obstacle(self, shape, pose, name: str = "obstacle", robot: str | None = None,
                     color=OBSTACLE_COLOR, opacity: float = OBSTACLE_OPACITY) -> None:
        """Draw the coal ``shape`` (sphere, box, capsule, cylinder, cone, ellipsoid, convex or
        mesh) at ``pose`` (``pin.SE3`` or 4x4; m) in the frame of ``robot``'s base, as a
        :class:`~sjt_pin.CollisionLimit` of that robot takes its obstacles."""
        draw_obstacle(self.meshcat[f"{self._rig(robot).name}/obstacles/{name}"], shape, pose,
                      color, opacity)

    # -- drawings ----------------------------------------------------------------------------
    def draw_path(self, points, color="blue", name: str = "path", robot: str | None = None,
                  linewidth: float = 2.0) -> None:
        """A polyline through ``points`` (N, 3) in m, in the frame of ``robot``'s base."""
        pts = _points(points)
        material = mg.LineBasicMaterial(color=to_int(color), linewidth=linewidth)
        node = f"{self._rig(robot).name}/paths/{name}"
        self.meshcat[node].set_object(mg.Line(mg.PointsGeometry(pts.T), material))

    def draw_points(self, points, color="blue", name: str = "points", robot: str | None = None,
                    size: float = 0.03) -> None:
        """Dots at ``points`` (N, 3) in m, in the frame of ``robot``'s base.

        ``size`` is three.js' point size: a dot is ``size * h / (2 d)`` pixels wide in a view
        ``h`` pixels high at a distance ``d`` (m), e.g. 4 px for 0.03 at 3 m in 720 px.
        """
        pts = _points(points)
        rgb = np.array([(to_int(color) >> shift & 255) / 255.0 for shift in (16, 8, 0)])
        node = f"{self._rig(robot).name}/paths/{name}"
        self.meshcat[node].set_object(mg.Points(  # meshcat's points always take vertex colours
            mg.PointsGeometry(pts.T, color=np.tile(rgb[:, None], len(pts))),
            mg.PointsMaterial(size=size)))

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
            color=to_int(color), opacity=opacity, transparent=opacity < 1.0))
        node.set_transform(pin.SE3(rotation, np.asarray(center, dtype=float)).homogeneous)

    # -- animations --------------------------------------------------------------------------
    def animate(self, log: TrackingLog, fps: float = 30.0, robot: str | None = None,
                color=None, start: float = 0.0, label: str | None = None, collision=None,
                segments: int = 4, geometry: bool = False,
                targets: Mapping[str, np.ndarray] | None = None, support=None) -> float:
        """Play ``log`` on ``robot`` from ``start`` s of the timeline; returns its end time.

        Draws the desired path (dark) and the path followed (``color``, default the method's,
        or a free colour when another run already has it); the target and the end effector are
        drawn as spheres that move with the animation. ``label`` names the run on the page
        (default: the method). With ``collision`` (a :class:`~sjt_pin.CollisionLimit` of this
        robot), the closest-point segments of its ``segments`` closest pairs within
        ``influence`` move with the run, and the page plots the closest distance over time;
        with ``geometry`` also the collision geometry it measures (translucent).

        A run of several task frames (a humanoid's two hands): the log holds the first, and
        ``targets`` maps each further frame to its targets (N, 3; m, world; one per row of the
        log), drawn as the log's (its position taken from ``log.q``). With ``support`` (the
        :class:`~sjt_pin.SupportLimit` that held the run), its polygon is drawn as a closed
        line on the ground (at the contacts' height at the run's start) and a disc on it
        follows the centre of mass's ground projection.
        """
        if support is not None and getattr(support, "polygon", None) is None:
            raise ValueError("support has no polygon: it takes one at its first step; pass the "
                             "SupportLimit that held the run, after it")
        end = self._add_run(log, fps, robot, color, start, label, targets)
        if collision is not None:
            self._add_distances(log, fps, robot, start, collision, segments, geometry)
        if support is not None:
            self._add_support(log, fps, robot, start, support)
        self._send_animation()
        return end

    def _add_distances(self, log: TrackingLog, fps: float, robot: str | None, start: float,
                       collision, segments: int, geometry: bool = False) -> None:
        """Key the last run's closest-point segments (under its run node, so shown only while
        it plays) and keep its closest distance over time for the page."""
        rig = self._rig(robot)
        run = rig.runs[-1]
        safe = _safe(run.label)
        frames, indices = _keyed_rows(log, fps)
        first = int(round(start * fps))
        closest = key_segments(self._animation, self.meshcat, f"{rig.name}/runs/{safe}/segments",
                               collision, log.q[indices], first, segments)
        if geometry:
            key_geometry(self._animation, self.meshcat, f"{rig.name}/runs/{safe}/collision",
                         collision, log.q[indices], first)
        rig.distances.append(Series(run.label, run.color, frames, np.array(closest)))

    def _add_support(self, log: TrackingLog, fps: float, robot: str | None, start: float,
                     support) -> None:
        """Draw ``support``'s polygon on the ground and key the last run's centre of mass's
        ground projection (a disc, the robot's as its target is: it stays where the run left
        it)."""
        rig, polygon = self._rig(robot), support.polygon
        model, data = rig.robot.model, rig.data
        pin.framesForwardKinematics(model, data, log.q[0])
        z = min(float(data.oMf[rig.robot.frame_id(c)].translation[2])
                for c in support.contacts) + GROUND_LIFT
        loop = np.column_stack([polygon, np.full(len(polygon), z)])
        self.draw_path(np.vstack([loop, loop[:1]]), SUPPORT_COLOR, "support", robot=rig.name)
        note = (f"Green: the support polygon and the centre of mass's ground projection, held "
                f"{1e3 * support.margin:g} mm inside it.")
        if note not in rig.notes:
            rig.notes.append(note)
        fan = np.array([[0, k, k + 1] for k in range(1, len(loop) - 1)], dtype=np.uint32)
        self.meshcat[f"{rig.name}/paths/support_area"].set_object(  # (a line is 1 pixel wide)
            mg.TriangularMeshGeometry(loop.astype(np.float32), fan),
            mg.MeshBasicMaterial(color=SUPPORT_COLOR, opacity=0.2, transparent=True))
        node = f"{rig.name}/markers/com"
        radius, thickness = COM_DISC
        self.meshcat[node].set_object(mg.Cylinder(thickness, radius),
                                      mg.MeshLambertMaterial(color=SUPPORT_COLOR))
        disc = np.eye(4)  # meshcat's cylinder stands on its y axis: lay it flat
        disc[:3, :3] = pin.utils.rotate("x", np.pi / 2)
        _, indices = _keyed_rows(log, fps)
        first = int(round(start * fps))
        for k, i in enumerate(indices):
            disc[:2, 3] = pin.centerOfMass(model, data, log.q[i])[:2]
            disc[2, 3] = z
            with self._animation.at_frame(self.meshcat, first + k) as frame:
                frame[node].set_transform(disc)

    def compare(self, logs: Mapping[str, TrackingLog] | Sequence[TrackingLog], fps: float = 30.0,
                robot: str | None = None) -> None:
        """Several runs on ``robot``, one after another on the timeline, each labelled by its
        key (a mapping) or its method (a sequence) and drawn in its own colour.
        """
        runs = list(logs.items()) if isinstance(logs, Mapping) else [(None, log) for log in logs]
        if not runs:
            raise ValueError("logs must hold at least one TrackingLog")
        start = 0.0
        for label, log in runs:
            start = self._add_run(log, fps, robot, None, start, label)
        self._send_animation()

    def _add_run(self, log: TrackingLog, fps: float, robot: str | None, color,
                 start: float, label: str | None = None,
                 targets: Mapping[str, np.ndarray] | None = None) -> float:
        """Key ``log``'s frames into the animation (not sent yet); returns the run's end (s).

        The run's followed path and end-effector sphere sit under the node ``runs/<method>`` of
        the robot, shown only while the run plays; the desired path (dots) and the target (a
        grey halo around the end effector) are the robot's. Each frame of ``targets`` gets the
        same, its nodes named with a ``-<frame>`` suffix.
        """
        if not isinstance(log, TrackingLog) or len(log) == 0:
            raise ValueError("log must be a non-empty TrackingLog")
        rig = self._rig(robot)
        label = str(label or log.method or "run")
        if any(run.label == label for run in rig.runs):
            raise ValueError(f"robot {rig.name!r} already has a run labelled {label!r}")
        if color is None:
            taken = {run.color for run in rig.runs}
            free = [c for c in (METHOD_COLORS.get(log.method, OTHER_COLOR), *EXTRA_COLORS)
                    if c not in taken]
            color = free[0] if free else OTHER_COLOR
        color = to_int(color)
        tracked = [("", log.position, log.target), *self._further(rig, log, targets)]
        run_node, target_node = f"{rig.name}/runs/{_safe(label)}", f"{rig.name}/markers/target"
        every = -(-len(log) // PATH_POINTS)  # a path of at most PATH_POINTS points
        rgb = np.array([(DESIRED_COLOR >> shift & 255) / 255.0 for shift in (16, 8, 0)])
        halo = mg.MeshLambertMaterial(color=DESIRED_COLOR, opacity=0.3, transparent=True)
        for suffix, positions, desired in tracked:
            dots = _dots(desired, DOT_SPACING * rig.size)
            node = f"{rig.name}/paths/desired{suffix}"
            self.meshcat[node].set_object(mg.Points(
                mg.PointsGeometry(dots.T, color=np.tile(rgb[:, None], len(dots))),
                _ScreenPointsMaterial(size=DOT_PIXELS)))
            if node not in rig.dots:
                rig.dots.append(node)
            self.meshcat[f"{run_node}/path{suffix}"].set_object(mg.Line(
                mg.PointsGeometry(_points(positions[::every]).T),
                mg.LineBasicMaterial(color=color, linewidth=2.0)))
            self.meshcat[f"{run_node}/ee{suffix}"].set_object(
                mg.Sphere(0.011), mg.MeshLambertMaterial(color=color))
            self.meshcat[f"{target_node}{suffix}"].set_object(mg.Sphere(0.02), halo)
        self._animation.default_framerate = fps
        frames, indices = _keyed_rows(log, fps)
        first = int(round(start * fps))
        for k, i in enumerate(indices):
            with self._animation.at_frame(self.meshcat, first + k) as frame:
                for node, T in zip(rig.nodes, rig.placements(log.q[i]), strict=True):
                    frame[node].set_transform(T)
                for suffix, positions, desired in tracked:
                    frame[f"{target_node}{suffix}"].set_transform(_translation(desired[i]))
                    frame[f"{run_node}/ee{suffix}"].set_transform(_translation(positions[i]))
        for frame, visible in ((0, first == 0), (first, True), (first + len(frames), False)):
            with self._animation.at_frame(self.meshcat, frame) as keyed:
                keyed[run_node].set_property("visible", "boolean", visible)
        end = start + frames[-1] + 1.0 / fps
        rig.runs.append(Run(label, log.method, color, start, end, log))
        return end

    @staticmethod
    def _further(rig: _Rig, log: TrackingLog, targets: Mapping[str, np.ndarray] | None
                 ) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """(node suffix, positions, targets), each (N, 3), of each frame of ``targets``, its
        positions at the rows of ``log.q``."""
        if targets is None:
            return []
        if not isinstance(targets, Mapping):
            raise TypeError(f"targets must map frame names to targets (N, 3), got "
                            f"{type(targets).__name__}")
        model, data = rig.robot.model, rig.data
        further = []
        for frame, desired in targets.items():
            fid = rig.robot.frame_id(frame)
            name = model.frames[fid].name
            desired = _points(desired, f"targets[{name!r}]")
            if len(desired) != len(log):
                raise ValueError(f"targets[{name!r}] must have one row per row of the log "
                                 f"({len(log)}), got {len(desired)}")
            positions = np.empty((len(log), 3))
            for i, q in enumerate(log.q):
                pin.forwardKinematics(model, data, q)
                positions[i] = pin.updateFramePlacement(model, data, fid).translation
            further.append((f"-{_safe(name)}", positions, desired))
        return further

    def _send_animation(self) -> None:
        """Send the animation, its tracks lengthened to the last key of all (meshcat loops
        each track over its own length: tracks of unequal lengths would drift apart)."""
        last = max(track.frames[-1] for clip in self._animation.clips.values()
                   for track in clip.tracks.values())
        padded = Animation(default_framerate=self._animation.default_framerate)
        for path, clip in self._animation.clips.items():
            tracks = {}
            for name, track in clip.tracks.items():
                more = [last] if track.frames[-1] < last else []
                tracks[name] = AnimationTrack(track.name, track.jstype, track.frames + more,
                                              track.values + [track.values[-1]] * len(more))
            padded.clips[path] = AnimationClip(tracks, fps=clip.fps, name=clip.name)
        self.meshcat.set_animation(padded, play=True, repetitions=1000)

    # -- output ------------------------------------------------------------------------------
    def static_html(self, title: str = "sjt-pin viewer", description: str = "") -> str:
        """One self-contained HTML page of the scene and its animation (works offline).

        Beside the 3-D view: ``title``, ``description`` (a paragraph), each robot's label and
        runs in their colours, a plot of each run's tracking error over time; under it a
        play/pause button and a time slider.
        """
        robots = [RobotEntry(rig.name, rig.label, tuple(rig.runs), tuple(
            [error_plot(rig.distances, width=PLOT_WIDTH_BESIDE, height=PLOT_HEIGHT,
                        ylabel="closest distance (m)")]
            if rig.distances else []), tuple(rig.notes)) for rig in self._rigs.values()]
        view = None if self._camera is not None else VIEW_DIRECTION
        dots = [node for rig in self._rigs.values() for node in rig.dots]
        return page_html(self._record.commands(), robots, title, description, view, dots)

    def save_html(self, path: str | Path, title: str = "sjt-pin viewer",
                  description: str = "") -> Path:
        """Write :meth:`static_html` to ``path``; returns the path."""
        path = Path(path)
        path.write_text(self.static_html(title, description), encoding="utf-8")
        return path

    def static_cell(self, height: int = 480, title: str = "sjt-pin viewer",
                    description: str = ""):
        """A static copy of the scene for a Jupyter cell: :meth:`static_html` in an iframe's
        ``srcdoc``, so the picture, its animation and its plots stay in the saved notebook after
        the kernel (and the server) stopped. ``height`` in CSS pixels."""
        from IPython.display import HTML

        if not isinstance(height, int) or height <= 0:
            raise ValueError(f"height must be a positive integer (pixels), got {height!r}")
        page = html.escape(self.static_html(title, description), quote=True)
        return HTML(f'<div class="sjt-pin-static"><iframe srcdoc="{page}" '
                    f'title="{html.escape(title, quote=True)}" style="width: 100%; '
                    f'height: {height}px; border: 1px solid #d8dbe0" sandbox="allow-scripts">'
                    "</iframe></div>")

    def jupyter_cell(self, height: int = 400):
        """The live viewer in a Jupyter cell (an iframe on :attr:`url`); blank once the kernel
        stops: :meth:`static_cell` keeps a copy in the notebook."""
        if self._server is None:
            raise RuntimeError(_NOT_LIVE)
        return self.meshcat.jupyter_cell(height=height)

    def close(self) -> None:
        """Stop the meshcat server, if any (idempotent); the scene stays for :meth:`save_html`
        and :meth:`restart`."""
        if isinstance(self._record.live, LiveWindow):
            self._record.live.close()
        self._record.live = None
        if self._server is not None:
            self._server.close()
        self._server = None

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        url = self._server.web_url if self._server is not None else None
        return f"Viewer({list(self._rigs)}, url={url!r})"


class _ScreenPointsMaterial(mg.PointsMaterial):
    """Points ``size`` pixels wide at any distance (three.js' ``sizeAttenuation`` off)."""

    def lower(self, object_data):
        return {**super().lower(object_data), "sizeAttenuation": False}


def _dots(path: np.ndarray, spacing: float) -> np.ndarray:
    """Points of ``path`` (N, 3) at least ``spacing`` m apart along it, at most DESIRED_DOTS
    of them evenly spread, the first and the last included (two, for a path that stands still).
    """
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    count = int(min(DESIRED_DOTS, arc[-1] / max(spacing, 1e-12))) + 1
    indices = np.searchsorted(arc, np.linspace(0.0, arc[-1], max(count, 2)))
    return path[np.minimum(indices, len(path) - 1)]


def _safe(label: str) -> str:
    """``label`` as a meshcat node name: characters other than letters, digits, ``-_.`` as
    ``_``."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in label)


def _keyed_rows(log: TrackingLog, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The animation's frame times (s, from the run's start) at ``fps`` and the rows of ``log``
    shown at each."""
    frames = np.arange(0.0, log.t[-1] + 0.5 / fps, 1.0 / fps)
    return frames, np.minimum(np.searchsorted(log.t, frames), len(log) - 1)


def _translation(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T
