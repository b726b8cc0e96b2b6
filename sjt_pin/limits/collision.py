"""Collision avoidance: world obstacles and self-collision as velocity-damper rows.

For every pair of geometries closer than ``influence``, one row on the relative normal velocity
of their closest points (the velocity damper of Faverjon and Tournassoud, "A local based
approach for path planning of manipulators with a high number of degrees of freedom", ICRA
1987; Kanoun, Lamiraux and Wieber, IEEE T-RO 27(4), 2011): the distance ``d`` may shrink at a
rate proportional to its excess over ``margin``,

    d_dot = n^T (J_a(p_a) - J_b(p_b)) q_dot >= -gain (d - margin) / dt,

with ``p_a``, ``p_b`` the closest points, ``n`` the unit vector from ``p_b`` to ``p_a`` and
``J_x(p)`` the world-aligned linear Jacobian of point ``p`` on geometry x's joint (zero for an
obstacle). With ``0 < gain <= 1`` a step never takes ``d`` below ``margin`` to first order.

The robot's geometry is its URDF's collision geometry (Pinocchio's ``GeometryModel``; coal, the
successor of hpp-fcl, computes the distances). Obstacles join it as geometries of the world.
A broad phase keeps the exact distance for the pairs whose bounding spheres come within
``influence``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence

import numpy as np
import pinocchio as pin

from .base import Limit, Motion

try:  # coal ships with the pin wheel (hpp-fcl before it)
    import coal
except ImportError:  # pragma: no cover - older Pinocchio builds
    import hppfcl as coal  # type: ignore[no-redef]

#: the obstacle shapes accepted (coal's)
SHAPES = tuple(getattr(coal, name) for name in
               ("Sphere", "Box", "Capsule", "Cylinder", "Cone", "Convex", "ConvexBase",
                "BVHModelOBBRSS", "BVHModelBase", "Halfspace", "Plane", "Ellipsoid")
               if hasattr(coal, name))


class CollisionLimit(Limit):
    """Keep the robot ``margin`` away from ``obstacles`` (and from itself).

    Args:
        robot: the :class:`~sjt_pin.Robot`; its collision geometry comes from its URDF.
        obstacles: ``(coal shape, pin.SE3)`` pairs in world axes (``coal.Sphere(r)``,
            ``coal.Box(x, y, z)``, ``coal.Capsule(r, h)``, ``coal.Cylinder(r, h)``, convex
            meshes and meshes); :meth:`move` moves one between steps.
        self_collision: also keep the robot's links apart: every pair of links except
            adjacent ones (a joint between them) and those the SRDF disables.
        margin: the closest any two geometries may come (m).
        influence: pairs farther than this (m) contribute no row.
        gain: the damper's gain in (0, 1]: the share of the excess over ``margin`` that one
            period may close.
        srdf: the SRDF whose ``disable_collisions`` pairs are skipped (default: the robot's
            own for an example-robot-data robot; ``None`` elsewhere).
        ignore: further ``(geometry or link name, geometry or link name)`` pairs to skip.
    """

    name = "collision"

    def __init__(self, robot, obstacles: Sequence[tuple] = (), self_collision: bool = False,
                 margin: float = 0.01, influence: float = 0.05, gain: float = 0.5,
                 srdf: str | None = "auto", ignore: Iterable[tuple[str, str]] = ()):
        if not 0.0 <= margin < influence:
            raise ValueError(f"need 0 <= margin < influence (m), got margin={margin!r}, "
                             f"influence={influence!r}")
        if not 0.0 < gain <= 1.0:
            raise ValueError(f"gain must be in (0, 1], got {gain!r}")
        self.robot = robot
        self.model = robot.model
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.geometry = _collision_model(robot)
        self.geometry.removeAllCollisionPairs()  # ours only (a loader may have added them all)
        self.robot_geometries = self.geometry.ngeoms
        if self.robot_geometries == 0 and self_collision:
            raise ValueError(f"{robot.name}: its URDF has no <collision> geometry")
        self.obstacles: list[int] = []
        for k, item in enumerate(obstacles):
            self._add_obstacle(k, item)
        pairs = [(i, o) for o in self.obstacles for i in range(self.robot_geometries)]
        if self_collision:
            pairs += self._self_pairs(srdf, ignore)
        skip = {frozenset(p) for p in ignore}
        names = [g.name for g in self.geometry.geometryObjects]
        links = [self.model.frames[g.parentFrame].name for g in self.geometry.geometryObjects]
        pairs = [(a, b) for a, b in pairs
                 if frozenset((names[a], names[b])) not in skip
                 and frozenset((links[a], links[b])) not in skip]
        if not pairs:
            raise ValueError("no geometry pair to keep apart: give obstacles, or "
                             "self_collision=True")
        for a, b in pairs:
            self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = np.array(pairs, dtype=np.int64).reshape(-1, 2)
        self.data = self.geometry.createData()
        self._radius, self._center = _bounding_spheres(self.geometry)
        self._checked = False
        #: the pairs of the last ``rows()``, one per row: (geometry a, geometry b, d (m),
        #: closest point on a, closest point on b; world axes)
        self.active: list[tuple[str, str, float, np.ndarray, np.ndarray]] = []

    # -- setup -------------------------------------------------------------------------------
    def _add_obstacle(self, k: int, item) -> None:
        try:
            shape, pose = item
        except (TypeError, ValueError):
            raise TypeError(f"obstacles[{k}] must be a (coal shape, pin.SE3) pair, "
                            f"got {item!r}") from None
        if not isinstance(shape, SHAPES):
            raise TypeError(f"obstacles[{k}]: {type(shape).__name__} is not a coal shape "
                            f"(Sphere, Box, Capsule, Cylinder, Convex, BVHModel, ...)")
        if not isinstance(pose, pin.SE3):
            raise TypeError(f"obstacles[{k}]: the pose must be a pin.SE3, got "
                            f"{type(pose).__name__}")
        obstacle = pin.GeometryObject(f"obstacle_{k}", 0, 0, pose, shape)
        self.obstacles.append(self.geometry.addGeometryObject(obstacle))

    def _self_pairs(self, srdf, ignore) -> list[tuple[int, int]]:
        """Every pair of the robot's geometries on different, non-adjacent joints, less the
        SRDF's disabled pairs."""
        model, objects = self.model, self.geometry.geometryObjects
        candidates = []
        for a in range(self.robot_geometries):
            for b in range(a + 1, self.robot_geometries):
                ja, jb = objects[a].parentJoint, objects[b].parentJoint
                if ja == jb or model.parents[ja] == jb or model.parents[jb] == ja:
                    continue
                candidates.append((a, b))
        if srdf == "auto":
            srdf = _example_srdf(self.robot)
        if srdf is not None:
            probe = self.geometry.copy()
            probe.removeAllCollisionPairs()
            for a, b in candidates:
                probe.addCollisionPair(pin.CollisionPair(a, b))
            pin.removeCollisionPairs(model, probe, str(srdf))
            kept = {(p.first, p.second) for p in probe.collisionPairs}
            candidates = [p for p in candidates if p in kept]
        return candidates

    def move(self, i: int, pose: pin.SE3) -> None:
        """Move obstacle ``i`` to ``pose`` (world axes), for the next step."""
        if not isinstance(pose, pin.SE3):
            raise TypeError(f"pose must be a pin.SE3, got {type(pose).__name__}")
        if not 0 <= i < len(self.obstacles):
            raise IndexError(f"obstacle {i} does not exist (there are {len(self.obstacles)})")
        self.geometry.geometryObjects[self.obstacles[i]].placement = pose

    # -- distances ---------------------------------------------------------------------------
    def _update(self, kinematics) -> None:
        pin.updateGeometryPlacements(self.model, kinematics.data, self.geometry, self.data)

    def _near_pairs(self) -> np.ndarray:
        """Indices (into ``pairs``) whose bounding spheres come within ``influence``: the
        broad phase."""
        oMg = self.data.oMg
        centers = np.array([oMg[g].act(self._center[g]) for g in range(len(oMg))])
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        gap = (np.linalg.norm(centers[a] - centers[b], axis=1) - self._radius[a]
               - self._radius[b])
        return np.flatnonzero(gap < self.influence)

    def _distance(self, k: int) -> coal.DistanceResult:
        return pin.computeDistance(self.geometry, self.data, int(k))

    def distances(self, q) -> list[tuple[str, str, float]]:
        """The distance (m) of every pair at configuration ``q``, closest first:
        ``(geometry a, geometry b, d)``; negative when they overlap."""
        from ..kinematics import Kinematics

        kinematics = Kinematics(self.model)
        kinematics.update(self.robot.check_q(q))
        self._update(kinematics)
        names = [g.name for g in self.geometry.geometryObjects]
        out = [(names[a], names[b], float(self._distance(k).min_distance))
               for k, (a, b) in enumerate(self.pairs)]
        return sorted(out, key=lambda item: item[2])

    # -- the limit ---------------------------------------------------------------------------
    def rows(self, kinematics, motion: Motion):
        self._update(kinematics)
        near = self._near_pairs()
        rows, bounds = [], []
        self.active = []
        objects = self.geometry.geometryObjects
        for k in near:
            result = self._distance(k)
            d = float(result.min_distance)
            if not self._checked and d < self.margin:
                a, b = (int(x) for x in self.pairs[k])
                raise ValueError(f"{objects[a].name} and {objects[b].name} are {d:.4f} m apart "
                                 f"at the start, closer than the margin {self.margin} m "
                                 "(an obstacle overlapping the robot?)")
            if d >= self.influence:
                continue
            a, b = (int(x) for x in self.pairs[k])
            p_a, p_b = np.array(result.getNearestPoint1()), np.array(result.getNearestPoint2())
            normal = p_a - p_b
            length = np.linalg.norm(normal)
            if length > 1e-9 and d > 0:
                normal /= length
            else:  # touching or overlapping: coal's normal (from a to b) reversed
                normal = -np.array(result.normal)
            row = normal @ (self._point_jacobian(kinematics, objects[a].parentJoint, p_a)
                            - self._point_jacobian(kinematics, objects[b].parentJoint, p_b))
            rows.append(-row)
            self.active.append((objects[a].name, objects[b].name, d, p_a, p_b))
            bounds.append(self.gain * (d - self.margin) / motion.dt)
        self._checked = True
        if not rows:
            return None
        return np.array(rows), np.array(bounds)

    def _point_jacobian(self, kinematics, joint: int, point: np.ndarray) -> np.ndarray:
        """The world-aligned linear Jacobian (3, nv) of ``point`` (world) moving with
        ``joint``; zero for the world."""
        if joint == 0:
            return np.zeros((3, self.model.nv))
        J = pin.getJointJacobian(self.model, kinematics.data, joint, pin.LOCAL_WORLD_ALIGNED)
        lever = point - kinematics.data.oMi[joint].translation
        return J[:3] - pin.skew(lever) @ J[3:]

    def __repr__(self) -> str:
        return (f"CollisionLimit({self.robot.name!r}, obstacles={len(self.obstacles)}, "
                f"pairs={len(self.pairs)}, margin={self.margin}, influence={self.influence})")


def _collision_model(robot) -> pin.GeometryModel:
    """A copy of the robot's collision geometry (from its URDF when it was not loaded)."""
    if robot.collision_model is not None:
        return robot.collision_model.copy()
    if robot.urdf is None:
        raise ValueError(f"{robot.name}: no URDF to read the collision geometry from")
    try:
        if os.path.exists(str(robot.urdf)):
            return pin.buildGeomFromUrdf(robot.model, str(robot.urdf), pin.COLLISION,
                                         package_dirs=robot.package_dirs)
        return pin.buildGeomFromUrdfString(robot.model, robot.urdf, pin.COLLISION,
                                           package_dirs=robot.package_dirs)
    except (ValueError, RuntimeError) as exc:
        raise ValueError(f"{robot.name}: cannot load the collision geometry of its URDF "
                         f"(package_dirs={robot.package_dirs}): {exc}") from exc


def _bounding_spheres(geometry: pin.GeometryModel) -> tuple[np.ndarray, list[np.ndarray]]:
    """Per geometry, the radius and centre (in its own frame) of a sphere around its local
    bounding box (infinite for unbounded shapes: halfspaces, planes)."""
    radius, center = np.empty(geometry.ngeoms), []
    for g, obj in enumerate(geometry.geometryObjects):
        shape = obj.geometry
        shape.computeLocalAABB()
        box = shape.aabb_local
        lo, hi = np.array(box.min_), np.array(box.max_)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            radius[g], middle = np.inf, np.zeros(3)
        else:
            middle = 0.5 * (lo + hi)
            radius[g] = 0.5 * float(np.linalg.norm(hi - lo))
        center.append(middle)
    return radius, center


def _example_srdf(robot) -> str | None:
    """The SRDF of an example-robot-data robot, if the robot is one."""
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:  # pragma: no cover
        return None
    loader = ROBOTS.get(robot.name)
    if loader is None or not getattr(loader, "srdf_filename", ""):
        return None
    try:
        path = loader().srdf_path
    except Exception:  # noqa: BLE001 - a loader that cannot load: no SRDF to use
        return None
    return path if path and os.path.exists(path) else None
