"""A robot's visual geometry as small plain triangle meshes, the form the viewer draws.

meshcat 0.3.2 loads a Collada file by merging its nodes into one geometry, and a node with
several materials turns into a material list nested inside the list of materials, which three.js
does not draw: those parts vanish. The UR5's joint housings are such parts, so the rest of its
links looked scattered. Here every visual becomes plain triangles instead: the mesh file is read
with trimesh (Collada, STL, OBJ), its parts grouped by colour, decimated toward a face budget
(fast-simplification; it keeps open borders, so a part full of them keeps more faces), cut
apart at sharp edges (three.js then shades them crisply) and scaled by the geometry's
``meshScale``. The scale is baked into the vertices, because an animation carries only
positions and rotations. Primitives (box, cylinder, sphere, capsule, cone,
ellipsoid) are tessellated the same way.

Meshes are read once per (file, scale, budget) per process. The Panda's two fingers share one
file, so they share one mesh.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import coal
import fast_simplification
import numpy as np
import pinocchio as pin
import trimesh

from ..mesh_paths import check_file

#: Faces aimed at per visual geometry: enough for a robot a few hundred pixels tall.
MAX_FACES = 2500
#: Faces a part of one colour keeps at least (if it has them): fewer, and a small part's
#: share of MAX_FACES could leave it centimetres off its shape.
MIN_PART_FACES = 1200
#: Edges sharper than this are drawn sharp (faces on either side get their own vertices).
CREASE_ANGLE = math.radians(35.0)


@dataclass(frozen=True)
class Part:
    """Triangles of one colour in the frame of their geometry.

    ``vertices`` (N, 3) float32 in m, ``faces`` (M, 3) uint32 indices, ``rgba`` in [0, 1].
    """

    vertices: np.ndarray
    faces: np.ndarray
    rgba: tuple[float, float, float, float]


def visual_parts(geometry: pin.GeometryObject, max_faces: int = MAX_FACES,
                 folders: Sequence[Path] | None = None) -> tuple[Part, ...]:
    """The parts of one visual geometry, decimated toward ``max_faces`` faces in all.

    A URDF ``<material>`` (``overrideMaterial``) colours every part; otherwise a mesh file keeps
    its own colours. Returns ``()``, with a warning, for a geometry that cannot be drawn. A mesh
    file is read only if it lies, after resolving ``..`` and symbolic links, inside ``folders``
    (the robot's ``mesh_roots``; None: anywhere), else :class:`~sjt_pin.URDFError`.
    """
    color = tuple(float(c) for c in geometry.meshColor)
    shape = geometry.geometry
    if isinstance(shape, coal.ShapeBase):
        mesh = _primitive(shape)
        if mesh is None:
            warnings.warn(f"cannot draw {geometry.name!r}: {type(shape).__name__} is not "
                          "supported", stacklevel=2)
            return ()
        return (_part(_smooth(mesh), color),)
    if not geometry.meshPath:
        warnings.warn(f"cannot draw {geometry.name!r}: it has no mesh file", stacklevel=2)
        return ()
    scale = tuple(float(s) for s in geometry.meshScale)
    path = check_file(geometry.meshPath, folders, f"geometry {geometry.name!r}: mesh")
    parts = _mesh_file(path, scale, max_faces)
    if geometry.overrideMaterial:
        return tuple(Part(p.vertices, p.faces, color) for p in parts)
    return parts


@functools.lru_cache(maxsize=256)
def _mesh_file(path: str, scale: tuple[float, float, float], max_faces: int) -> tuple[Part, ...]:
    """The mesh file at ``path``, scaled, grouped by colour and decimated (cached)."""
    loaded = trimesh.load(path, force="scene")
    by_color: dict[tuple[int, ...], list[trimesh.Trimesh]] = {}
    for mesh in loaded.dump(concatenate=False):
        if len(mesh.faces):
            by_color.setdefault(_file_color(mesh), []).append(mesh)
    total = sum(len(m.faces) for meshes in by_color.values() for m in meshes)
    parts = []
    for rgba, meshes in by_color.items():
        mesh = trimesh.util.concatenate(meshes)
        mesh.apply_transform(np.diag([*scale, 1.0]))
        mesh.merge_vertices(merge_tex=True, merge_norm=True)  # by position alone
        budget = max(round(max_faces * len(mesh.faces) / total),
                     min(len(mesh.faces), MIN_PART_FACES))
        if len(mesh.faces) > budget:
            vertices, faces = fast_simplification.simplify(
                mesh.vertices, mesh.faces, target_reduction=1.0 - budget / len(mesh.faces))
            mesh = trimesh.Trimesh(vertices, faces)
        parts.append(_part(_smooth(mesh), tuple(c / 255.0 for c in rgba)))
    return tuple(parts)


def _file_color(mesh: trimesh.Trimesh) -> tuple[int, ...]:
    """The main RGBA colour (0-255) of a part read from a mesh file."""
    visual = mesh.visual
    material = getattr(visual, "material", None)
    color = material.main_color if material is not None else visual.main_color
    return tuple(int(c) for c in color)


def _primitive(shape: coal.ShapeBase) -> trimesh.Trimesh | None:
    """A coal primitive (in m, axis along z as in coal) as triangles, or None."""
    if isinstance(shape, coal.Box):
        return trimesh.creation.box(extents=2.0 * np.asarray(shape.halfSide))
    if isinstance(shape, coal.Cylinder):
        return trimesh.creation.cylinder(shape.radius, 2.0 * shape.halfLength, sections=32)
    if isinstance(shape, coal.Sphere):
        return trimesh.creation.icosphere(subdivisions=2, radius=shape.radius)
    if isinstance(shape, coal.Capsule):
        return trimesh.creation.capsule(2.0 * shape.halfLength, shape.radius, count=[16, 16])
    if isinstance(shape, coal.Cone):  # coal's cone is centred on its axis' midpoint
        cone = trimesh.creation.cone(shape.radius, 2.0 * shape.halfLength, sections=32)
        cone.apply_translation([0.0, 0.0, -shape.halfLength])
        return cone
    if isinstance(shape, coal.Ellipsoid):
        sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        sphere.apply_transform(np.diag([*np.asarray(shape.radii), 1.0]))
        return sphere
    return None


def _smooth(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` with its faces cut apart along edges sharper than :data:`CREASE_ANGLE`."""
    return trimesh.graph.smooth_shade(mesh, angle=CREASE_ANGLE, facet_minarea=None)


def _part(mesh: trimesh.Trimesh, rgba) -> Part:
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
    vertices.flags.writeable = faces.flags.writeable = False
    return Part(vertices, faces, tuple(float(c) for c in rgba))
