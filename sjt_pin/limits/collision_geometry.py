"""The collision limit's geometry: loading the robot's collision model (its URDF, its SRDF),
convex hulls of meshes, the checks of an obstacle's shape, pose and velocity, and the types
:class:`sjt_pin.limits.collision.CollisionLimit` reports distances in."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

try:
    import coal
except ImportError:  # pragma: no cover - the pin wheel ships coal
    coal = None

from ..exceptions import SJTError

#: the precision (m) of coal's GJK and EPA on convex shapes (its default is 1e-6)
GJK_TOLERANCE = 1e-9
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


def srdf_of(robot) -> str | None:
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


def collision_model_of(robot) -> pin.GeometryModel:
    """A copy of ``robot``'s collision geometry: its ``collision_model``, else the
    ``<collision>`` elements of its URDF (a robot loaded with :meth:`Robot.from_urdf`)."""
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


def to_hulls(geom: pin.GeometryModel) -> None:
    """Replace every mesh of ``geom`` by its convex hull (in place; the meshes themselves,
    possibly shared with the robot's model, are not changed)."""
    for g in geom.geometryObjects:
        shape = g.geometry
        if isinstance(shape, coal.BVHModelBase) and not isinstance(shape, coal.ConvexBase):
            g.geometry = mesh_hull(shape, g.name)


_coal_settled = False


def settle_coal() -> None:
    """One distance query of a box against a convex hull, on fixed shapes, once per process.
    coal's first such query in a process leaves some state of its own behind: the same
    queries then answer differently in their last bits than before it (a box, cylinder or
    ellipsoid obstacle beside UR5's hulls; a sphere's are not affected). Made before a limit's
    own queries, a run's distances no longer depend on what the process queried before, and a
    copy of a limit loaded in another process steps as its original, bitwise."""
    global _coal_settled
    if _coal_settled:
        return
    corners = np.array([[x, y, z] for x in (0.0, 0.1) for y in (0.0, 0.1) for z in (0.0, 0.1)])
    hull = mesh_hull(coal_mesh(corners), "settle_coal")
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    coal.distance(hull, coal.Transform3s(), coal.Box(0.1, 0.1, 0.1),
                  coal.Transform3s(np.eye(3), np.array([0.0, 0.0, -0.5])), request, result)
    _coal_settled = True


def coal_mesh(vertices: np.ndarray, triangles: np.ndarray | None = None):
    """A coal mesh (``BVHModelOBBRSS``) of ``vertices`` (n, 3; m) and ``triangles`` (k, 3;
    vertex indices), or of the points alone (None: for their hull)."""
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(0 if triangles is None else len(triangles), len(vertices))
    mesh.addVertices(np.ascontiguousarray(vertices, dtype=float))
    if triangles is not None:
        mesh.addTriangles(np.ascontiguousarray(triangles, dtype=np.int64))
    mesh.endModel()
    return mesh


def mesh_hull(mesh, name: str, triangles: bool = False):
    """The convex hull of ``mesh`` (qhull through coal): triangulated ("Qt"), or, where qhull
    refuses that (Centauro's pelvis), of its points joggled ("QJ": qhull's default joggle, a
    relative 1e-11 or so of the mesh's size, far below any margin). ``triangles``: keep the
    hull's triangles (a ``coal.Convex``, which pickles; else a ``ConvexBase``). Points that
    span no volume (flat, or on a line) are refused: coal's hull of them crashes the process."""
    points = np.asarray(mesh.vertices(), dtype=float).reshape(-1, 3)
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False) if len(points) \
        else np.zeros(1)
    advice = "" if triangles else "; pass convex=False to use the mesh itself"
    if len(points) < 4 or not spread[-1] > 1e-9 * spread[0]:
        raise CollisionError(f"collision mesh {name!r}: its points span no volume (flat or on "
                             f"a line), so it has no convex hull{advice}")
    error = None
    for options in ("Qt", "QJ"):
        copy = mesh.clone()
        try:
            copy.buildConvexHull(triangles, options)
            return copy.convex
        except Exception as exc:  # noqa: BLE001 - qhull's errors are plain exceptions
            error = exc
    raise CollisionError(f"collision mesh {name!r}: no convex hull ({error}){advice}") \
        from error


def check_pose(pose, name: str) -> None:
    """TypeError unless ``pose`` is a ``pin.SE3``, ValueError unless it is finite and rigid
    (its rotation orthonormal, of determinant 1, to 1e-6). (Plain floats: a move a step.)"""
    if not isinstance(pose, pin.SE3):
        raise TypeError(f"{name} must be a pin.SE3, got {type(pose).__name__}")
    R = pose.rotation
    (a, b, c), (d, e, f), (g, h, i) = rows = R.tolist()
    x, y, z = pose.translation.tolist()
    if not math.isfinite(a + b + c + d + e + f + g + h + i + x + y + z):
        raise ValueError(f"{name} is not finite:\n{pose.homogeneous}")
    # (columns of unit length and at right angles, in plain floats: a pose is checked per move)
    defect = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0),
                 abs(c * c + f * f + i * i - 1.0), abs(a * b + d * e + g * h),
                 abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))
    determinant = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if defect > 1e-6 or determinant <= 0.0:
        raise ValueError(f"{name} is not a rigid motion (its rotation is not orthonormal with "
                         f"determinant 1):\n{np.array(rows)}")


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


def obstacle_twist(velocity, name: str) -> np.ndarray:
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
