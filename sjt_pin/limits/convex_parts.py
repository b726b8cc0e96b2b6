"""A mesh obstacle's convex parts, for a :class:`~sjt_pin.limits.collision.CollisionLimit` that
must let the arm reach into a concave obstacle (a bin, a ring, a shelf) within its acceleration
and jerk limits.

A mesh kept as given (``convex=False``) has closest points that jump from one triangle to
another as the arm moves, and a damper row that jumps asks a change of speed no limit can give
(231–1,994 times the acceleration limit beside a torus); its hull (``convex=True``, the
default) moves its closest points continuously but fills the concavity in. The convex parts of
an approximate convex decomposition are both: each is convex, so its closest points move
continuously, and together they leave the concavities open. The decomposition is CoACD's
(Wei, Liu, Lin, Sun, Wang and Peng, "Approximate convex decomposition for 3D meshes with
collision-aware concavity and tree search", ACM Trans. Graph. 41(4), 2022; PyPI ``coacd``,
``pip install 'sjt-pin[mesh]'``): the mesh is cut by planes until each piece's concavity is
below ``threshold``, and each part is the convex hull of a piece. The pieces cover the mesh, so
the parts contain it (to the decomposition's rounding: 0.01 mm on a 30 cm torus and a 22 cm
bunny), and the margin a limit keeps from the parts it keeps from the mesh.
"""

from __future__ import annotations

import numbers

import numpy as np

from .collision_geometry import CollisionError, coal, coal_mesh, mesh_hull

__all__ = ["convex_parts"]


def _vertices_faces(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64, faces (m, 3) int64) of a coal mesh or a (vertices, faces)
    pair, checked."""
    if isinstance(mesh, coal.ConvexBase):
        raise TypeError("convex_parts takes a mesh (a coal BVHModel or (vertices, faces)); "
                        "this shape is convex already: give it as an obstacle itself")
    if isinstance(mesh, coal.BVHModelBase):
        vertices = np.array(mesh.vertices(), dtype=float).reshape(-1, 3)
        faces = np.array([[t[0], t[1], t[2]] for t in
                          (mesh.tri_indices(i) for i in range(mesh.num_tris))],
                         dtype=np.int64).reshape(-1, 3)
    else:
        try:
            vertices, faces = mesh
            vertices = np.array(vertices, dtype=float)
            faces = np.array(faces)
        except (TypeError, ValueError):
            raise TypeError("convex_parts takes a coal BVHModel or a (vertices, faces) pair, "
                            f"got {type(mesh).__name__}") from None
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (n, 3), got {vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
            raise ValueError(f"faces must be integer vertex indices of shape (m, 3), got "
                             f"{faces.dtype} {faces.shape}")
        faces = faces.astype(np.int64)
    if len(vertices) < 4 or len(faces) < 4:
        raise ValueError(f"a mesh needs at least 4 vertices and 4 faces to enclose a volume, "
                         f"got {len(vertices)} and {len(faces)}")
    if not np.all(np.isfinite(vertices)):
        raise ValueError("the mesh's vertices are not all finite")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"faces index vertices 0..{len(vertices) - 1}, got "
                         f"{faces.min()}..{faces.max()}")
    return vertices, faces


def convex_parts(mesh, threshold: float = 0.05, max_parts: int | None = None,
                 seed: int = 0) -> list:
    """The convex parts of ``mesh`` (module docstring), each a ``coal.Convex`` to give a
    :class:`~sjt_pin.limits.collision.CollisionLimit` as an obstacle of its own, at the mesh's
    pose::

        parts = sjt.convex_parts(bin_mesh)
        limit = sjt.CollisionLimit(robot, [(part, bin_pose) for part in parts])
        # a moving mesh: move every part, limit.move(i, pose, velocity) for i in range(len(parts))

    Args:
        mesh: a coal mesh (``BVHModel``) or a ``(vertices, faces)`` pair (m; vertices (n, 3),
            faces (m, 3) vertex indices), closed: a watertight surface around a volume (CoACD
            remeshes an open one first, on a 50-voxel grid, and its parts then follow that
            grid, not the mesh).
        threshold: the largest concavity a part may keep, in (0, 1], relative to the mesh's
            size: smaller gives more parts, closer to the mesh (CoACD's default 0.05: 12 parts
            for a torus, 42 for the Stanford bunny; 0.1: 8 and 17).
        max_parts: at most this many parts (CoACD merges the closest ones); None: no cap.
        seed: CoACD's random seed: the same seed gives the same parts.

    Returns:
        The parts, ``coal.Convex`` in the mesh's own frame. Decomposing takes about a second
        per 10 parts: do it once, when the cell is set up.
    """
    if coal is None:  # pragma: no cover - the pin wheel ships coal
        raise CollisionError("convex_parts needs coal (shipped with the pin wheel)")
    if isinstance(threshold, bool) or not isinstance(threshold, numbers.Real) or not (
            0.0 < threshold <= 1.0):
        raise ValueError(f"threshold must be a number in (0, 1], got {threshold!r}")
    if max_parts is not None and (isinstance(max_parts, bool)
                                  or not isinstance(max_parts, numbers.Integral)
                                  or max_parts < 1):
        raise ValueError(f"max_parts must be a positive int or None, got {max_parts!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    vertices, faces = _vertices_faces(mesh)
    try:
        import coacd
    except ImportError:
        raise ImportError("convex_parts needs CoACD: pip install 'sjt-pin[mesh]' "
                          "(or pip install coacd)") from None
    coacd.set_log_level("error")
    pieces = coacd.run_coacd(coacd.Mesh(vertices, faces), threshold=float(threshold),
                             max_convex_hull=-1 if max_parts is None else int(max_parts),
                             seed=int(seed))
    # (each with its triangles: a coal.Convex pickles, as a solver's copies need)
    return [mesh_hull(coal_mesh(np.asarray(piece_vertices, dtype=float)), f"convex part {k}",
                  triangles=True) for k, (piece_vertices, _) in enumerate(pieces)]
