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
and below ``margin`` (or in penetration) the row pushes the pair apart.

Distances and closest points come from coal (through Pinocchio's ``GeometryModel``); only the
pairs whose bounding spheres come within ``influence`` pay for an exact distance query.
"""

from __future__ import annotations

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
from .base import Limit, Motion

__all__ = ["ClosestPoints", "CollisionLimit", "CollisionError", "PairDistance"]

#: the precision (m) of coal's GJK and EPA on convex shapes (its default is 1e-6)
GJK_TOLERANCE = 1e-9

_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0


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
            mesh = shape.clone()
            try:
                mesh.buildConvexHull(False, "Qt")
            except Exception as exc:  # noqa: BLE001 - qhull's errors are plain exceptions
                raise CollisionError(f"collision mesh {g.name!r}: no convex hull ({exc}); "
                                     "pass convex=False to use the mesh itself") from exc
            g.geometry = mesh.convex


class CollisionLimit(Limit):
    """Keep the robot ``margin`` away from ``obstacles`` and (``self_collision=True``) from
    itself, as one velocity-damper row per pair closer than ``influence``.

    Args:
        robot: a :class:`sjt_pin.Robot` (its ``collision_model``, else the ``<collision>``
            geometry of ``robot.urdf`` with ``robot.package_dirs``).
        obstacles: ``(coal shape, pin.SE3)`` pairs fixed in the world: ``coal.Sphere``, ``Box``,
            ``Capsule``, ``Cylinder``, ``Convex`` or a mesh (``BVHModel``). Move them with
            :meth:`move`.
        self_collision: also check the robot's link pairs, except adjacent links (geometries on
            the same joint or on a joint and its parent) and the pairs the SRDF disables.
        margin: distance to keep, m.
        influence: pairs farther than this (m) contribute no row.
        gain: the damper's gain in (0, 1]: per period the excess ``d - margin`` may shrink by
            at most this fraction.
        pairs: extra ``(link_a, link_b)`` (or geometry names) to check although the rules above
            skip them (e.g. an adjacent pair).
        ignore: ``(link_a, link_b)`` (or geometry names; ``"world"`` for every obstacle) never
            to check.
        srdf: an SRDF path whose ``disable_collisions`` apply; by default the SRDF of an
            example-robot-data robot.
        convex: replace the robot's collision meshes by their convex hulls (qhull, through
            coal). A hull contains its mesh, so the distance to it never exceeds the mesh's and
            the margin still holds for the mesh; GJK on hulls takes about a microsecond where
            a mesh-to-mesh distance takes from 10 us to several ms (Panda). Obstacles stay as
            given.
    """

    name: str = "collision"

    def __init__(self, robot, obstacles: Sequence = (), self_collision: bool = False,
                 margin: float = 0.01, influence: float = 0.05, gain: float = 0.5,
                 pairs: Iterable[tuple[str, str]] = (), ignore: Iterable[tuple[str, str]] = (),
                 srdf: str | None = None, convex: bool = True):
        if coal is None:  # pragma: no cover
            raise CollisionError("CollisionLimit needs coal (shipped with the pin wheel)")
        if not (np.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be a finite distance >= 0 (m), got {margin!r}")
        if not (np.isfinite(influence) and influence > margin):
            raise ValueError(f"influence must be finite and > margin={margin} (m), "
                             f"got {influence!r}")
        if not (0 < gain <= 1):
            raise ValueError(f"gain must be in (0, 1], got {gain!r}")
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.model: pin.Model = robot.model
        self.geometry = _collision_model(robot)
        if convex:
            _to_hulls(self.geometry)
        self.n_robot = self.geometry.ngeoms
        self._obstacle_ids: list[int] = []
        for i, item in enumerate(obstacles):
            self._add_obstacle(i, item)
        self._choose_pairs(self_collision, list(pairs), list(ignore),
                           srdf if srdf is not None else (_srdf_of(robot) if self_collision
                                                          else None))
        self.geometry_data = self.geometry.createData()
        for req in self.geometry_data.distanceRequests:
            req.enable_signed_distance = True
            req.gjk_tolerance = req.epa_tolerance = GJK_TOLERANCE
        self._data = self.model.createData()
        self._checked = False
        self.active: list[int] = []
        self._prepare_broad_phase()

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
        if not isinstance(pose, pin.SE3):
            raise TypeError(f"obstacle {i}: pose must be a pin.SE3, got {type(pose).__name__}")
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
        self.geometry.removeAllCollisionPairs()
        for a, b in chosen:
            self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = np.array(chosen, dtype=int).reshape(-1, 2)
        self.pair_names = [(geoms[a].name, geoms[b].name) for a, b in chosen]

    def _prepare_broad_phase(self) -> None:
        """Everything a step reads, as arrays: each geometry's bounding sphere (the sphere
        around coal's local AABB) in its parent joint's frame, the pairs as index arrays, and
        which joints' Jacobian columns move a point fixed to each joint."""
        geoms = self.geometry.geometryObjects
        model = self.model
        n = len(geoms)
        self._joint = np.array([g.parentJoint for g in geoms], dtype=np.int64)
        self._box_center = np.zeros((n, 3))  # coal's local AABB, in the geometry's frame
        self._box_half = np.zeros((n, 3))
        self._radius = np.zeros(n)  # the sphere around that box
        self._placement = np.zeros((n, 4, 4))  # geometry in its parent joint's frame
        for i, g in enumerate(geoms):
            g.geometry.computeLocalAABB()
            box = g.geometry.aabb_local
            lo, hi = np.array(box.min_), np.array(box.max_)
            self._box_center[i], self._box_half[i] = (lo + hi) / 2, (hi - lo) / 2
            self._radius[i] = float(np.linalg.norm(hi - lo) / 2)
            self._placement[i] = g.placement.homogeneous
        self._pa, self._pb = self.pairs[:, 0].copy(), self.pairs[:, 1].copy()
        self._ja, self._jb = self._joint[self._pa], self._joint[self._pb]
        self._reach2 = (self._radius[self._pa] + self._radius[self._pb] + self.influence) ** 2
        # sphere centres: in the parent joint's frame (homogeneous) and in the world
        local = self._placement @ np.append(self._box_center, np.ones((n, 1)), axis=1)[:, :, None]
        self._center_local = local[:, :, 0]
        self._moving = np.flatnonzero(self._joint != 0)
        self._joints = [int(j) for j in np.unique(self._joint[self._moving])]
        self._slot = np.searchsorted(self._joints, self._joint)  # joint of g in the stack
        self._slot[self._joint == 0] = len(self._joints)  # the world: an identity at the end
        self._world = np.eye(4)
        # one product of the stacked joint poses and the world's identity (4 nj + 4, 4) with
        # every centre in its joint's frame (4, n) gives every centre in the world; _pick takes
        # geometry g's xyz out of it (flat indices, (n, 3))
        self._centers_in = np.ascontiguousarray(self._center_local.T)
        self._pick = (4 * self._slot[:, None] + np.arange(3)) * n + np.arange(n)[:, None]
        # centre differences of every pair: D @ centres
        D = np.zeros((len(self.pairs), n))
        D[np.arange(len(self.pairs)), self._pa] = 1.0
        D[np.arange(len(self.pairs)), self._pb] -= 1.0
        self._difference = D
        # the sphere-box test pays only where exact distances are dear (meshes)
        self._refine = any(isinstance(g.geometry, coal.BVHModelBase)
                           and not isinstance(g.geometry, coal.ConvexBase) for g in geoms)
        # supports[j]: the velocity coordinates that move joint j's frame (WORLD Jacobian columns)
        self._support = np.zeros((model.njoints, model.nv))
        for j in range(1, model.njoints):
            for i in model.supports[j]:
                if i > 0:
                    joint = model.joints[i]
                    self._support[j, joint.idx_v:joint.idx_v + joint.nv] = 1.0
        self._version = 0  # bumped by move(): a new scene
        self._cache: tuple | None = None

    # -- obstacles ---------------------------------------------------------------------------
    def move(self, i: int, pose: pin.SE3) -> None:
        """Move obstacle ``i`` (its index in ``obstacles``) to ``pose`` before the next step."""
        if not 0 <= i < len(self._obstacle_ids):
            raise IndexError(f"obstacle {i} does not exist ({len(self._obstacle_ids)} obstacles)")
        if not isinstance(pose, pin.SE3):
            raise TypeError(f"pose must be a pin.SE3, got {type(pose).__name__}")
        g = self._obstacle_ids[i]
        obj = self.geometry.geometryObjects[g]
        obj.placement = pose
        self._placement[g] = pose.homogeneous
        self._center_local[g] = self._centers_in[:, g] = (self._placement[g]
                                                          @ np.append(self._box_center[g], 1.0))
        self._version += 1

    @property
    def obstacles(self) -> list[tuple]:
        """The obstacles as ``(coal shape, pin.SE3)`` pairs, at their current poses."""
        geoms = self.geometry.geometryObjects
        return [(geoms[g].geometry, pin.SE3(geoms[g].placement)) for g in self._obstacle_ids]

    # -- queries -----------------------------------------------------------------------------
    def _candidates(self, data) -> np.ndarray:
        """The pairs whose bounding volumes come within ``influence`` (indices into pairs).

        Each geometry has a box in its own frame (coal's local AABB) and the sphere around it.
        First the spheres of both (for every pair), then, where exact distances are dear
        (meshes), for the few pairs left, the sphere of either one against the other's box:
        volumes contain their geometry, so neither test drops a pair within ``influence``."""
        oMi = data.oMi.tolist()
        H = np.concatenate([oMi[j].homogeneous for j in self._joints] + [self._world])
        center = (H @ self._centers_in).take(self._pick)
        diff = self._difference @ center
        near = np.flatnonzero(np.einsum("ij,ij->i", diff, diff) < self._reach2)
        if near.size == 0 or not self._refine:
            return near
        # both directions at once: the sphere of a against b's box, and of b against a's box
        one = np.concatenate((self._pa[near], self._pb[near]))
        other = np.concatenate((self._pb[near], self._pa[near]))
        poses = H.reshape(-1, 4, 4)[self._slot[other]] @ self._placement[other]
        gap = (self._sphere_box(center[one], poses, other) - self._radius[one]).reshape(2, -1)
        return near[np.maximum(gap[0], gap[1]) < self.influence]

    def _sphere_box(self, points, poses, g) -> np.ndarray:
        """Distance of world ``points`` (k, 3) to the local boxes of geometries ``g``."""
        local = np.einsum("kji,kj->ki", poses[:, :3, :3], points - poses[:, :3, 3])
        outside = np.maximum(np.abs(local - self._box_center[g]) - self._box_half[g], 0.0)
        return np.sqrt(np.einsum("ki,ki->k", outside, outside))

    def _distance(self, k: int):
        return pin.computeDistance(self.geometry, self.geometry_data, int(k))

    def check(self, q: np.ndarray) -> None:
        """Raise :class:`CollisionError` if an obstacle overlaps the robot at ``q``."""
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        self._check(self.model, self._data)

    def _check(self, model, data) -> None:
        pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        for k, (a, b) in enumerate(self.pairs):
            if b < self.n_robot and a < self.n_robot:
                continue
            d = self._distance(k).min_distance
            if d <= 0:
                na, nb = self.pair_names[k]
                raise CollisionError(f"{nb if b >= self.n_robot else na} overlaps "
                                     f"{na if b >= self.n_robot else nb} at the start "
                                     f"(distance {d * 1e3:.1f} mm); move the obstacle or the "
                                     "start configuration")
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
        Jacobians); None when no pair is within ``influence``. A second call at the same
        configuration, period and obstacle poses returns the same (read-only) arrays."""
        dt = motion.dt
        if not dt > 0:
            raise ValueError(f"dt must be a period > 0 (s), got {dt!r}")
        model, data, q = kinematics.model, kinematics.data, kinematics.q
        key = (dt, self._version, None if q is None else q.tobytes())
        cache = self._cache
        if cache is not None and q is not None and cache[0] is data and cache[1] == key:
            self.active = list(cache[2])
            return cache[3]
        if not self._checked:
            self._check(model, data)
        out = self._rows(model, data, dt)
        self._cache = (data, key, tuple(self.active), out)
        return out

    def _rows(self, model, data, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        near = self._candidates(data)
        self.active = []  # indices into self.pairs / self.pair_names of the rows returned
        if near.size == 0:
            return None
        pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        geometry, gdata, influence = self.geometry, self.geometry_data, self.influence
        compute = pin.computeDistance
        found, distance, normal, point_a, point_b = [], [], [], [], []
        for k in near.tolist():
            res = compute(geometry, gdata, k)
            d = res.min_distance
            if d >= influence:
                continue
            found.append(k)
            distance.append(d)
            normal.append(res.normal)
            point_a.append(res.getNearestPoint1())
            point_b.append(res.getNearestPoint2())
        if not found:
            return None
        self.active = found
        k = np.array(found)
        # coal's normal points from the first object to the second; the row wants b -> a;
        # the WORLD Jacobian of joint j (its supports' columns) moves a point p fixed to it at
        # v_O + w x p, so n.v(p) = n.v_O + (p x n).w: one product for both ends of every pair
        n = np.array(normal)
        u = np.empty((2 * len(found), 6))
        u[:, :3] = np.concatenate((-n, n))
        p = np.concatenate((point_b, point_a))
        u[:, 3:] = np.einsum("ijk,pj,pk->pi", _LEVI_CIVITA, p, u[:, :3])
        U = u @ data.J
        U *= self._support[np.concatenate((self._jb[k], self._ja[k]))]
        A = U[:len(found)] + U[len(found):]
        b = self.gain / dt * (np.array(distance) - self.margin)
        A.setflags(write=False)
        b.setflags(write=False)
        return A, b
