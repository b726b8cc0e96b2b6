"""A mesh obstacle's convex parts (``sjt.convex_parts``, CoACD): convex, together covering the
mesh, its concavities left open, and beside a CollisionLimit within the acceleration and jerk
limits where the mesh itself (``convex=False``) breaks them and its hull (``convex=True``)
blocks the way."""

from __future__ import annotations

import pickle
import sys

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull

import sjt_pin as sjt
from sjt_pin.bench import collision_mesh as bench
from sjt_pin.limits import CollisionLimit
from sjt_pin.limits.collision_geometry import coal_mesh

MARGIN = 0.01
ACCELERATION, JERK = 10.0, 5000.0  # rad/s^2, rad/s^3


@pytest.fixture(scope="module")
def ring():
    """The benchmark's ring (a torus lying flat, 0.46 m across, a 0.34 m hole): its vertices,
    faces, mesh and parts."""
    vertices, faces = bench.ring_grid()
    return vertices, faces, coal_mesh(vertices, faces), sjt.convex_parts((vertices, faces))


def _outside(points: np.ndarray, part) -> np.ndarray:
    """Signed distance (m) of each point beyond the part's faces (<= 0: inside), from the
    part's points through scipy's qhull (not coal's)."""
    planes = ConvexHull(np.asarray(part.points(), dtype=float)).equations
    return (points @ planes[:, :3].T + planes[:, 3]).max(axis=1)


def test_the_parts_are_convex_cover_the_mesh_and_leave_its_hole_open(ring):
    vertices, faces, mesh, parts = ring
    assert 2 <= len(parts) <= 40
    assert all(isinstance(p, coal.Convex) for p in parts)
    beyond = np.min([_outside(vertices, p) for p in parts], axis=0)
    assert beyond.max() < 1e-4  # every vertex of the mesh inside some part (to 0.1 mm)
    # the hole stays open: its centre is far outside every part (the hull covers it)
    centre = np.zeros((1, 3))
    assert min(float(_outside(centre, p)[0]) for p in parts) > 0.1
    assert float(_outside(centre, _hull_of(vertices))[0]) < 0.0
    # the same seed, the same parts; a coal mesh gives what its vertices and faces give
    again = sjt.convex_parts(mesh)
    assert len(again) == len(parts)
    for a, b in zip(parts, again, strict=True):
        np.testing.assert_array_equal(np.asarray(a.points()), np.asarray(b.points()))


def _hull_of(vertices):
    mesh = coal_mesh(vertices)
    mesh.buildConvexHull(True, "Qt")
    return mesh.convex


def _through_the_ring(panda, obstacles):
    """Panda's hand sent 33 cm down, through a ring 18 cm below it, with acceleration and jerk
    limits: the configurations of 4 s at 1 kHz and the solver."""
    q0 = panda.q0.copy()
    start = panda.fk(q0).translation
    pose = pin.SE3(np.eye(3), start - np.array([0.0, 0.0, 0.18]))
    limit = CollisionLimit(panda, [(shape, pose) for shape in obstacles], margin=MARGIN)
    solver = sjt.make_solver("sjt", panda, dt=1e-3, task=sjt.PositionTask(), limits=[limit],
                             acceleration_limits=ACCELERATION, jerk_limits=JERK)
    goal = start - np.array([0.0, 0.0, 0.33])
    q, qs = q0, [q0]
    for _ in range(4000):
        q = solver.step(q, goal)
        qs.append(q)
    return np.array(qs), solver, pose


def test_the_arm_reaches_through_the_parts_within_its_limits(panda, ring):
    vertices, faces, mesh, parts = ring
    qs, solver, pose = _through_the_ring(panda, parts)
    assert solver.error_norm < 1e-6  # through the hole, on its target
    # the margin from the mesh itself at every step (the robot's hulls contain its meshes:
    # measured against them, the distance is never larger)
    check = CollisionLimit(panda, [(mesh, pose)], margin=MARGIN, convex="robot")
    closest = min(min(p.distance for p in check.distances(q)) for q in qs)
    assert closest >= MARGIN - 1e-3
    # every finite-difference acceleration and jerk within 1 % of its limit
    dt = 1e-3
    v = np.diff(qs, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    j = np.diff(a, axis=0) / dt
    assert np.abs(a).max() <= 1.01 * ACCELERATION
    assert np.abs(j).max() <= 1.01 * JERK
    # the hull fills the hole in: the benchmark's run stops on it
    blocked = bench.through_ring("hull", panda)
    assert blocked.final_error > 0.1 and blocked.closest >= MARGIN - 1e-3
    # ... within every limit where the hand meets the lid, with six joints at their
    # acceleration limits (a finger's row and its witnesses each asked the whole of what the
    # joints' boxes gave: 1.012x the acceleration limit, 1.024x the jerk limit)
    assert blocked.acceleration_ratio <= 1.0 + 1e-6 and blocked.jerk_ratio <= 1.0 + 1e-6
    assert blocked.conflicts == 0


def test_a_limit_with_parts_copies_and_pickles(panda, ring):
    parts = ring[3]
    pose = pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.2]))
    limit = CollisionLimit(panda, [(p, pose) for p in parts], margin=MARGIN)
    copy = pickle.loads(pickle.dumps(limit))
    q = panda.q0.copy()
    assert [d.distance for d in copy.distances(q)] == [d.distance for d in limit.distances(q)]


def test_a_hull_without_its_triangles_is_refused_a_copy_by_name(panda, ring):
    """coal cannot pickle a bare ConvexBase (a hull built without its triangles): copying a
    solver whose limit holds one says which obstacle and how to build it instead of boost's
    "Pickling ... is not enabled"."""
    mesh = coal_mesh(ring[0])
    mesh.buildConvexHull(False, "Qt")
    pose = pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.2]))
    limit = CollisionLimit(panda, [(ring[3][0], pose), (mesh.convex, pose)], margin=MARGIN)
    solver = sjt.make_solver("sjt", panda, limits=[limit])
    with pytest.raises(TypeError, match="obstacle 1 is a coal.ConvexBase without its triangles"):
        pickle.dumps(solver)


def test_bad_meshes_and_options_are_refused(ring):
    vertices, faces, mesh, parts = ring
    with pytest.raises(ValueError, match="threshold"):
        sjt.convex_parts(mesh, threshold=0.0)
    with pytest.raises(ValueError, match="max_parts"):
        sjt.convex_parts(mesh, max_parts=0)
    with pytest.raises(ValueError, match="seed"):
        sjt.convex_parts(mesh, seed=-1)
    with pytest.raises(ValueError, match="faces index"):
        sjt.convex_parts((vertices, faces + len(vertices)))
    with pytest.raises(ValueError, match="finite"):
        sjt.convex_parts((np.where(vertices > 0.1, np.nan, vertices), faces))
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        sjt.convex_parts((vertices[:, :2], faces))
    with pytest.raises(TypeError, match="convex already"):
        sjt.convex_parts(parts[0])
    with pytest.raises(TypeError, match="BVHModel"):
        sjt.convex_parts(coal.Sphere(0.1))


def test_without_coacd_the_error_says_how_to_install_it(ring, monkeypatch):
    """CoACD is an optional extra: without it, convex_parts says which one."""
    monkeypatch.setitem(sys.modules, "coacd", None)
    with pytest.raises(ImportError, match=r"pip install 'sjt-pin\[mesh\]'"):
        sjt.convex_parts(ring[2])
