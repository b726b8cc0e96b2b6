"""Obstacles and closest-point segments in the viewer.

An obstacle is a coal shape at a pose, as :class:`~sjt_pin.CollisionLimit` takes it: primitives
(sphere, box, capsule, cylinder, cone, ellipsoid) are tessellated as the robots' primitive
visuals are (:mod:`.meshes`), a convex shape is drawn as the hull of its points and a mesh
(``BVHModel``) as its triangles. A closest-point segment joins the two closest points of a pair
of geometries that a limit checks: a thin cylinder from one point to the other, keyed per frame
in an animation (position, rotation, length along its axis, and visibility when the pair is
farther than the limit's ``influence``).
"""

from __future__ import annotations

from collections.abc import Sequence

import coal
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin

from .meshes import visual_parts
from .style import to_int

#: Default colour (0xRRGGBB) and opacity of obstacles, and colour of closest-point segments.
OBSTACLE_COLOR = 0xC8553D
OBSTACLE_OPACITY = 0.55
SEGMENT_COLOR = 0xD81B60
#: Radius (m) of a drawn segment.
SEGMENT_RADIUS = 0.0035


def obstacle_mesh(shape) -> tuple[np.ndarray, np.ndarray]:
    """``shape`` (a coal shape) as triangles in its own frame: vertices (N, 3) float32 in m,
    faces (M, 3) uint32. Raises ``ValueError`` (naming ``shape``) for a shape it cannot draw
    (a half-space or a plane: they are infinite)."""
    if isinstance(shape, coal.ConvexBase):
        from scipy.spatial import ConvexHull

        points = np.asarray(shape.points(), dtype=float)
        hull = ConvexHull(points)
        return points.astype(np.float32), hull.simplices.astype(np.uint32)
    if isinstance(shape, coal.BVHModelBase):
        vertices = np.asarray(shape.vertices(), dtype=np.float32)
        faces = np.array([[t[0], t[1], t[2]] for t in
                          (shape.tri_indices(i) for i in range(shape.num_tris))], dtype=np.uint32)
        if faces.size == 0:
            raise ValueError("shape: a mesh without triangles cannot be drawn")
        return vertices, faces
    if isinstance(shape, coal.ShapeBase):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # visual_parts warns; here it is an error
            parts = visual_parts(pin.GeometryObject("obstacle", 0, 0, pin.SE3.Identity(), shape))
        if parts:
            return parts[0].vertices, parts[0].faces
    raise ValueError(f"shape: cannot draw a {type(shape).__name__}; obstacles are drawn for coal "
                     "Sphere, Box, Capsule, Cylinder, Cone, Ellipsoid, Convex and BVHModel")


def draw_obstacle(node, shape, pose, color=OBSTACLE_COLOR,
                  opacity: float = OBSTACLE_OPACITY) -> None:
    """Set meshcat ``node`` to ``shape`` at ``pose`` (``pin.SE3`` or 4x4, in the node's
    parent frame)."""
    T = pose.homogeneous if isinstance(pose, pin.SE3) else np.asarray(pose, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError("pose must be a pin.SE3 or a finite 4x4 matrix")
    if not 0.0 < opacity <= 1.0:
        raise ValueError(f"opacity must be in (0, 1], got {opacity!r}")
    vertices, faces = obstacle_mesh(shape)
    node.set_object(mg.TriangularMeshGeometry(vertices, faces),
                    mg.MeshPhongMaterial(color=to_int(color), opacity=float(opacity),
                                         transparent=opacity < 1.0, shininess=20.0))
    node.set_transform(T)


def segment_object(node, color=SEGMENT_COLOR) -> None:
    """Set ``node`` to a unit-length segment (a cylinder along its y axis, centred)."""
    node.set_object(mg.Cylinder(1.0, SEGMENT_RADIUS),
                    mg.MeshLambertMaterial(color=to_int(color)))


def segment_pose(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """The rigid transform (4x4) that puts a unit segment's axis (y) on the segment from ``a``
    to ``b``, centred between them, and its length (m; scale the y axis by it)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    direction = b - a
    length = float(np.linalg.norm(direction))
    T = np.eye(4)
    T[:3, 3] = (a + b) / 2
    if length > 1e-12:
        y = direction / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
        x = np.cross(y, helper)
        x /= np.linalg.norm(x)
        T[:3, :3] = np.column_stack((x, y, np.cross(x, y)))
    return T, length


def segments(limit, q: np.ndarray, count: int) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """The closest-point segments ``(a, b)`` (world, m) of ``limit``'s ``count`` closest pairs
    at ``q`` that are within its ``influence``, closest first; ``None`` for the rest."""
    found: list[tuple[np.ndarray, np.ndarray] | None] = [
        (s.a, s.b) for s in limit.closest_points(q)[:count]]
    return found + [None] * (count - len(found))


def show_segments(meshcat, prefix: str, limit, q, count: int) -> None:
    """Draw ``limit``'s closest-point segments at ``q`` under ``prefix/0`` ... (static)."""
    for k, segment in enumerate(segments(limit, q, count)):
        node = meshcat[f"{prefix}/{k}"]
        segment_object(node)
        if segment is None:
            node.set_property("visible", False)
            continue
        T, length = segment_pose(*segment)
        T[:3, 1] *= max(length, 1e-6)  # the node's matrix carries the length as a scale
        node.set_transform(T)
        node.set_property("visible", True)


def key_segments(animation, meshcat, prefix: str, limit, configurations: Sequence[np.ndarray],
                 first: int, count: int) -> list[float]:
    """Key ``limit``'s closest-point segments for each of ``configurations`` (one per frame,
    from frame ``first``) into ``animation``; returns the least distance (m, signed) of the
    checked pairs at each configuration."""
    for k in range(count):
        segment_object(meshcat[f"{prefix}/{k}"])
    closest = []
    for i, q in enumerate(configurations):
        found = limit.closest_points(q)
        everything = found or limit.distances(q)
        closest.append(float(everything[0].distance) if everything else float("nan"))
        with animation.at_frame(meshcat, first + i) as frame:
            for k in range(count):
                node = frame[f"{prefix}/{k}"]
                if k < len(found):
                    T, length = segment_pose(found[k].a, found[k].b)
                    node.set_transform(T)
                    node.set_property("scale", "vector3", [1.0, max(length, 1e-6), 1.0])
                node.set_property("visible", "boolean", k < len(found))
    return closest
