"""``sjt-pin bench collision``'s peer rows (pink: ``bench.collision_peers``, mink:
``bench.collision_mink``) on the moving ball and the plate of bumps, on short runs: a row's
distances, ratios and failure come from the configurations the peer returned, recomputed here
independently."""

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

from sjt_pin.bench import collision_mesh, collision_mink, collision_moving, collision_peers
from sjt_pin.bench.collision import DT, Checker, run_scene, run_steps
from sjt_pin.limits import CollisionLimit


def test_a_step_that_fails_ends_the_run_and_the_row_says_when(panda):
    """A solver that holds the arm still and fails at its 31st step (returns None): 31
    configurations, the row's ``failed_at`` at 0.3 s, and its closest distance that of the
    ball when the failing step started (the ball comes closer at every step)."""
    driven = collision_moving.ball(panda, 1.0, 1e-2)
    limit = CollisionLimit(panda, driven.obstacles)
    driven.checker = Checker(panda, driven.obstacles, limit.pair_names)
    calls = []

    def step(q, pose, velocity):
        calls.append(pose)
        return None if len(calls) == 31 else q

    qs, us = run_steps(panda.q0, driven.path, step)
    assert len(qs) == 31 and len(calls) == 31 and us > 0
    row = collision_moving.moving_row(panda, driven, 1e-2, False, False, qs, us, None, "peer")
    assert row.failed_at == pytest.approx(0.3) and row.speed_ratio == 0.0
    first = Checker(panda, driven.obstacles, limit.pair_names).closest(panda.q0)[0]
    last = Checker(panda, [(driven.shape, driven.path[30][0])], limit.pair_names)
    assert row.closest == pytest.approx(last.closest(panda.q0)[0]) and row.closest < first
    full = collision_moving.moving_row(panda, driven, 1e-2, False, False,
                                       np.repeat(qs[:1], len(driven.path) + 1, axis=0), us,
                                       None, "peer")
    assert math.isnan(full.failed_at)


def test_without_the_peers_their_rows_are_left_out(monkeypatch):
    monkeypatch.setattr(collision_peers, "available", lambda: False)
    monkeypatch.setattr(collision_mink, "available", lambda: False)
    assert collision_peers.pink_moving() == [] and collision_peers.pink_mesh() == []
    assert collision_mink.mink_moving() == [] and collision_mink.mink_mesh() == []


def _finite(row) -> None:
    for field in dataclasses.fields(row):
        value = getattr(row, field.name)
        if isinstance(value, float) and field.name not in ("failed_at", "acceleration_ratio",
                                                            "jerk_ratio"):
            assert math.isfinite(value), field.name


@pytest.mark.bench
def test_pinks_ball_run_measures_what_pink_returned(panda):
    """pink beside the ball at 1 m/s and 100 Hz: the row's closest distance is that of the
    configurations pink returns (run again here, the ball moved in a fresh checker), never
    less than the hulls' (a lower bound); a QP with no solution is reported with its time,
    and pink fails again from the same state."""
    pytest.importorskip("pink")
    row = collision_peers.pink_drive(panda, 1.0, 1e-2)
    _finite(row)
    assert (row.method, row.told, row.exceeded) == ("pink", False, None)
    driven = collision_moving.ball(panda, 1.0, 1e-2)
    limit = CollisionLimit(panda, driven.obstacles)
    arm = collision_peers.PinkArm(panda, panda.q0, 1e-2, limit)

    def step(q, pose, velocity):
        arm.move(0, pose)
        return arm.step(q, driven.hand)

    qs, _ = run_steps(panda.q0, driven.path, step)
    checker = Checker(panda, driven.obstacles, limit.pair_names)
    distances, hulls = [], []
    for q, (pose, _) in zip(qs, driven.path, strict=False):
        checker.move(0, pose)
        distances.append(checker.closest(q)[0])
        limit.move(0, pose)
        hulls.append(min(d.distance for d in limit.distances(q)))
    assert row.closest == min(distances) and min(hulls) <= row.closest + 1e-9
    assert row.below == sum(d < collision_moving.MARGIN - 1e-3 for d in distances)
    v = np.diff(qs, axis=0) / 1e-2
    assert row.speed_ratio == pytest.approx(np.max(np.abs(v) / panda.velocity_limits))
    if len(qs) - 1 < len(driven.path):  # pink failed: the row says when, and so it does again
        assert row.failed_at == pytest.approx((len(qs) - 1) * 1e-2)
        arm.move(0, driven.path[len(qs) - 1][0])
        assert arm.step(qs[-1], driven.hand) is None
    else:
        assert math.isnan(row.failed_at)


@pytest.mark.bench
def test_pinks_pull_over_the_plate_measures_what_pink_returned():
    """pink's pull over the plate (its first 0.4 s), the plate as its hull, with its
    acceleration limit: the row's distance to the mesh is that of pink's configurations every
    5th step, its acceleration ratio that of their finite differences, and the final error
    that of the last one."""
    pytest.importorskip("pink")
    scene = dataclasses.replace(collision_mesh.plate_scene(), duration=0.4)
    row = collision_peers.pink_pull(True, scene)
    _finite(row)
    assert (row.method, row.convex, row.conflicts, row.unreported) == ("pink", True, None, None)
    limit = CollisionLimit(scene.robot, scene.obstacles)
    accelerations, _ = collision_moving.franka_like(scene.robot.nv)
    arm = collision_peers.PinkArm(scene.robot, scene.q0, DT, limit, accelerations)
    qs, _ = run_scene(scene, lambda q, pose, velocity: arm.step(q, pose))
    checker = Checker(scene.robot, scene.obstacles, limit.pair_names)
    assert row.closest == min(checker.closest(q)[0] for q in qs[1::5])
    v = np.diff(qs, axis=0) / DT
    a = np.diff(np.vstack([np.zeros((1, scene.robot.nv)), v]), axis=0) / DT
    assert row.acceleration_ratio == pytest.approx(np.max(np.abs(a) / accelerations))
    end, _ = scene.target(scene.duration)
    error = np.linalg.norm(pin.log6(scene.robot.fk(qs[-1]).actInv(end)).vector)
    assert row.final_error == pytest.approx(error)
    assert (math.isnan(row.failed_at) if len(qs) == 401
            else row.failed_at == pytest.approx((len(qs) - 1) * DT))


@pytest.mark.bench
def test_minks_model_is_the_robots_and_its_row_measures_it(panda):
    """mink's MuJoCo model, compiled from Panda's URDF: the hand's pose equals Pinocchio's at
    the same joints, and the row's distance is that of the configurations mink returns."""
    pytest.importorskip("mink")
    row = collision_mink.mink_drive(panda, 1.0, 1e-2)
    _finite(row)
    assert (row.method, row.told, row.exceeded) == ("mink", False, None)
    driven = collision_moving.ball(panda, 1.0, 1e-2)
    arm = collision_mink.MinkArm(panda, 1e-2, lambda spec: collision_mink.add_ball(spec, driven))
    q = panda.q0 + 0.1
    arm.configuration.update(arm.to_mujoco(q))
    hand = arm.configuration.get_transform_frame_to_world("panda_hand", "body").as_matrix()
    np.testing.assert_allclose(hand, panda.fk(q).homogeneous, atol=1e-12)
    qs, _ = run_steps(panda.q0, driven.path,
                      lambda q, pose, velocity: arm.step(q, driven.hand, pose.translation))
    limit = CollisionLimit(panda, driven.obstacles)
    checker = Checker(panda, driven.obstacles, limit.pair_names)
    distances = []
    for q, (pose, _) in zip(qs, driven.path, strict=False):
        checker.move(0, pose)
        distances.append(checker.closest(q)[0])
    assert row.closest == min(distances)

