"""The collision limit's distance queries (Pinocchio's computeDistance, called back by the
compiled kernels.collision_rows): an obstacle moved is queried where it lies, the rows read
through the data views are those read through Pinocchio's Python bindings, and the broad
phase's sphere gaps are the spheres' distances."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
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


def test_a_moved_obstacle_is_queried_where_it_now_lies():
    # the queries (Pinocchio's computeDistance, called back by kernels.collision_rows) see the
    # obstacle at the pose move() gave it: the pair's floor is its new distance
    robot, obstacles = _scene()
    limit = CollisionLimit(robot, obstacles[:1], influence=0.5)  # (the ball within influence)
    kinematics = Kinematics(robot.model)
    motion = Motion(robot.q0, np.zeros(robot.nv), np.zeros(robot.nv), 1e-3)
    shape, pose = obstacles[0]
    kinematics.update(robot.q0)
    limit.rows(kinematics, motion)
    before = limit._floor[0]
    limit.move(0, pin.SE3(pose.rotation, pose.translation + [0.0, 0.0, 0.02]))
    limit.rows(kinematics, motion)
    after = limit._floor[0]
    assert 0 in limit.within
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.q0)
    pin.updateGeometryPlacements(robot.model, data, limit.geometry, limit.geometry_data)
    assert after == pytest.approx(pin.computeDistance(limit.geometry, limit.geometry_data,
                                                      0).min_distance, abs=1e-12)
    assert after != before


def _rows_of(limit, robot, qs, python: bool):
    """The limit's rows at each q, the joint poses and Jacobians read through the data views
    (python False) or through Pinocchio's Python bindings (data.oMi, data.J)."""
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
        kernels.sphere_gaps(views, limit._joint, limit._center_local, limit.pairs,
                            limit._span, gap)
        centres = np.array([data.oMi[int(j)].homogeneous @ c
                            for j, c in zip(limit._joint, limit._center_local, strict=True)])
        a, b = limit.pairs[:, 0], limit.pairs[:, 1]
        expected = np.linalg.norm(centres[a, :3] - centres[b, :3], axis=1) - limit._span
        np.testing.assert_allclose(gap, expected, atol=1e-12)
