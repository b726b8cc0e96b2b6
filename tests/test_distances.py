"""The compiled distance queries (sjt_pin.kernels.distance_queries, src/distances.cpp): built,
the same distances and closest points as Pinocchio's computeDistance on every kind of shape,
the same rows as the queries through Python, and clear errors for bad input."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
from sjt_pin.kernels import _distances
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits import CollisionLimit, Motion


def _mesh():
    """A tetrahedron as a coal mesh (BVHModel) and as a convex hull."""
    points = np.array([[0, 0, 0], [0.08, 0, 0], [0, 0.08, 0], [0, 0, 0.08]], dtype=float)
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(4, 4)
    mesh.addVertices(points)
    mesh.addTriangles(np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    mesh.endModel()
    hull = mesh.clone()
    hull.buildConvexHull(False, "Qt")
    return mesh, hull.convex


def _scene():
    """Panda with self-collision beside one obstacle of every kind the limit takes."""
    robot = sjt.Robot.from_example("panda")
    hand = robot.fk(robot.q0).translation
    mesh, hull = _mesh()
    shapes = [coal.Sphere(0.04), coal.Box(0.1, 0.05, 0.08), coal.Capsule(0.03, 0.1),
              coal.Cylinder(0.03, 0.1), hull, mesh]
    offsets = [[0.0, 0.2, 0.0], [0.0, -0.2, 0.0], [0.2, 0.0, 0.05], [0.12, 0.15, 0.15],
               [0.15, -0.12, -0.1], [0.0, 0.0, 0.22]]
    rng = np.random.default_rng(3)
    obstacles = [(shape, pin.SE3(pin.exp3(rng.normal(size=3)), hand + offset))
                 for shape, offset in zip(shapes, offsets, strict=True)]
    obstacles.append((coal.Halfspace(np.array([0.0, 0.0, 1.0]), -0.3), pin.SE3.Identity()))
    return robot, obstacles


def test_the_compiled_queries_are_built():
    # what pyproject.toml's build requirements make: a missing module is a slower limit
    assert kernels.distance_queries is not None, kernels.distance_queries_missing


def _joint_poses(data) -> np.ndarray:
    """Pinocchio's data.oMi as the compiled queries read it: (njoints, 16), row-major."""
    return np.array([M.homogeneous.ravel() for M in data.oMi])


def test_the_compiled_queries_match_pinocchio_on_every_shape():
    robot, obstacles = _scene()
    limit = CollisionLimit(robot, obstacles, self_collision=True)
    geometry, gdata = limit.geometry, limit.geometry_data
    queries = limit._compiled_queries()
    assert queries is not None
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(0)
    worst = checked = 0
    for _ in range(20):
        q = pin.randomConfiguration(model)
        q[:7] = robot.q0[:7] + rng.normal(0, 0.4, 7)
        pin.updateGeometryPlacements(model, data, geometry, gdata, q)
        poses = _joint_poses(data)
        for k in range(len(limit.pairs)):
            expected = pin.computeDistance(geometry, gdata, k)
            d, _, p1, p2 = _distances.distance(queries, k, poses)
            worst = max(worst, abs(d - expected.min_distance),
                        np.abs(np.subtract(p1, expected.getNearestPoint1())).max(),
                        np.abs(np.subtract(p2, expected.getNearestPoint2())).max())
            checked += 1
    assert checked > 1000
    assert worst < 1e-12


def test_a_moved_obstacle_is_queried_where_it_now_lies():
    robot, obstacles = _scene()
    limit = CollisionLimit(robot, obstacles[:1])
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.q0)
    before = _distances.distance(limit._compute, 0, _joint_poses(data))[0]
    shape, pose = obstacles[0]
    limit.move(0, pin.SE3(pose.rotation, pose.translation + [0.0, 0.0, 0.5]))
    after = _distances.distance(limit._compute, 0, _joint_poses(data))[0]
    pin.updateGeometryPlacements(robot.model, data, limit.geometry, limit.geometry_data)
    assert after == pytest.approx(pin.computeDistance(limit.geometry, limit.geometry_data,
                                                      0).min_distance, abs=1e-12)
    assert after > before + 0.1


def _rows_of(limit, robot, qs, python: bool):
    """The limit's rows at each q, through the compiled queries and data views (python False)
    or through Pinocchio's Python bindings alone."""
    if python:
        limit._compute = pin.computeDistance
    kinematics = Kinematics(robot.model)
    motion = Motion(qs[0], np.zeros(robot.nv), np.zeros(robot.nv), 1e-3)
    out = []
    for q in qs:
        kinematics.update(q)
        if python:
            limit._views = (kinematics.data, kinematics.data)
        rows = limit.rows(kinematics, motion)
        out.append(None if rows is None else (rows[0].copy(), rows[1].copy(),
                                               list(limit.active), limit.witness_pairs))
    return out


def test_the_rows_are_those_of_the_queries_through_python():
    # a path that brushes the obstacles: rows, witnesses and the skip as a step meets them
    robot, obstacles = _scene()
    rng = np.random.default_rng(1)
    start = robot.q0.copy()
    qs = [start + np.concatenate([np.sin(0.002 * k + rng.normal(0, 0.01, 7)) * 0.6,
                                  np.zeros(robot.nq - 7)]) for k in range(600)]
    compiled = _rows_of(CollisionLimit(robot, obstacles, self_collision=True), robot, qs, False)
    python = _rows_of(CollisionLimit(robot, obstacles, self_collision=True), robot, qs, True)
    assert sum(r is not None for r in compiled) > 100
    for a, b in zip(compiled, python, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            assert a[2] == b[2] and a[3] == b[3]
            np.testing.assert_allclose(a[0], b[0], atol=1e-12)
            np.testing.assert_allclose(a[1], b[1], atol=1e-9)


def _two(shapes=None, pairs=((0, 1),), joints=(0, 0), placements=None):
    shapes = [coal.Sphere(0.1), coal.Box(0.2, 0.2, 0.2)] if shapes is None else shapes
    if placements is None:
        placements = np.array([np.eye(4)] * 2)
        placements[1, 0, 3] = 1.0
    return _distances.queries(shapes, list(pairs), [coal.DistanceRequest()] * len(pairs),
                              list(joints), placements)


def test_bad_input_is_refused_clearly():
    with pytest.raises(TypeError, match="shape 1 is not a coal shape"):
        _two(shapes=[coal.Sphere(0.1), "box"])
    with pytest.raises(ValueError, match="one shape, joint and placement per geometry"):
        _two(joints=(0,))
    with pytest.raises(ValueError, match="pair 0 names no shape"):
        _two(pairs=((0, 2),))
    with pytest.raises(ValueError, match=r"C-contiguous float64 array of shape \(ngeoms, 4, 4\)"):
        _two(placements=np.zeros((2, 3, 4)))
    queries = _two(joints=(0, 1))
    with pytest.raises(IndexError, match="pair 1 out of range"):
        _distances.distance(queries, 1, np.eye(4).reshape(1, 16).repeat(2, axis=0))
    with pytest.raises(ValueError, match="its joints are not among the 1 poses"):
        _distances.distance(queries, 0, np.eye(4).reshape(1, 16))


def test_the_queries_read_poses_and_placements_where_they_live():
    # the placements array is read at each query (move() writes it), the poses are the call's
    placements = np.array([np.eye(4)] * 2)
    placements[1, 0, 3] = 1.0
    queries = _two(joints=(0, 1), placements=placements)
    poses = np.eye(4).reshape(1, 16).repeat(2, axis=0)
    assert _distances.distance(queries, 0, poses)[0] == pytest.approx(0.8)
    placements[1, 0, 3] = 2.0
    assert _distances.distance(queries, 0, poses)[0] == pytest.approx(1.8)
    turn = np.eye(4)
    turn[:3, :3] = pin.exp3(np.array([0.0, 0.0, np.pi / 4]))
    poses[1] = turn.ravel()  # the box's joint turns about the world's z: the box orbits
    d, normal, p1, p2 = _distances.distance(queries, 0, poses)
    assert d == pytest.approx(1.8)
    np.testing.assert_allclose(normal, turn[:3, 0], atol=1e-9)
    np.testing.assert_allclose(p2, 1.9 * turn[:3, 0], atol=1e-9)


def test_the_compiled_sphere_gaps_are_the_spheres_distances():
    # the broad phase's test (kernels.sphere_gaps, joint poses read through the data views)
    # against the bounding spheres' centres placed here with numpy
    robot, obstacles = _scene()
    limit = CollisionLimit(robot, obstacles[:5], self_collision=True)
    data = robot.model.createData()
    views = limit._data_views(data)
    assert views is not data
    for _ in range(20):
        pin.forwardKinematics(robot.model, data, pin.randomConfiguration(robot.model))
        gap = np.empty(len(limit.pairs))
        kernels.sphere_gaps(views, limit._joint_f, limit._center_local, limit._pair_f,
                            limit._span, gap)
        centres = np.array([data.oMi[int(j)].homogeneous @ c
                            for j, c in zip(limit._joint, limit._center_local, strict=True)])
        a, b = limit.pairs[:, 0], limit.pairs[:, 1]
        expected = np.linalg.norm(centres[a, :3] - centres[b, :3], axis=1) - limit._span
        np.testing.assert_allclose(gap, expected, atol=1e-12)
