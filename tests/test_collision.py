"""Collision avoidance: damper rows are the derivative of the distance, no geometry comes closer
than the margin (checked independently with coal), SRDF pairs are skipped, obstacles move."""

import re

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits import Motion


def independent_distance(robot, q, shape, pose) -> float:
    """The least distance between the robot's collision geometry and one obstacle, computed
    with coal on a geometry model of its own (not the limit's numbers)."""
    model = robot.collision_model.copy()
    model.removeAllCollisionPairs()
    obstacle = model.addGeometryObject(pin.GeometryObject("obstacle", 0, 0, pose, shape))
    for g in range(obstacle):
        model.addCollisionPair(pin.CollisionPair(g, obstacle))
    data = model.createData()
    pin.computeDistances(robot.model, robot.model.createData(), model, data, q)
    return min(r.min_distance for r in data.distanceResults)


def rows_at(limit, robot, q, dt=1e-3):
    kinematics = Kinematics(robot.model)
    kinematics.update(q)
    return limit.rows(kinematics, Motion(q, np.zeros(robot.nv), np.zeros(robot.nv), dt))


def test_damper_rows_are_the_derivative_of_the_distance(panda, rng):
    """Against finite differences of the distance along random joint velocities (smooth
    obstacles: a box's distance to a mesh has ties between features, where only one-sided
    derivatives exist; its rows hold the derivative of one of them)."""
    hand = panda.fk(panda.q0)
    for shape in [coal.Sphere(0.05), coal.Capsule(0.03, 0.1), coal.Sphere(0.02)]:
        pose = pin.SE3(pin.exp3(rng.normal(size=3)), hand.translation + [0.0, 0.0, -0.25])
        limit = sjt.CollisionLimit(panda, obstacles=[(shape, pose)], influence=0.2)
        A, b = rows_at(limit, panda, panda.q0)
        assert A.shape[0] == len(limit.active) > 0
        for row, (name_a, name_b, _, _, _) in zip(A, limit.active, strict=True):
            u = rng.normal(size=panda.nv)
            u[7:] = 0.0  # fingers: prismatic, fine too, but keep the arm's motion
            h = 1e-6

            def distance(q, a=name_a, b=name_b, limit=limit):
                return next(x[2] for x in limit.distances(q) if x[:2] == (a, b))

            plus = distance(pin.integrate(panda.model, panda.q0, h * u))
            minus = distance(pin.integrate(panda.model, panda.q0, -h * u))
            assert (plus - minus) / (2 * h) == pytest.approx(-row @ u, rel=1e-3, abs=1e-6)


def test_a_line_past_a_sphere_keeps_the_margin_and_recovers(panda):
    """A Panda hand on a 40 cm line that passes an 8 cm sphere: no geometry within the margin
    (- 1 mm), checked with coal on a model of its own; once the line is clear, the task."""
    q0 = panda.q0.copy()
    start = panda.fk(q0)
    end = pin.SE3(start.rotation, start.translation + [0.0, 0.4, 0.0])
    sphere = coal.Sphere(0.04)
    pose = pin.SE3(np.eye(3), start.translation + [0.0, 0.2, -0.07])
    margin = 0.01
    limit = sjt.CollisionLimit(panda, obstacles=[(sphere, pose)], margin=margin)
    solver = sjt.SJTSolver(panda, limits=[limit])
    line = sjt.PoseInterpolation(start, end, duration=2.0)
    log = sjt.track(solver, line, q0, duration=3.5)  # 1.5 s holding the end
    closest = min(independent_distance(panda, q, sphere, pose) for q in log.q[::10])
    free = sjt.track(sjt.SJTSolver(panda), line, q0)
    assert min(independent_distance(panda, q, sphere, pose) for q in free.q[::10]) < 0
    assert closest >= margin - 1e-3
    assert log.error_norm[-1] < 1e-3  # the end is reachable without touching: reached


def test_srdf_disabled_and_adjacent_pairs_are_skipped(panda):
    limit = sjt.CollisionLimit(panda, self_collision=True)
    names = [g.name for g in limit.geometry.geometryObjects]
    links = {(names[a], names[b]) for a, b in limit.pairs}
    from sjt_pin.limits.collision import _example_srdf

    srdf = open(_example_srdf(panda)).read()
    disabled = re.findall(r'link1="([^"]+)" link2="([^"]+)"', srdf)
    assert disabled
    link_of = {g.name: panda.model.frames[g.parentFrame].name
               for g in limit.geometry.geometryObjects}
    for a, b in links:
        assert (link_of[a], link_of[b]) not in disabled and (link_of[b], link_of[a]) not in disabled
    model = panda.model
    for a, b in limit.pairs:
        ja = limit.geometry.geometryObjects[int(a)].parentJoint
        jb = limit.geometry.geometryObjects[int(b)].parentJoint
        assert ja != jb and model.parents[ja] != jb and model.parents[jb] != ja


def test_obstacles_move_between_steps(panda):
    hand = panda.fk(panda.q0)
    near = pin.SE3(np.eye(3), hand.translation + [0.0, 0.0, -0.25])
    limit = sjt.CollisionLimit(panda, obstacles=[(coal.Sphere(0.05), near)], influence=0.2)
    assert rows_at(limit, panda, panda.q0) is not None
    limit.move(0, pin.SE3(np.eye(3), np.array([3.0, 3.0, 3.0])))
    assert rows_at(limit, panda, panda.q0) is None
    assert limit.distances(panda.q0)[0][2] > 2.0


def test_bad_obstacles_and_missing_geometry_are_refused(panda, planar3):
    pose = pin.SE3.Identity()
    with pytest.raises(TypeError, match="not a coal shape"):
        sjt.CollisionLimit(panda, obstacles=[("sphere", pose)])
    with pytest.raises(TypeError, match="pin.SE3"):
        sjt.CollisionLimit(panda, obstacles=[(coal.Sphere(0.1), np.eye(4))])
    with pytest.raises(TypeError, match="pair"):
        sjt.CollisionLimit(panda, obstacles=[coal.Sphere(0.1)])
    with pytest.raises(ValueError, match="margin < influence"):
        sjt.CollisionLimit(panda, obstacles=[(coal.Sphere(0.1), pose)], margin=0.1)
    inside = pin.SE3(np.eye(3), panda.fk(panda.q0).translation)
    limit = sjt.CollisionLimit(panda, obstacles=[(coal.Sphere(0.05), inside)])
    with pytest.raises(ValueError, match="at the start"):
        sjt.SJTSolver(panda, limits=[limit]).step(panda.q0, panda.fk(panda.q0))
