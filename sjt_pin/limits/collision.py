"""Collision avoidance as linear inequalities on the joint velocity: velocity dampers.

Each pair of geometries (robot link / world obstacle, or two robot links) closer than
``influence`` contributes one row on the relative normal velocity of its closest points, the
velocity damper of Faverjon and Tournassoud (ICRA 1987) in the form of Kanoun, Lamiraux and
Wieber (IEEE T-RO 2011, eq. 14):

    d_dot >= -gain (d - margin) / dt,    d_dot = n^T (J_a(p_a) - J_b(p_b)) q_dot

with ``p_a``, ``p_b`` the closest points, ``n`` the unit normal from ``b`` to ``a`` and
``J_x(p)`` the world-aligned linear Jacobian of the point ``p`` fixed to geometry ``x``'s parent
joint (zero for an obstacle). Over one period ``dt`` the distance then changes to first order
by ``d_dot dt >= -gain (d - margin)``: with ``gain`` in (0, 1] it never crosses ``margin``,
and below ``margin`` (or in penetration) the row pushes the pair apart. Where the solver's
speed limits ``v`` keep ``|d_dot|`` below ``gain (d - margin) / dt`` already (``|d_dot| <=
sum_j lever_j v_j``, the levers of the broad phase's skip, below), the row is implied by them
and is left out of the step's rows.

Acceleration limits. A damper alone lets a pair close at up to ``gain (d - margin) / dt``, far
more than an arm with acceleration limits can stop from in the gap left, so a solver with
acceleration limits (``Motion.acceleration_limits``) also bounds each row's closing speed by
what half of those limits can still brake within ``d - margin`` (a braking-distance bound,
the discrete form of ``d_dot >= -sqrt(2 a (d - margin))``; ``kernels.stoppable_rows``): the
arm slows as it nears the margin instead of stopping at it in one period. A row whose closing
speed jumps (a contact's closest points slide onto another feature, a witness row appears)
eases in: it asks that speed to drop no faster than the limits allow from the previous step's
velocity and acceleration, as long as the pair, braking at its whole acceleration, stays
``margin - EASING_SLACK`` apart. A row that appears at ``influence`` could not stop a pair
closing at arm speeds (a link at 1.5 m/s needs some 14 cm at 10 rad/s^2), so each pair's
influence grows to the distance within which the row may have to start braking it: its
joints' speeds after this step bound its closing speed ``s`` (the levers of the broad phase's
skip, below), the time ``T`` the joints take to stop at their limits bounds ``s`` over the
row's acceleration, and ``s (dt + ramp + T / (2 share))`` covers what the row needs
(``kernels.braking_reach``; a robot whose joints give no such bound, Euler angles or a
translation without a range, keeps ``influence``). The acceleration limit still yields where
the rows ask more than its share at once (several contacts, a row that jumps);
``StepInfo.limit_conflicts`` says so on those steps.

Witnesses. Where two hulls touch along a face or an edge their closest points are not unique,
and coal's pick jumps from one end of the contact to the other as the pair slides or turns: one
row at a time lets the arm turn about the point it keeps, the next step's row (the other end)
turns it back, and at a blocked target the arm chatters in a limit cycle. So each pair also
keeps a few of its recent closest points (fixed to their geometries) as rows of their own, on
the current normal ``n``: for points ``a'`` of geometry a and ``b'`` of b, the plane through
the closest points separates the hulls, so ``s = n^T (b' - a') >= d``; a row
``s_dot >= -gain (s - margin) / dt`` asks nothing the pair's own row does not imply to first
order, but together they hold the whole contact (the several points of a contact manifold),
and the arm comes to rest there. A witness is forgotten when its ``s`` exceeds ``d`` by half
the band ``influence - margin`` or when the pair leaves ``influence``, and a pair farther
than that from its margin remembers nothing (its row binds nothing); nor does a pair with a
sphere (or an ellipsoid), whose closest points are unique and move continuously.

Moving obstacles. An obstacle moved with its velocity (:meth:`CollisionLimit.move`, twist
``(v, w)`` in world axes) makes each of its pairs' rows bound the relative closing speed:

    n^T (J_a(p_a) q_dot - v_b(p_b)) <= gain (d - margin) / dt,    v_b(p) = v + w x (p - o)

(``o`` the obstacle's origin; the bound of ``A q_dot <= b`` rises by ``n^T v_b(p_b)``, falls
where the obstacle comes closer). With ``u = -n^T v_b(p_b)`` the obstacle's approach speed
and ``r = sum_j |A_ij| v_j`` the fastest the arm's speed limits ``v`` let the row's point
retreat, the guarantee is:

- without acceleration limits, where ``u <= r``: the step keeps its row, so per period the
  excess ``d - margin`` shrinks by at most the fraction ``gain`` to first order in ``dt``, as
  beside a still obstacle; without the velocity the row lags the obstacle by a period and
  the pair settles about ``u dt / gain`` inside the margin;
- with acceleration limits (``a = sum_j |A_ij| a_j`` along the row, ``BRAKING_SHARE`` of it
  counted on), the row starts giving way while its excess still covers the retreat's ramp,
  ``h >= (u + s) tau + (u + s)^2 / (2 share a)`` for a closing speed ``s`` and ``tau = dt +
  a / j``: each pair with a moving obstacle is watched ``u (2 dt + T)`` farther out (``T``
  the longest time a joint takes to reach its speed limit, at most 1 s, plus the jerk's
  ramp: :meth:`CollisionLimit._lookahead`), and where the obstacle comes faster than the
  limits can answer the acceleration and jerk limits yield to the row (``limit_conflicts``);
- where ``u > r`` no motion within the speed limits keeps the row: the step breaks it by
  the least the stage can, and ``StepInfo.rows_exceeded`` gives ``A q_dot - b`` (m/s; times
  ``dt``, how much of the margin the step gave up).

A moving obstacle is moved every step (its velocity holds until the next :meth:`move`); each
move starts the broad phase again.

Distances and closest points come from coal on the shapes of Pinocchio's ``GeometryModel``:
Pinocchio's ``computeDistance``, called back from the compiled step of the limit
(``kernels.collision_rows``) for each pair it must query. Only the pairs whose bounding
spheres come within ``influence`` (plus a skin of half the band ``influence - margin`` while the
broad phase's result is reused, as in a Verlet list) pay for an exact distance query, and a pair
whose last exact distance was beyond ``influence`` is not queried again until the joints' moves
since that query can have closed the gap (a bound from the joint offsets and the ranges of the
prismatic joints between, summed step by step: :meth:`CollisionLimit._near`,
:meth:`CollisionLimit._aged`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

try:
    import coal
except ImportError:  # pragma: no cover - the pin wheel ships coal
    coal = None

from ..exceptions import SJTError
from ..kernels import (
    CollisionTables,
    Skip,
    braking_reach,
    collision_rows,
    damper_rows,
    near_pairs,
    refresh_pairs,
    sphere_gaps,
    stoppable_rows,
    witness_rows,
)
from .base import Limit, Motion

__all__ = ["ClosestPoints", "CollisionLimit", "CollisionError", "PairDistance"]

#: the precision (m) of coal's GJK and EPA on convex shapes (its default is 1e-6)
GJK_TOLERANCE = 1e-9
#: the share of each joint's acceleration (and jerk) limit a damper row counts on to stop its
#: pair's closing speed (``kernels.stoppable_rows``); the rest is the task's and the other rows'
BRAKING_SHARE = 0.5
#: with acceleration limits a row that turns or appears eases in at what they allow as long as
#: its pair stays at least ``margin`` minus this (m) apart (``kernels.stoppable_rows``)
EASING_SLACK = 5e-4
#: two witnesses of a pair closer than this (m, either point, in its geometry's frame) are one
WITNESS_APART = 1e-4
#: a local bounding box reaching this far (m) bounds nothing (coal's Halfspace and Plane)
UNBOUNDED = 1e300



class CollisionError(SJTError, ValueError):
    """Collision geometry that cannot be used: missing, of an unknown shape, or an obstacle
    that overlaps the robot where the limit starts."""


@dataclass(frozen=True)
class PairDistance:
    """One pair of :meth:`CollisionLimit.distances`: geometry names, their links (``"world"``
    for an obstacle) and the signed distance in m (negative in penetration)."""

    a: str
    b: str
    link_a: str
    link_b: str
    distance: float


@dataclass(frozen=True)
class ClosestPoints:
    """One pair of :meth:`CollisionLimit.closest_points`: the pair and its distance, and the
    closest point of each geometry (world, m; on ``pair.a`` and on ``pair.b``)."""

    pair: PairDistance
    a: np.ndarray
    b: np.ndarray

    @property
    def distance(self) -> float:
        """The pair's signed distance (m)."""
        return self.pair.distance


def _supported(shape) -> bool:
    if coal is None:
        return False
    kinds = [coal.ShapeBase, coal.BVHModelBase]
    return isinstance(shape, tuple(kinds))


def _srdf_of(robot) -> str | None:
    """The SRDF of an example-robot-data robot, or None."""
    path = getattr(robot, "srdf", None)
    if path:
        return str(path)
    name = getattr(robot, "name", None)
    try:
        from example_robot_data.robots_loader import ROBOTS, getModelPath
    except ImportError:  # pragma: no cover
        return None
    loader = ROBOTS.get(name) if isinstance(name, str) else None
    if loader is None or not getattr(loader, "srdf_filename", None):
        return None
    urdf = os.path.join(loader.path, loader.urdf_subpath, loader.urdf_filename or "")
    try:
        model_path = getModelPath(urdf)
    except Exception:  # noqa: BLE001 - no installed data: no SRDF
        return None
    srdf = os.path.join(model_path, loader.path, loader.srdf_subpath, loader.srdf_filename)
    return srdf if os.path.isfile(srdf) else None


def _collision_model(robot) -> pin.GeometryModel:
    geom = getattr(robot, "collision_model", None)
    if geom is None:
        urdf = getattr(robot, "urdf", None)
        if urdf is None:
            raise CollisionError(f"{getattr(robot, 'name', 'robot')}: no collision model and no "
                                 "URDF to load one from (robot.urdf is None)")
        dirs = [str(d) for d in getattr(robot, "package_dirs", ()) or ()]
        text = str(urdf)
        try:
            if text.lstrip().startswith("<"):
                geom = pin.buildGeomFromUrdfString(robot.model, text, pin.COLLISION,
                                                   package_dirs=dirs)
            else:
                geom = pin.buildGeomFromUrdf(robot.model, text, pin.COLLISION,
                                             package_dirs=dirs)
        except (ValueError, RuntimeError) as exc:
            raise CollisionError(f"cannot load the collision geometry of "
                                 f"{getattr(robot, 'name', 'robot')} (package_dirs={dirs}): "
                                 f"{exc}") from exc
    geom = geom.copy()
    if geom.ngeoms == 0:
        raise CollisionError(f"{getattr(robot, 'name', 'robot')}: its URDF has no <collision> "
                             "geometry; a CollisionLimit needs one per link to check")
    for g in geom.geometryObjects:
        if not _supported(g.geometry):
            raise CollisionError(f"collision geometry {g.name!r} has a shape coal cannot "
                                 f"measure distances to: {type(g.geometry).__name__}")
    return geom


def _to_hulls(geom: pin.GeometryModel) -> None:
    """Replace every mesh of ``geom`` by its convex hull (in place; the meshes themselves,
    possibly shared with the robot's model, are not changed)."""
    for g in geom.geometryObjects:
        shape = g.geometry
        if isinstance(shape, coal.BVHModelBase) and not isinstance(shape, coal.ConvexBase):
            g.geometry = _hull(shape, g.name)


def _hull(mesh, name: str):
    """The convex hull of ``mesh`` (qhull through coal): triangulated ("Qt"), or, where qhull
    refuses that (Centauro's pelvis), of its points joggled ("QJ": qhull's default joggle, a
    relative 1e-11 or so of the mesh's size, far below any margin)."""
    error = None
    for options in ("Qt", "QJ"):
        copy = mesh.clone()
        try:
            copy.buildConvexHull(False, options)
            return copy.convex
        except Exception as exc:  # noqa: BLE001 - qhull's errors are plain exceptions
            error = exc
    raise CollisionError(f"collision mesh {name!r}: no convex hull ({error}); pass "
                         "convex=False to use the mesh itself") from error


class CollisionLimit(Limit):
    """Keep the robot ``margin`` away from ``obstacles`` and (``self_collision=True``) from
    itself, as one velocity-damper row per pair closer than ``influence``.

    Args:
        robot: a :class:`sjt_pin.Robot` (its ``collision_model``, else the ``<collision>``
            geometry of ``robot.urdf`` with ``robot.package_dirs``).
        obstacles: ``(coal shape, pin.SE3)`` pairs fixed in the world: ``coal.Sphere``, ``Box``,
            ``Capsule``, ``Cylinder``, ``Halfspace``, ``Plane``, ``Convex`` or a mesh
            (``BVHModel``; its convex hull with ``convex=True``). Move them with :meth:`move`,
            with their velocity when they move (module docstring, "Moving obstacles").
        self_collision: also check the robot's link pairs, except adjacent links (geometries on
            the same joint or on a joint and its parent) and the pairs the SRDF disables.
        margin: distance to keep, m.
        influence: pairs farther than this (m) contribute no row; beside acceleration limits,
            farther as the arm's speed needs (module docstring, "Acceleration limits").
        gain: the damper's gain in (0, 1]: per period the excess ``d - margin`` may shrink by
            at most this fraction.
        pairs: extra ``(link_a, link_b)`` (or geometry names) to check although the rules above
            skip them (e.g. an adjacent pair).
        ignore: ``(link_a, link_b)`` (or geometry names; ``"world"`` for every obstacle) never
            to check.
        srdf: an SRDF path whose ``disable_collisions`` apply; by default the SRDF of an
            example-robot-data robot.
        convex: replace the robot's collision meshes and the mesh obstacles by their convex
            hulls (qhull, through coal). A hull contains its mesh, so the distance to it never
            exceeds the mesh's and the margin still holds for the mesh; GJK on hulls takes
            about a microsecond where a mesh-to-mesh distance takes from 10 us to several ms
            (Panda), and a hull's closest points move continuously where a mesh's jump from
            triangle to triangle (beside a mesh obstacle those jumps broke the acceleration
            limit 30x). A non-convex obstacle is filled in: the arm keeps off its hull
            (give its convex parts as obstacles of their own to reach into it). ``False``
            keeps every mesh as given.
        witnesses: how many recent closest points of each pair within ``influence`` to keep as
            rows beside its own (module docstring, "Witnesses"); 0 keeps none.
    """

    name: str = "collision"
    uses_motion: bool = False  # its rows depend on q and dt (and, with acceleration limits,
    # on motion.dq and motion.ddq, which the solver then keeps up to date anyway)

    def __init__(self, robot, obstacles: Sequence = (), self_collision: bool = False,
                 margin: float = 0.01, influence: float = 0.05, gain: float = 0.5,
                 pairs: Iterable[tuple[str, str]] = (), ignore: Iterable[tuple[str, str]] = (),
                 srdf: str | None = None, convex: bool = True, witnesses: int = 3):
        if coal is None:  # pragma: no cover
            raise CollisionError("CollisionLimit needs coal (shipped with the pin wheel)")
        if not (np.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be a finite distance >= 0 (m), got {margin!r}")
        if not (np.isfinite(influence) and influence > margin):
            raise ValueError(f"influence must be finite and > margin={margin} (m), "
                             f"got {influence!r}")
        if not (0 < gain <= 1):
            raise ValueError(f"gain must be in (0, 1], got {gain!r}")
        if isinstance(witnesses, bool) or not isinstance(witnesses, (int, np.integer)) or (
                witnesses < 0):
            raise ValueError(f"witnesses must be an int >= 0, got {witnesses!r}")
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.witnesses = int(witnesses)
        # what a copy in another process is rebuilt from (coal's hulls do not pickle)
        self._args = dict(robot=robot, obstacles=list(obstacles), self_collision=self_collision,
                          margin=margin, influence=influence, gain=gain, pairs=list(pairs),
                          ignore=list(ignore), srdf=srdf, convex=convex, witnesses=witnesses)
        self.model: pin.Model = robot.model
        self._mimics = list(getattr(robot, "mimic_joints", ()))
        self._mimic = _mimic_map(robot.model, self._mimics)
        source = self.__dict__.pop("_restored_geometry", None)  # set by __setstate__
        self.geometry = source.copy() if source is not None else _collision_model(robot)
        self._source = self.geometry.copy()  # the robot's own geometry (meshes), for copies
        if convex:
            _to_hulls(self.geometry)
        self._convex = bool(convex)
        self.n_robot = self.geometry.ngeoms
        self._obstacle_ids: list[int] = []
        self._obstacle_shapes: list = []  # (as given: a mesh obstacle's hull is the limit's)
        for i, item in enumerate(obstacles):
            self._add_obstacle(i, item)
        #: each obstacle's velocity (m/s and rad/s, world axes: its origin's linear velocity,
        #: then its angular velocity), set by :meth:`move`
        self._velocity = np.zeros((len(self._obstacle_ids), 6))
        self._obstacle_of = np.full(self.geometry.ngeoms, -1, dtype=np.int64)  # (-1: robot's)
        self._obstacle_of[self._obstacle_ids] = np.arange(len(self._obstacle_ids))
        self._choose_pairs(self_collision, list(pairs), list(ignore),
                           srdf if srdf is not None else (_srdf_of(robot) if self_collision
                                                          else None))
        self._data = self.model.createData()
        self._checked = False
        #: the pairs (indices into pairs / pair_names) of the first rows of the last rows()
        #: (one each, from its exact distance), and of the witness rows that follow them
        self.active: list[int] = []
        #: the pairs within influence at the last rows(): those of :attr:`active` and those
        #: whose row could not bind at the solver's speed limits (left out)
        self.within: list[int] = []
        self._witness_count = 0  # the witness rows of the last rows() (_owners holds their pairs)
        self._prepare_broad_phase()

    def __getstate__(self) -> dict:
        """Pickled as its arguments (obstacles at their current poses) and the robot's own
        collision geometry (the robot pickles without it; coal's hulls do not pickle, they
        are built again)."""
        return {"args": {**self._args, "obstacles": self.obstacles},
                "geometry": self._source.copy(), "velocity": self._velocity.copy()}

    def __setstate__(self, state: dict) -> None:
        self._restored_geometry = state["geometry"]
        self.__init__(**state["args"])  # type: ignore[misc]
        self._velocity[:] = state.get("velocity", 0.0)
        self._moving_speeds()

    # -- construction ------------------------------------------------------------------------
    def _add_obstacle(self, i: int, item) -> None:
        try:
            shape, pose = item
        except (TypeError, ValueError):
            raise TypeError(f"obstacle {i} must be a (coal shape, pin.SE3) pair, got "
                            f"{type(item).__name__}") from None
        if not _supported(shape):
            raise CollisionError(f"obstacle {i}: unknown shape {type(shape).__name__}; use a "
                                 "coal Sphere, Box, Capsule, Cylinder, Convex or BVHModel")
        _check_pose(pose, f"pose of obstacle {i}")
        _check_extent(shape, f"obstacle {i}")
        self._obstacle_shapes.append(shape)
        if self._convex and isinstance(shape, coal.BVHModelBase) and not isinstance(
                shape, coal.ConvexBase):  # a mesh: its hull, as the robot's own meshes
            shape = _hull(shape, f"obstacle {i}")
        obj = pin.GeometryObject(f"obstacle_{i}", 0, 0, pose, shape)
        self._obstacle_ids.append(self.geometry.addGeometryObject(obj))

    def _link(self, g: int) -> str:
        g = int(g)
        if g >= self.n_robot:
            return "world"
        return self.model.frames[self.geometry.geometryObjects[g].parentFrame].name

    def _matches(self, rules, a: int, b: int) -> bool:
        na, nb = self.geometry.geometryObjects[a].name, self.geometry.geometryObjects[b].name
        la, lb = self._link(a), self._link(b)
        for x, y in rules:
            if (x in (na, la) and y in (nb, lb)) or (y in (na, la) and x in (nb, lb)):
                return True
        return False

    def _choose_pairs(self, self_collision, extra, ignore, srdf) -> None:
        geoms = self.geometry.geometryObjects
        names = {g.name for g in geoms} | {self._link(i) for i in range(len(geoms))}
        for rule in extra + ignore:
            if len(rule) != 2 or any(n not in names for n in rule):
                raise ValueError(f"pair {rule!r} names no known link or geometry; known links: "
                                 f"{sorted({self._link(i) for i in range(self.n_robot)})}")
        disabled = set()
        if self_collision and srdf is not None:
            probe = self.geometry.copy()
            probe.addAllCollisionPairs()
            every = {(p.first, p.second) for p in probe.collisionPairs}
            pin.removeCollisionPairs(self.model, probe, str(srdf))
            disabled = every - {(p.first, p.second) for p in probe.collisionPairs}
        parents = self.model.parents
        chosen = []
        n = len(geoms)
        for a in range(n):
            for b in range(a + 1, n):
                ja, jb = geoms[a].parentJoint, geoms[b].parentJoint
                obstacle_a, obstacle_b = a >= self.n_robot, b >= self.n_robot
                if obstacle_a and obstacle_b:
                    continue
                if obstacle_a or obstacle_b:
                    keep = (jb if obstacle_a else ja) != 0  # a link fixed to the world: skip
                else:
                    keep = (self_collision and ja != jb and parents[ja] != jb
                            and parents[jb] != ja and (a, b) not in disabled)
                if not keep and extra and self._matches(extra, a, b):
                    keep = True
                if keep and ignore and self._matches(ignore, a, b):
                    keep = False
                if keep:
                    chosen.append((a, b))
        self._set_pairs(chosen)

    def _set_pairs(self, chosen: list[tuple[int, int]]) -> None:
        """Check the geometry pairs ``chosen`` (indices): the geometry model's pairs, its data
        (coal's requests: signed distances, GJK and EPA to GJK_TOLERANCE) and their names."""
        geoms = self.geometry.geometryObjects
        self.geometry.removeAllCollisionPairs()
        for a, b in chosen:
            self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = np.array(chosen, dtype=np.int64).reshape(-1, 2)
        self.pair_names = [(geoms[a].name, geoms[b].name) for a, b in chosen]
        self.geometry_data = self.geometry.createData()
        for req in self.geometry_data.distanceRequests:
            req.enable_signed_distance = True
            req.gjk_tolerance = req.epa_tolerance = GJK_TOLERANCE
        #: the distance each pair keeps (m): ``margin``, or less for a pair of the robot's own
        #: links that was closer than ``margin`` where the limit started
        self.margins = np.full(len(chosen), self.margin)

    def _prepare_broad_phase(self) -> None:
        """Everything a step reads, as arrays: each geometry's bounding volumes, the pairs as
        index arrays and row buffers, the witnesses' memory, the stacked sphere centres of the
        broad phase, which Jacobian columns move each joint, and the state of the skip."""
        self._bounding_volumes()
        self._pair_tables()
        self._witness_memory()
        self._sphere_stack()
        self._jacobian_support()
        self._skip_state()
        self._compute = pin.computeDistance  # (kernels.collision_rows calls it for each query)
        self._moving_speeds()

    def _bounding_volumes(self) -> None:
        """Per geometry: its parent joint, coal's local AABB (centre and half extents, in the
        geometry's frame), the sphere around that box, and its placement in the joint's
        frame."""
        geoms = self.geometry.geometryObjects
        n = len(geoms)
        self._joint = np.array([g.parentJoint for g in geoms], dtype=np.int64)
        self._box_center = np.zeros((n, 3))
        self._box_half = np.zeros((n, 3))
        self._radius = np.zeros(n)
        self._placement = np.zeros((n, 4, 4))
        for i, g in enumerate(geoms):
            g.geometry.computeLocalAABB()
            box = g.geometry.aabb_local
            lo, hi = np.array(box.min_), np.array(box.max_)
            if np.all(np.abs(lo) < UNBOUNDED) and np.all(np.abs(hi) < UNBOUNDED):
                self._box_center[i], self._box_half[i] = (lo + hi) / 2, (hi - lo) / 2
                self._radius[i] = float(np.linalg.norm(hi - lo) / 2)
            else:  # a Halfspace or a Plane (coal's box: +-DBL_MAX): always a candidate
                self._box_half[i] = self._radius[i] = np.inf
            self._placement[i] = g.placement.homogeneous

    def _pair_tables(self) -> None:
        """Per pair: its geometries and their joints, the reach of its spheres, and the
        buffer of a step's rows in the form of ``kernels.damper_rows`` (distance, margin,
        the two joints, the normal, the closest points), one per pair and witness."""
        self._pa, self._pb = self.pairs[:, 0].copy(), self.pairs[:, 1].copy()
        ja, jb = self._joint[self._pa], self._joint[self._pb]
        self._joint_table = np.ascontiguousarray(np.column_stack([ja, jb]).reshape(-1, 2),
                                                 dtype=np.int64)
        self._pair_rows = np.zeros((max(len(self.pairs), 1) * (1 + self.witnesses), 13))
        self._span = self._radius[self._pa] + self._radius[self._pb]
        # each pair's obstacles (-1: the robot's geometry) and how far their sphere reaches
        # from their origin (m), for the speed of a moving one (_moving_speeds)
        self._pair_obstacle = self._obstacle_of[self.pairs].reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            self._pair_far = (np.linalg.norm(self._box_center[self.pairs], axis=-1)
                              + self._radius[self.pairs]).reshape(-1, 2)

    def _witness_memory(self) -> None:
        """Per pair: its recent closest points, each in its joint's frame (``witnesses`` rows
        of 6), how many (-1: none ever) and the tick of the last rows() that had it within
        influence (module docstring, "Witnesses"; ``kernels.witness_rows``), and that kernel's
        scratch: the world poses of the joints the step's pairs name, the owners of its
        rows."""
        slots = max(len(self.pairs), 1)
        self._memory = np.zeros((slots * max(self.witnesses, 1), 6))
        self._memory_state = np.zeros((slots, 2))
        self._memory_state[:, 1] = -np.inf
        # a pair with a sphere (or an ellipsoid) has unique closest points, which move
        # continuously with the joints: its own row holds the contact, it remembers nothing
        geoms = self.geometry.geometryObjects
        for k, pair in enumerate(self.pairs):
            if any(isinstance(geoms[int(g)].geometry, (coal.Sphere, coal.Ellipsoid))
                   for g in pair):
                self._memory_state[k, 0] = -1.0
        self._tick = 0.0
        self._owners = np.zeros(slots * max(self.witnesses, 1))
        njoints = self.model.njoints
        self._poses = np.zeros((njoints, 4, 4))
        self._poses[0] = np.eye(4)
        self._flat_poses = self._poses.reshape(njoints, 16)

    def _sphere_stack(self) -> None:
        """The broad phase's products: one product of the stacked poses of the joints that
        carry geometry and the world's identity (4 nj + 4, 4) with every sphere centre in its
        joint's frame (4, n) gives every centre in the world; ``_pick`` takes geometry g's
        xyz out of it (flat indices, (n, 3)) and ``_difference`` the centre differences of
        every pair."""
        n = len(self._joint)
        local = self._placement @ np.append(self._box_center, np.ones((n, 1)), axis=1)[:, :, None]
        self._center_local = local[:, :, 0]
        moving = np.flatnonzero(self._joint != 0)
        self._joints = [int(j) for j in np.unique(self._joint[moving])]
        self._slot = np.searchsorted(self._joints, self._joint)  # joint of g in the stack
        self._slot[self._joint == 0] = len(self._joints)  # the world: an identity at the end
        self._world = np.eye(4)
        self._centers_in = np.ascontiguousarray(self._center_local.T)
        self._pick = (4 * self._slot[:, None] + np.arange(3)) * n + np.arange(n)[:, None]
        D = np.zeros((len(self.pairs), n))
        D[np.arange(len(self.pairs)), self._pa] = 1.0
        D[np.arange(len(self.pairs)), self._pb] -= 1.0
        self._difference = D
        # the sphere-box test pays only where exact distances are dear (meshes)
        self._refine = any(isinstance(g.geometry, coal.BVHModelBase)
                           and not isinstance(g.geometry, coal.ConvexBase)
                           for g in self.geometry.geometryObjects)

    def _jacobian_support(self) -> None:
        """``_support[j]``: the columns of Pinocchio's WORLD joint Jacobians (data.J) that move
        joint j's frame; data.J has a column per joint coordinate, mimic joints' included
        (nvExtended), which ``_mimic`` folds onto the coordinates they follow."""
        model = self.model
        self._support = np.zeros((model.njoints, model.nvExtended))
        for j in range(1, model.njoints):
            for i in model.supports[j]:
                if i > 0:
                    start = model.idx_vExtendeds[i]
                    self._support[j, start:start + model.nvExtendeds[i]] = 1.0

    def _skip_state(self) -> None:
        """The levers that bound how far the joints move a pair (:meth:`_pair_levers`), and
        the state of the skip of the broad phase and of the queries: the last broad phase
        (obstacles' version, q, its pairs, each pair's gap, its pairs as a list) and each
        pair's floor, a lower bound of its exact distance at ``_floor_q`` (m): its distance at
        its last query, less the levers' bound of every move since (:meth:`_aged`); while it
        exceeds influence, the pair is not queried."""
        self._version = 0  # bumped by move(): a new scene
        self._cache: tuple | None = None
        self._kinds, self._extent, self._lower, self._upper = _extents(
            self.model, getattr(self, "_mimics", ()))
        self._lever = self._levers()
        # the speed bounds: (dt, the speed limits, whether they let a step cross the band,
        # (lower, upper))
        self._bounds: tuple[float, np.ndarray | None, bool, tuple] | None = None
        self._pair_lever, self._flat = self._pair_levers()
        self._reference: tuple[int, np.ndarray, np.ndarray, np.ndarray, list] | None = None
        self._floor = np.full(len(self.pairs), -np.inf)
        self._prefilter = np.full(1 + 3 * len(self.pairs), -1.0)  # (near_pairs' order)
        self._floor_q: np.ndarray | None = None  # where the floors hold (None: nowhere)
        self._influence = np.full(len(self.pairs), self.influence)  # each pair's, m
        self._braking_influence = np.zeros(len(self.pairs))  # kernels.braking_reach's output
        #: what kernels.collision_rows reads and writes besides the step's (arrays changed in
        #: place only)
        self._tables = CollisionTables(
            geometry=self.geometry, geometry_data=self.geometry_data, model=self.model,
            update=pin.updateGeometryPlacements, floor=self._floor, margins=self.margins,
            joints=self._joint_table, rows=self._pair_rows, memory=self._memory,
            state=self._memory_state, owners=self._owners, support=self._support,
            mimic=self._mimic, keep=0.5 * (self.influence - self.margin), apart=WITNESS_APART,
            witnesses=self.witnesses > 0)
        self._skip: Skip | None = None  # near_pairs' (from _reference and _floor_q)
        self._views: tuple = (None, None)  # (a data, collision_rows' views onto it)
        # each pair's reach at the solver's speed limits (_reach): (those limits, the reach)
        self._reaches: tuple[object, np.ndarray | None] = (self, None)  # (none yet)

    def _chains(self, unbounded: float) -> tuple[np.ndarray, np.ndarray]:
        """For each geometry g and joint coordinate (nvExtended) of a joint k that moves it:
        a bound (m) on the distance from joint k's origin to any point of g's bounding
        sphere, over every configuration with the translating joints in their ranges
        (:func:`_extents`): the sphere's far side from g's joint, plus, for each joint i from
        g's joint up to (not including) k, its fixed offset (``jointPlacements``) and how far
        its own motion can carry its frame (a prismatic joint's extension); ``unbounded``
        stands for the extension of a joint without a finite range. And which coordinates
        move g at all. The sum of :meth:`_levers` and :meth:`_pair_levers`."""
        model = self.model
        n = len(self.geometry.geometryObjects)
        extent = np.where(np.isfinite(self._extent), self._extent, unbounded)
        chain = np.zeros((n, model.nvExtended))
        moves = np.zeros((n, model.nvExtended), dtype=bool)
        for g in range(n):
            k = int(self._joint[g])
            length = float(np.linalg.norm(self._center_local[g, :3]) + self._radius[g])
            while k > 0:
                start = model.idx_vExtendeds[k]
                span = slice(start, start + model.nvExtendeds[k])
                chain[g, span] = length
                moves[g, span] = True
                length += float(np.linalg.norm(model.jointPlacements[k].translation)) + extent[k]
                k = model.parents[k]
        return chain, moves

    def _pair_levers(self) -> tuple[np.ndarray | None, bool]:
        """For each pair and velocity coordinate, a bound (m per unit) on how much the
        coordinate changes the distance between any two points of the pair's bounding
        spheres, at every configuration whose translating joints lie in their ranges
        (:attr:`_inside`): :meth:`_chains` to the far side of either sphere when it moves only
        one of them (at least 1 m for a joint that translates: a prismatic joint's own
        displacement moves the geometry 1:1), 0 when it moves both (rigidly together), summed
        over the joints it drives (a mimic joint's times its multiplier); and whether ``q`` is
        its own tangent space (revolute and prismatic joints, mimic joints following them).
        ``None`` (no skip) for joints whose coordinates are not rates of a motion (Euler
        angles), or when a joint without a finite range of translation lies between a pair's
        geometry and a joint that moves it."""
        model = self.model
        kinds = self._kinds
        if any("ZYX" in kind for kind in kinds[1:]):
            return None, False
        flat = model.nq == model.nv and all(model.nqs[j] == model.nvs[j] <= 1
                                             for j in range(1, model.njoints))
        chain, moves = self._chains(np.inf)
        translates = np.zeros(model.nvExtended, dtype=bool)
        for k in range(1, model.njoints):
            start = model.idx_vExtendeds[k]
            translates[start:start + model.nvExtendeds[k]] = _translates(kinds[k])
        lever = np.where(translates, np.maximum(chain, 1.0), chain)
        lever[~moves] = 0.0
        one = moves[self._pa] != moves[self._pb]
        pair = np.where(one, lever[self._pa] + lever[self._pb], 0.0)
        if not np.isfinite(pair).all():
            return None, False
        if self._mimic is not None:
            pair = pair @ np.abs(self._mimic)
        return pair, flat

    def _levers(self) -> np.ndarray:
        """For each velocity coordinate, a bound (m per unit) on the speed it gives any point of
        the geometry it moves: the longest of :meth:`_chains` (triangle inequality), or at
        least 1 m for a joint that translates (prismatic, planar, free-flyer). A joint without
        a finite range of translation counts at its origin here (these bounds only keep steps
        small, :meth:`bounds`; the broad phase's skip does not use them)."""
        model = self.model
        chain, _ = self._chains(0.0)
        reach = chain[:self.n_robot].max(axis=0) if self.n_robot else np.zeros(model.nvExtended)
        lever = np.zeros(model.nvExtended)
        for j in range(1, model.njoints):
            start = model.idx_vExtendeds[j]
            span = slice(start, start + model.nvExtendeds[j])
            lever[span] = (np.maximum(reach[span], 1.0) if _translates(self._kinds[j])
                           else reach[span])
        if self._mimic is not None:  # a coordinate's lever: the largest of the joints it drives
            lever = (np.abs(self._mimic) * lever[:, None]).max(axis=0)
        return lever

    def bounds(self, kinematics, motion: Motion) -> tuple[np.ndarray, np.ndarray] | None:
        """Speed bounds (rad/s or m/s) that keep each step small against the damper: no
        joint moves a point of the geometry it carries by more than ``(influence - margin) /
        2`` in one period, so that the first-order rows hold (a correction of the stage that
        turns a joint by a radian in one step would carry a link through an obstacle before
        any row could see it) and no link crosses the band from beyond ``influence`` into
        ``margin`` between two steps. Far above a robot's own speeds at usual periods: 20 rad/s
        for a 1 m lever at 1 kHz with the defaults. On every step where the solver's speed
        limits (``motion.velocity_limits``) do not keep within them already (a free-flying
        base without a speed limit, a long period), never where they do; without speed limits
        (``solve()``'s iterations), while a pair is within ``influence``."""
        dt, speeds, known = motion.dt, motion.velocity_limits, self._bounds
        if known is None or known[1] is not speeds or known[0] != dt:
            cap = self.speed_caps(dt)
            lower = -cap
            lower.setflags(write=False)
            loose = speeds is not None and not bool(np.all(speeds <= cap))
            self._bounds = known = (dt, speeds, loose, (lower, cap))
        if speeds is not None:
            return known[3] if known[2] else None
        # no speed limits (solve()'s iterations): while a pair is within influence
        return known[3] if self.rows(kinematics, motion) is not None else None

    def speed_caps(self, dt: float) -> np.ndarray:
        """The speed bounds of :meth:`bounds` at period ``dt`` (s): ``(influence - margin) /
        (2 dt lever)`` (rad/s or m/s) for each joint with a lever (inf for the others;
        read-only). They bind only where the solver's own speed limits are loose, and there on
        every step, so a solver may hold them with its own."""
        if not dt > 0:
            raise ValueError(f"dt must be a period > 0 (s), got {dt!r}")
        with np.errstate(divide="ignore"):
            cap = np.where(self._lever > 0, (self.influence - self.margin)
                           / (2.0 * dt * self._lever), np.inf)
        cap.setflags(write=False)
        return cap

    # -- obstacles ---------------------------------------------------------------------------
    def move(self, i: int, pose: pin.SE3, velocity=None) -> None:
        """Move obstacle ``i`` (its index in ``obstacles``) to ``pose`` before the next step.

        ``velocity``: the obstacle's velocity at ``pose`` (6,): the linear velocity of its
        origin (m/s) then its angular velocity (rad/s), both in world axes (Pinocchio's
        ``LOCAL_WORLD_ALIGNED`` twist; a ``pin.Motion`` is read the same way); None for an
        obstacle at rest. It holds until the next ``move`` - move a moving obstacle every
        step. Each row of a pair with a moving obstacle then bounds the relative normal
        velocity of its closest points (module docstring, "Moving obstacles"): the arm gives
        way as its limits allow."""
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"obstacle index must be an int, got {type(i).__name__}")
        if not 0 <= i < len(self._obstacle_ids):
            raise IndexError(f"obstacle {i} does not exist ({len(self._obstacle_ids)} obstacles)")
        _check_pose(pose, f"pose of obstacle {i}")
        twist = _twist(velocity, f"velocity of obstacle {i}")
        g = self._obstacle_ids[i]
        changed = bool(np.any(twist != self._velocity[i]))
        obj = self.geometry.geometryObjects[g]
        obj.placement = pose
        H = self._placement[g] = pose.homogeneous
        self._center_local[g, :3] = self._centers_in[:3, g] = (H[:3, :3] @ self._box_center[g]
                                                              + H[:3, 3])
        if changed:
            self._velocity[i] = twist
            self._moving_speeds()
        self._version += 1
        self._skip = None  # (its broad phase is of the old scene)
        self._tick += 2.0  # the remembered points on the obstacle moved: forget every one

    def _moving_speeds(self) -> None:
        """Each pair's bound on its obstacle's speed (m/s) at any point of the obstacle's
        bounding sphere, ``|v| + |w| (|c| + r)`` (``c`` the sphere's centre in the obstacle's
        frame, ``r`` its radius; inf for a turning Halfspace or Plane), 0 for a pair of the
        robot's own links: ``_pair_speed``; ``_moving``: whether any is above 0."""
        if not len(self._obstacle_ids):
            self._pair_speed, self._moving = np.zeros(len(self.pairs)), False
            return
        linear = np.linalg.norm(self._velocity[:, :3], axis=1)
        turn = np.linalg.norm(self._velocity[:, 3:], axis=1)
        index = self._pair_obstacle
        mine = index >= 0
        pick = np.where(mine, index, 0)
        with np.errstate(invalid="ignore"):
            spin = np.where(turn[pick] > 0, turn[pick] * self._pair_far, 0.0)
        self._pair_speed = np.where(mine, linear[pick] + spin, 0.0).sum(axis=1)
        self._moving = bool(np.any(self._pair_speed > 0))

    @staticmethod
    def _lookahead(motion: Motion) -> float:
        """How long (s) a pair with a moving obstacle is watched ahead: the obstacle's
        travel in this time widens the pair's influence. Two periods (the obstacle may close
        a period's travel before the row sees it and another while the step runs); with
        acceleration limits also the longest time a joint takes to reach its speed limit
        (at most 1 s), and with jerk limits the longest ramp to its acceleration limit: the
        arm may need that long to match the obstacle's speed."""
        time = 2.0 * motion.dt
        accelerations = motion.acceleration_limits
        if accelerations is None:
            return time
        speeds = motion.velocity_limits
        with np.errstate(divide="ignore", invalid="ignore"):
            if speeds is not None:
                reach = speeds / accelerations
                reach = reach[np.isfinite(reach)]
                time += min(float(reach.max()), 1.0) if reach.size else 1.0
            else:
                time += 1.0
            if motion.jerk_limits is not None:
                ramp = accelerations / motion.jerk_limits
                ramp = ramp[np.isfinite(ramp)]
                time += float(ramp.max()) if ramp.size else 0.0
        return time

    def _carried(self, out: tuple[np.ndarray, np.ndarray] | None
                 ) -> tuple[np.ndarray, np.ndarray] | None:
        """``out``, the rows of this step, with each bound raised by the normal velocity of the
        moving obstacle's closest point away from the robot (lowered where it comes closer):
        ``b_i + n^T (v_b(p_b) - v_a(p_a))`` with ``v_x(p) = v + w x (p - o)`` for an obstacle
        with twist ``(v, w)`` and origin ``o`` (0 for a link of the robot), so that the row
        bounds the pair's relative closing speed (module docstring, "Moving obstacles")."""
        if out is None or not self._moving:
            return out
        A, b = out
        count = len(self.active)
        owners = np.concatenate([np.asarray(self.active, dtype=np.int64),
                                 self._owners[:self._witness_count].astype(np.int64)])
        rows = self._pair_rows[:count + self._witness_count]
        normal = rows[:, 4:7]
        shift = np.zeros(len(owners))
        for side, sign, points in ((1, 1.0, rows[:, 10:13]), (0, -1.0, rows[:, 7:10])):
            index = self._obstacle_of[self.pairs[owners, side]]
            mine = np.flatnonzero(index >= 0)
            if mine.size == 0:
                continue
            twist = self._velocity[index[mine]]
            origin = self._placement[self.pairs[owners[mine], side], :3, 3]
            velocity = twist[:, :3] + np.cross(twist[:, 3:], points[mine] - origin)
            shift[mine] += sign * np.einsum("ij,ij->i", normal[mine], velocity)
        carried = b + shift
        carried.setflags(write=False)
        return A, carried

    @property
    def obstacles(self) -> list[tuple]:
        """The obstacles as ``(coal shape, pin.SE3)`` pairs, at their current poses."""
        geoms = self.geometry.geometryObjects
        return [(shape, pin.SE3(geoms[g].placement))
                for shape, g in zip(self._obstacle_shapes, self._obstacle_ids, strict=True)]

    @property
    def velocities(self) -> np.ndarray:
        """The obstacles' velocities (nobstacles, 6) as :meth:`move` set them: linear (m/s)
        then angular (rad/s), world axes (a copy)."""
        return self._velocity.copy()

    # -- queries -----------------------------------------------------------------------------
    def _broad_phase(self, data, influence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pairs whose bounding volumes come within their ``influence`` (npairs,; indices
        into pairs), and for each pair the gap (m) between its bounding volumes.

        Each geometry has a box in its own frame (coal's local AABB) and the sphere around it.
        First the spheres of both (for every pair), then, where exact distances are dear
        (meshes), for the few pairs left, the sphere of either one against the other's box:
        volumes contain their geometry, so neither test drops a pair within its influence."""
        views = self._data_views(data)
        if views is not data and not self._refine:  # (compiled: joint poses read in place)
            gap = self._sphere_gaps(views)
            return np.flatnonzero(gap < influence), gap
        oMi = data.oMi.tolist()
        H = np.concatenate([oMi[j].homogeneous for j in self._joints] + [self._world])
        center = (H @ self._centers_in).take(self._pick)
        diff = self._difference @ center
        gap = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self._span
        near = np.flatnonzero(gap < influence)
        if near.size == 0 or not self._refine:
            return near, gap
        # both directions at once: the sphere of a against b's box, and of b against a's box
        one = np.concatenate((self._pa[near], self._pb[near]))
        other = np.concatenate((self._pb[near], self._pa[near]))
        poses = H.reshape(-1, 4, 4)[self._slot[other]] @ self._placement[other]
        box_gap = (self._sphere_box(center[one], poses, other) - self._radius[one]).reshape(2, -1)
        gap[near] = np.maximum(box_gap[0], box_gap[1])
        return np.flatnonzero(gap < influence), gap

    def _near(self, data, q: np.ndarray | None, influence: np.ndarray,
              stale: bool = False) -> np.ndarray:
        """:meth:`_broad_phase`'s pairs at ``q``, from the last broad phase while ``q`` is close
        to where it ran: a displacement ``dq`` from there changes the distance of a pair's
        bounding spheres by at most ``sum_j lever_j |dq_j|`` (:meth:`_pair_levers`), so a
        pair it left out stays out until that plus its influence reaches the gap it left the
        pair at (``stale``: ``kernels.near_pairs`` found it does). A new broad phase keeps the
        floors of the pairs it had before (the others have none)."""
        inside = q is not None and self._inside(q)
        ref = self._reference if inside and self._reference is not None \
            and self._reference[0] == self._version else None  # (None: floors gone too)
        if ref is not None and q is not None and not stale:  # (ref: q inside the box)
            if (self._pair_lever @ self._moved(ref[1], q) + influence < ref[3]).all():
                return ref[2]
        near, gap = self._broad_phase(data, influence)
        if q is not None and inside and self._pair_lever is not None:
            # the pairs within a skin of half the band (influence - margin) of being candidates
            # are candidates too, as in a Verlet list: the next broad phase waits until some
            # bound reaches the skin at least (Panda's scenes: on 1-3 % of the steps instead
            # of 8-16 %), and an extra candidate costs one exact query (its floor skips it
            # after that; a wider skin queries more than it saves)
            near = np.flatnonzero(gap < influence + 0.5 * (self.influence - self.margin))
            gap[near] = np.inf  # a candidate stays one
            kept = np.full(len(self.pairs), -np.inf)
            if ref is not None:  # (after a move() of an obstacle the floors are gone)
                kept[ref[2]] = self._floor[ref[2]]
            self._floor[:] = kept
            self._reference = (self._version, q.copy(), near, gap, near.tolist())
        else:
            self._reference = None  # no reference outside the box the levers hold in
            self._floor.fill(-np.inf)
            self._floor_q = None
        self._skip = None
        return near

    def _refresh(self, data, q: np.ndarray, influence: np.ndarray) -> list[int] | None:
        """A new broad phase at ``q`` and the pairs to query, as :meth:`_near` (stale) then
        :meth:`_aged` make them, in two compiled calls (``kernels.sphere_gaps`` and
        ``kernels.refresh_pairs``); None (nothing changed) where those do not apply: the
        sphere-box refinement, no levers, the views missing, ``q`` outside the box the
        levers hold in."""
        views = self._data_views(data)
        if views is data or self._refine or self._pair_lever is None:
            return None
        gap = self._sphere_gaps(views)
        ref = self._reference
        kept = ref[4] if ref is not None and ref[0] == self._version else None
        out = refresh_pairs(q, self._lower, self._upper, gap, influence,
                            0.5 * (self.influence - self.margin), self._floor, kept,
                            self._floor_q, self._pair_lever)
        if out is None:
            return None
        near, listed = out
        self._reference = (self._version, q.copy(), np.array(near, dtype=np.intp), gap, near)
        if self._floor_q is None:
            self._floor_q = q.copy()
        self._skip = None
        return listed

    def _sphere_gaps(self, views) -> np.ndarray:
        """The gap (m) between the bounding spheres of each pair (npairs,), from the joint
        poses the ``views`` (:meth:`_data_views`) read in place (``kernels.sphere_gaps``)."""
        gap = np.empty(len(self.pairs))
        sphere_gaps(views, self._joint, self._center_local, self.pairs, self._span, gap)
        return gap

    def _aged(self, q: np.ndarray | None, near: np.ndarray, influence: np.ndarray) -> np.ndarray:
        """The pairs of ``near`` (the last broad phase's, :meth:`_near`) to query at ``q``:
        those whose floor, aged from ``_floor_q`` to ``q`` by the levers' bound, is within
        their influence (every pair where the floors hold nowhere)."""
        lever = self._pair_lever
        if q is None or self._reference is None or lever is None:
            return near
        if self._floor_q is None:  # (every floor is -inf: _near)
            self._floor_q = q.copy()
            self._skip = None
            return near
        self._floor[near] -= lever[near] @ self._moved(self._floor_q, q)
        self._floor_q[:] = q
        return near[self._floor[near] <= influence[near]]

    def _moved(self, start: np.ndarray, q: np.ndarray) -> np.ndarray:
        """|q - start| per velocity coordinate (rad, m; on the manifold where q is not its own
        tangent space), what :meth:`_pair_levers` multiply."""
        return np.abs(q - start if self._flat else pin.difference(self.model, start, q))

    def _inside(self, q: np.ndarray) -> bool:
        """Whether ``q`` lies in the box of position limits :meth:`_pair_levers` holds in."""
        return bool(np.all(q >= self._lower) and np.all(q <= self._upper))

    def _sphere_box(self, points, poses, g) -> np.ndarray:
        """Distance of world ``points`` (k, 3) to the local boxes of geometries ``g``."""
        local = np.einsum("kji,kj->ki", poses[:, :3, :3], points - poses[:, :3, 3])
        outside = np.maximum(np.abs(local - self._box_center[g]) - self._box_half[g], 0.0)
        return np.sqrt(np.einsum("ki,ki->k", outside, outside))

    def _distance(self, k: int):
        return pin.computeDistance(self.geometry, self.geometry_data, int(k))

    def check(self, q: np.ndarray) -> None:
        """Raise :class:`CollisionError` if an obstacle overlaps the robot at ``q``, and take
        ``q`` as the start (what the first step does otherwise): pairs of the robot's links
        that overlap there are dropped, those closer than ``margin`` keep their distance."""
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        self._check(self.model, self._data)

    def _check(self, model, data) -> None:
        """At the start: an obstacle that overlaps the robot is an error; a pair of the robot's
        own links that overlaps (meshes that intersect in the URDF's pose, as adjacent links'
        do) is dropped, with a warning; one closer than ``margin`` keeps its start distance
        as its margin (:attr:`margins`)."""
        pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        start = np.array([self._distance(k).min_distance for k in range(len(self.pairs))])
        own = (self.pairs[:, 0] < self.n_robot) & (self.pairs[:, 1] < self.n_robot)
        for k in np.flatnonzero(~own & ~(start > 0)):
            a, b = self.pairs[k]
            na, nb = self.pair_names[k]
            raise CollisionError(f"{nb if b >= self.n_robot else na} overlaps "
                                 f"{na if b >= self.n_robot else nb} at the start "
                                 f"(distance {start[k] * 1e3:.1f} mm); move the obstacle or "
                                 "the start configuration")
        overlap = own & ~(start > 0)
        if overlap.any():
            import warnings

            names = [self.pair_names[k] for k in np.flatnonzero(overlap)]
            warnings.warn(f"CollisionLimit: {len(names)} pair(s) of links overlap at the start "
                          f"and are not checked: {names}", stacklevel=4)
            keep = ~overlap
            start = start[keep]
            self._set_pairs([(int(a), int(b)) for a, b in self.pairs[keep]])
            self._prepare_broad_phase()
            pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        own = (self.pairs[:, 0] < self.n_robot) & (self.pairs[:, 1] < self.n_robot)
        close = own & (start < self.margin)
        self.margins[close] = start[close]
        inside = np.flatnonzero(~own & (start < self.margin))
        if inside.size:
            import warnings

            said = ", ".join(f"{self.pair_names[k][0]} / {self.pair_names[k][1]} at "
                             f"{start[k] * 1e3:.1f} mm" for k in inside)
            warnings.warn(f"CollisionLimit: the robot starts inside the {self.margin * 1e3:g} mm "
                          f"margin of an obstacle ({said}); its rows move it out, within the "
                          "solver's limits", UserWarning, stacklevel=4)
        self._checked = True

    def distances(self, q: np.ndarray) -> list[PairDistance]:
        """Every checked pair at ``q`` with its exact distance (m), closest first."""
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        pin.updateGeometryPlacements(self.model, self._data, self.geometry, self.geometry_data)
        out = []
        for k, (a, b) in enumerate(self.pairs):
            d = self._distance(k).min_distance
            na, nb = self.pair_names[k]
            out.append(PairDistance(na, nb, self._link(a), self._link(b), float(d)))
        out.sort(key=lambda p: p.distance)
        return out

    def placements(self, q: np.ndarray) -> list[tuple[str, object, np.ndarray]]:
        """The robot's checked geometry at ``q``: ``(name, coal shape, 4x4 world pose)`` for
        each geometry that moves (hulls with ``convex=True``), e.g. to draw it."""
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        pin.updateGeometryPlacements(self.model, self._data, self.geometry, self.geometry_data)
        geoms = self.geometry.geometryObjects
        return [(geoms[g].name, geoms[g].geometry, self.geometry_data.oMg[g].homogeneous)
                for g in range(self.n_robot) if geoms[g].parentJoint != 0]

    def closest_points(self, q: np.ndarray, within: float | None = None
                       ) -> list[ClosestPoints]:
        """The checked pairs closer than ``within`` (m; default ``influence``) at ``q``, with
        their closest points, closest first (e.g. to draw them: ``Viewer.show(..., collision=)``).
        """
        within = self.influence if within is None else float(within)
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        pin.updateGeometryPlacements(self.model, self._data, self.geometry, self.geometry_data)
        out = []
        for k, (a, b) in enumerate(self.pairs):
            res = self._distance(k)
            d = res.min_distance
            if d < within:
                na, nb = self.pair_names[k]
                out.append(ClosestPoints(PairDistance(na, nb, self._link(a), self._link(b),
                                                      float(d)),
                                         np.array(res.getNearestPoint1()),
                                         np.array(res.getNearestPoint2())))
        out.sort(key=lambda p: p.distance)
        return out

    def rows(self, kinematics, motion: Motion) -> tuple[np.ndarray, np.ndarray] | None:
        """Rows ``A q_dot <= b`` (A: (k, nv) in m per unit of q_dot, b: (k,) in m/s) at the
        configuration of ``kinematics`` (after ``update(q)``: its joint poses and WORLD joint
        Jacobians), one for each pair within ``influence`` (:attr:`active`, then the witness
        rows) but those that no step within the solver's speed limits
        (``motion.velocity_limits``) can break (:meth:`_reach`; :attr:`within` lists them
        all); None when there is none. With acceleration limits in ``motion`` each bound is
        also cut to a closing speed they can stop within the pair's excess over ``margin``
        (module docstring, "Acceleration limits"), and every pair within influence has its
        row. A second call at the same configuration, period, obstacle poses and motion
        returns the same (read-only) arrays."""
        skip, q, listed = self._skip, kinematics.q, False
        # (most steps: nothing to query, as near_pairs finds; a moving obstacle queries)
        if skip is not None and q is not None and motion.acceleration_limits is None \
                and motion.dt > 0 and not self._moving:
            listed = near_pairs(q, skip, self._influence)
            if listed == []:
                if self.active or self.within:
                    self.active, self.within = [], []
                self._witness_count = 0
                return None
            views, speeds = self._views, motion.velocity_limits
            if listed and views[0] is kinematics.data and self._reaches[0] is speeds \
                    and self._checked:  # (a step like the last: no check, views and reach)
                here = self._key(q, motion)
                cache = self._cache
                if cache is not None and cache[0] is views[0] and cache[1] == here:
                    self.active, self.within, self._witness_count = cache[2]
                else:
                    out = self._queried(views, listed, self._influence, self._reaches[1],
                                        motion.dt)
                    cache = self._cache = (views[0], here, (self.active, self.within,
                                                            self._witness_count), out)
                return cache[3]
        data, dt = kinematics.data, motion.dt
        accelerations, jerks = motion.acceleration_limits, motion.jerk_limits
        key = self._key(q, motion)
        cache = self._cache
        if cache is not None and q is not None and cache[0] is data and cache[1] == key:
            self.active, self.within, self._witness_count = cache[2]
            return cache[3]
        if not dt > 0:
            raise ValueError(f"dt must be a period > 0 (s), got {dt!r}")
        if not self._checked:
            self._check(kinematics.model, data)
        influence = self._influence
        if accelerations is not None and self._pair_lever is not None:
            influence = self._braking_influence
            braking_reach(self._pair_lever, motion.dq, accelerations, jerks, dt, BRAKING_SHARE,
                          self.influence, self.margin, influence)
        if accelerations is None:
            speeds, reaches = motion.velocity_limits, self._reaches
            reach = reaches[1] if reaches[0] is speeds else self._reach(speeds)
        else:
            reach = None  # (the stoppable rows below are tighter than the damper's)
        if self._moving:  # (the rows of a pair bound its relative speed: _carried)
            influence = influence + self._pair_speed * self._lookahead(motion)
            if reach is not None:
                reach = reach + self._pair_speed
        out = self._rows(data, dt, q, influence, reach, listed)
        if out is not None and accelerations is not None:
            b = out[1]
            b.setflags(write=True)  # (its own data: the rows' bounds, cut in place)
            stoppable_rows(out[0], b, motion.dq, motion.ddq, accelerations, jerks,
                           self.gain / dt, dt, BRAKING_SHARE, EASING_SLACK)
            b.setflags(write=False)
        out = self._carried(out)
        self._cache = (data, key, (self.active, self.within, self._witness_count), out)
        return out

    def _key(self, q: np.ndarray | None, motion: Motion) -> tuple:
        """What :meth:`rows` answers for, its cache's key: the configuration, the period, the
        obstacles' poses (``_version``) and the motion's limits, with acceleration limits its
        joint speeds and accelerations too."""
        where = None if q is None else q.tobytes()
        accelerations = motion.acceleration_limits
        if accelerations is None:
            return (where, motion.dt, self._version, id(motion.velocity_limits))
        return (where, motion.dt, self._version, id(accelerations), id(motion.jerk_limits),
                motion.dq.tobytes() + motion.ddq.tobytes())

    def _reach(self, speeds: np.ndarray | None) -> np.ndarray | None:
        """Each pair's reach (npairs,; m/s; kept for these ``speeds``): the fastest its
        distance can shrink at the solver's speed limits (``motion.velocity_limits``, which
        every step it commands keeps), ``sum_j lever_kj v_j`` (:meth:`_pair_levers`). A pair
        whose damper bound ``gain (d - margin) / dt`` is not below it needs no row: no step can
        break it. None without speed limits (``solve()``'s iterations) or levers."""
        reach = None
        if speeds is not None and self._pair_lever is not None:
            finite = np.isfinite(speeds)
            reach = self._pair_lever @ np.where(finite, speeds, 0.0)
            reach[(self._pair_lever[:, ~finite] > 0).any(axis=1)] = np.inf
        self._reaches = (speeds, reach)
        return reach

    @property
    def witness_pairs(self) -> list[int]:
        """The pairs (indices into :attr:`pairs`) of the witness rows of the last
        :meth:`rows`, which follow the rows of :attr:`active` (one each)."""
        return self._owners[:self._witness_count].astype(int).tolist()

    def _rows(self, data, dt: float, q: np.ndarray | None, influence: np.ndarray,
              reach: np.ndarray | None, listed: list[int] | None | bool = False
              ) -> tuple[np.ndarray, np.ndarray] | None:
        """rows() at ``q``; ``listed``: ``kernels.near_pairs``' answer at ``q`` with these
        ``influence`` where rows() asked it already (False where it did not)."""
        self.active = []  # indices into self.pairs / self.pair_names of the rows returned
        self.within = []
        self._witness_count = 0
        ref = self._reference
        # a pair's distance changes by at most its levers' bound (_near): one that was beyond
        # influence by more than that at its last query still is; both tests compiled where q
        # is its own tangent space, else _near, _aged and numpy
        if listed is not False:
            stale = listed is None
        elif (self._flat and q is not None and ref is not None and ref[0] == self._version
                and self._floor_q is not None):
            skip = self._skip
            if skip is None:  # (what near_pairs reads, since the last broad phase)
                self._prefilter[0] = -1.0  # (near_pairs orders its test for this gap)
                skip = self._skip = Skip(
                    reference=ref[1], lower=self._lower, upper=self._upper,
                    lever=self._pair_lever, gap=ref[3], near=ref[2], floor=self._floor,
                    floor_q=self._floor_q, prefilter=self._prefilter)
            listed = near_pairs(q, skip, influence)
            stale = listed is None
        else:
            listed, stale = None, False
        if listed is None and q is not None and self._flat and (
                stale or ref is None or ref[0] != self._version):
            listed = self._refresh(data, q, influence)
        if listed is None:
            listed = self._aged(q, self._near(data, q, influence, stale), influence).tolist()
        if not (isinstance(listed, list) and listed):
            return None
        self._data_views(data)
        return self._queried(self._views, listed, influence, reach, dt)

    def _queried(self, views: tuple, listed: list[int], influence: np.ndarray,
                 reach: np.ndarray | None, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The rows of the pairs ``listed`` (:attr:`active`, :attr:`within` and the witness
        count set): the geometries' placements, coal's distance of each pair (those within
        influence get a row, unless it cannot bind at the speed limits: :meth:`_reach`), their
        witnesses' rows and the damper rows of them all, in one compiled call (the Python
        around each query and between the parts cost more than the queries); ``views``:
        :attr:`_views`, ``(data, its views or data itself)``."""
        rate = self.gain / dt
        out = collision_rows(self._tables, listed, views[1], rate, influence, self._tick + 1.0,
                             reach, self._compute)
        if out is None:
            self.active, self.within, self._witness_count = [], [], 0
            return None
        self.within, found, A, b, self._witness_count = out
        self.active = found
        if not found:
            return None
        if A is None:  # a query found no closest points: its row first, then the rest
            return self._formed_rows(views[0], found, rate)
        if self.witnesses:
            self._tick += 1.0
        return A, b

    def _data_views(self, data) -> object:
        """``kernels.collision_rows``' views onto ``data`` (Pinocchio's data of the solver's
        kinematics): ``(data, data.J, [oMi[j].rotation], [oMi[j].translation])``, numpy
        arrays on its own memory that the kernel reads without a Python call (kept while the
        same data comes back); ``data`` itself where Pinocchio's bindings give copies."""
        if self._views[0] is data:
            return self._views[1]
        parts = [data.J] + [getattr(data.oMi[j], name) for name in ("rotation", "translation")
                            for j in range(self.model.njoints)]
        n = self.model.njoints
        views = data if any(part.flags.owndata or part.base is not None for part in parts) \
            else (data, parts[0], parts[1:1 + n], parts[1 + n:])
        self._views = (data, views)
        return views

    def _formed_rows(self, data, found: list[int], rate: float) -> tuple[np.ndarray, np.ndarray]:
        """The rows of a step where some query found no closest points (:meth:`_centre_rows`
        forms theirs), its witnesses' and the damper rows of them all, as
        ``kernels.collision_rows`` makes them otherwise."""
        self._centre_rows(data, found)
        count = self._witness_rows(data, found) if self.witnesses else len(found)
        A = np.empty((count, self._support.shape[1]))
        b = np.empty(count)
        damper_rows(data.J, self._support, self._pair_rows[:count], rate, A, b)
        if self._mimic is not None:
            A = A @ self._mimic
        A.setflags(write=False)
        b.setflags(write=False)
        return A, b

    def _centre_rows(self, data, found: list[int]) -> None:
        """The rows of the pairs coal found no closest points for (deep in a penetration, as a
        restart of ``solve()`` may start: ``kernels.collision_rows`` marks them ``d = -inf``):
        along the line between the centres of the two geometries' bounding spheres, at the
        depth by which the spheres overlap (at least 1 mm), so that they separate, and the
        configuration is not taken for one within the limit."""
        rows = self._pair_rows
        for i, k in enumerate(found):
            if rows[i, 0] != -np.inf:
                continue
            centres = []
            for g in self.pairs[k]:
                pose = data.oMi[int(self._joint[g])]
                centres.append(pose.rotation @ self._center_local[g, :3] + pose.translation)
            u = centres[1] - centres[0]
            apart = float(np.linalg.norm(u))
            normal = u / apart if apart > 0 else np.array([0.0, 0.0, 1.0])
            overlap = self._radius[self.pairs[k]].sum() - apart
            rows[i, 0] = -max(overlap, 1e-3) if np.isfinite(overlap) else -1e-3
            rows[i, 4:7], rows[i, 7:10], rows[i, 10:13] = normal, centres[0], centres[1]

    def _witness_rows(self, data, found: list[int]) -> int:
        """Append to the step's rows (``_pair_rows[:len(found)]``) one per remembered witness
        of each pair in ``found`` (module docstring, "Witnesses"; ``kernels.witness_rows``) and
        remember this step's closest points; returns the number of rows."""
        count = len(found)
        self._tick += 1.0
        total = witness_rows(data.oMi, self._flat_poses, self._pair_rows, found, self._memory,
                             self._memory_state,
                             self._tick, 0.5 * (self.influence - self.margin), WITNESS_APART,
                             self._owners)
        self._witness_count = total - count
        return total


def damper_rows_reference(J: np.ndarray, support: np.ndarray, pairs: np.ndarray, rate: float
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``kernels.damper_rows`` in numpy: coal's normal ``n`` points from geometry a to b, so
    ``n^T (v_a - v_b) = -d_dot``; the WORLD Jacobian of joint j (its supports' columns) moves
    a point p fixed to it at ``v_O + w x p``, so ``n.v(p) = n.v_O + (p x n).w``."""
    pairs = np.atleast_2d(pairs)
    n = pairs[:, 4:7]
    ends = []
    for side, joints in ((pairs[:, 7:10], pairs[:, 2]), (pairs[:, 10:13], pairs[:, 3])):
        u = np.hstack([n, np.cross(side, n)])
        ends.append((u @ J) * support[joints.astype(int)])
    return ends[0] - ends[1], rate * (pairs[:, 0] - pairs[:, 1])


def _translates(kind: str) -> bool:
    """Whether a joint of this ``shortname()`` translates (its coordinates move points by at
    least a metre per unit)."""
    return any(t in kind for t in ("Prismatic", "FreeFlyer", "Planar", "Translation",
                                   "JointModelP"))


#: joints (``shortname()``) whose motion only turns their frame about its origin
_TURNS = ("JointModelR", "JointModelSpherical", "JointModelUniversal")


def _extents(model: pin.Model, mimics: Sequence = ()
             ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Per joint: its kind (``shortname()``; a mimic joint's is the kind of the joint it
    follows) and how far (m) its own motion can carry its frame's origin over its position
    range: 0 for joints that only turn, the largest translation in the box of the URDF limits
    for prismatic, translation, planar and free-flyer joints (``inf`` where a limit is not
    finite, and for any other kind); and the box ``lower <= q <= upper`` (nq,) those extents
    hold in (``-inf``/``inf`` for coordinates they do not depend on, a root joint's among them:
    the levers add a joint's extent only to the joints above it)."""
    lower = np.full(model.nq, -np.inf)
    upper = np.full(model.nq, np.inf)
    kinds = [model.joints[j].shortname() for j in range(model.njoints)]
    extent = np.zeros(model.njoints)
    follows = {model.getJointId(m.joint): m for m in mimics}
    for j in range(1, model.njoints):
        relation = follows.get(j)
        leader = model.getJointId(relation.mimicked) if relation is not None else j
        kind = kinds[leader]
        kinds[j] = kind
        if kind.startswith(_TURNS):
            continue
        if kind.startswith(("JointModelP", "JointModelTranslation", "JointModelFreeFlyer")):
            count = 2 if "Planar" in kind else (1 if kind.startswith("JointModelP") else 3)
        else:
            extent[j] = np.inf  # helical, composite, ...: not bounded here
            continue
        start = model.idx_qs[leader]
        lo = np.array(model.lowerPositionLimit[start:start + count], dtype=float)
        hi = np.array(model.upperPositionLimit[start:start + count], dtype=float)
        if relation is not None:  # q[j] = multiplier q[leader] + offset
            ends = relation.multiplier * np.array([lo, hi]) + relation.offset
            far = np.abs(ends).max(axis=0)
        else:
            far = np.maximum(np.abs(lo), np.abs(hi))
        finite = bool(np.all(np.isfinite(far)) and np.all(far < 1e10))
        extent[j] = float(np.linalg.norm(far)) if finite else np.inf
        if finite and model.parents[j] > 0:  # (a root joint's extent moves no joint's origin:
            # a free-flying base outside its position box keeps the bounds)
            lower[start:start + count], upper[start:start + count] = lo, hi
    return kinds, extent, lower, upper


def _check_pose(pose, name: str) -> None:
    """TypeError unless ``pose`` is a ``pin.SE3``, ValueError unless it is finite and rigid
    (its rotation orthonormal, of determinant 1, to 1e-6). (Plain floats: a move a step.)"""
    if not isinstance(pose, pin.SE3):
        raise TypeError(f"{name} must be a pin.SE3, got {type(pose).__name__}")
    H = pose.homogeneous
    (a, b, c, _), (d, e, f, _), (g, h, i, _), _ = H.tolist()
    if not math.isfinite(sum(H.ravel().tolist())):
        raise ValueError(f"{name} is not finite:\n{H}")
    columns = ((a, d, g), (b, e, h), (c, f, i))
    gram = [x[0] * y[0] + x[1] * y[1] + x[2] * y[2] for x in columns for y in columns]
    determinant = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if max(abs(v - (k % 4 == 0)) for k, v in enumerate(gram)) > 1e-6 or determinant <= 0.0:
        raise ValueError(f"{name} is not a rigid motion (its rotation is not orthonormal with "
                         f"determinant 1):\n{H[:3, :3]}")


def _check_extent(shape, name: str) -> None:
    """CollisionError unless ``shape`` has a finite extent above zero (a Halfspace or a
    Plane, unbounded, passes)."""
    if isinstance(shape, (coal.Halfspace, coal.Plane)):
        return
    shape.computeLocalAABB()
    box = shape.aabb_local
    lo, hi = np.array(box.min_), np.array(box.max_)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
            and float(np.max(hi - lo)) > 0.0):
        raise CollisionError(f"{name}: a {type(shape).__name__} of zero or non-finite size "
                             f"(its box runs from {lo} to {hi})")


def _twist(velocity, name: str) -> np.ndarray:
    """An obstacle's twist (6,), linear (m/s) then angular (rad/s), from ``velocity``: None
    (at rest), a ``pin.Motion`` or 6 numbers; ``name`` names it in the errors."""
    if velocity is None:
        return np.zeros(6)
    if isinstance(velocity, np.ndarray) and velocity.shape == (6,) and velocity.dtype == float:
        if not math.isfinite(sum(velocity.tolist())):
            raise ValueError(f"{name} is not finite: {velocity}")
        return velocity.copy()
    if isinstance(velocity, pin.Motion):
        return np.concatenate([velocity.linear, velocity.angular])
    try:
        twist = np.array(velocity, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be 6 numbers (linear m/s, angular rad/s) or a "
                        f"pin.Motion, got {type(velocity).__name__}") from None
    if twist.shape != (6,):
        raise ValueError(f"{name} must hold 6 numbers (linear m/s, angular rad/s), got "
                         f"{twist.size}")
    if not np.all(np.isfinite(twist)):
        raise ValueError(f"{name} is not finite: {twist}")
    return twist


def _mimic_map(model: pin.Model, mimic_joints) -> np.ndarray | None:
    """The (nvExtended, nv) matrix from the velocity of every joint coordinate, mimic joints'
    included, to the model's velocity coordinates (a mimic joint's column adds, times its
    multiplier, to the one it follows); ``None`` without mimic joints."""
    if model.nvExtended == model.nv:
        return None
    G = np.zeros((model.nvExtended, model.nv))
    for j in range(1, model.njoints):
        for k in range(model.nvs[j]):
            G[model.idx_vExtendeds[j] + k, model.idx_vs[j] + k] = 1.0
    for mimic in mimic_joints:
        follower, leader = model.getJointId(mimic.joint), model.getJointId(mimic.mimicked)
        G[model.idx_vExtendeds[follower], model.idx_vs[leader]] = mimic.multiplier
    return G
