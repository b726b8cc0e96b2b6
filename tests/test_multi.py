"""Several frames at once, and the posture task of redundant arms."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .helpers import regulate


def test_talos_tracks_both_hands():
    talos = sjt.Robot.from_example("talos")
    hands = ["gripper_left_joint", "gripper_right_joint"]
    solver = sjt.SJTSolver(talos, dt=0.01, task={h: sjt.PoseTask() for h in hands},
                           position_limits=False)
    assert solver.stack.dim == 12
    goal = talos.q0.copy()
    arms = [talos.model.idx_qs[talos.model.getJointId(f"arm_{s}_{k}_joint")]
            for s in ("left", "right") for k in (1, 2, 4)]
    goal[arms] += np.array([0.2, 0.3, -0.4, -0.2, -0.3, -0.4])
    targets = {h: talos.fk(goal, frame=h) for h in hands}
    q = regulate(solver, talos.q0, targets, 20_000)
    for h in hands:
        error = pin.log6(talos.fk(q, frame=h).actInv(targets[h])).vector
        assert np.linalg.norm(error) < 1e-6
    alpha = solver.last.alpha
    legs = talos.model.idx_vs[talos.model.getJointId("leg_left_1_joint")]
    assert alpha[legs] == 0 and np.all(alpha[:6] > 0)  # legs move no hand; the base does
    assert set(solver.last.pose) == set(hands)


def test_panda_hand_position_with_an_orientation_task(panda, rng):
    tasks = {"panda_hand_tcp": sjt.PositionTask(), "panda_link7": sjt.OrientationTask()}
    solver = sjt.SJTSolver(panda, dt=0.01, task=tasks)
    goal = panda.q0 + rng.uniform(-0.2, 0.2, panda.nq)
    goal[7:] = panda.q0[7:]
    targets = {"panda_hand_tcp": panda.fk(goal, "panda_hand_tcp").translation,
               "panda_link7": panda.fk(goal, "panda_link7")}
    regulate(solver, panda.q0, targets, 20_000)
    assert solver.last.error_norm < 1e-6
    assert solver.last.error.shape == (6,)


def test_bad_multi_frame_input(panda):
    tasks = {"panda_hand_tcp": sjt.PositionTask(), "panda_link7": sjt.OrientationTask()}
    solver = sjt.SJTSolver(panda, task=tasks)
    with pytest.raises(ValueError, match="missing \\['panda_link7'\\]"):
        solver.step(panda.q0, {"panda_hand_tcp": [0.3, 0.0, 0.5]})
    with pytest.raises(ValueError, match="mapping"):
        solver.step(panda.q0, panda.fk(panda.q0))
    with pytest.raises(TypeError, match="track drives one task frame"):
        sjt.track(solver, sjt.Line([0, 0, 0], [1, 0, 0], 1.0), panda.q0)


def test_posture_bounds_the_null_space_drift_of_panda():
    """60 s of a periodic circle with a 3-row position task (4 redundant joints)."""
    panda = sjt.Robot.from_example("panda")
    p0 = panda.fk(panda.q0).translation
    circle = sjt.Circle(p0 - [0, 0.15, 0], 0.15, duration=60.0, normal=[1, 0, 0], turns=15)
    period = int(4.0 / 0.01)

    def drift(posture):
        solver = sjt.SJTSolver(panda, dt=0.01, task=sjt.PositionTask(), posture=posture)
        log = sjt.track(solver, circle, panda.q0)
        starts = log.q[::period]  # the configuration at the start of each turn
        return np.linalg.norm(starts[-1] - starts[1]), log

    free, free_log = drift(None)
    held, held_log = drift(sjt.PostureTask(weight=1e-2))
    assert free > 0.3  # the self-motion wanders
    assert held < 0.01  # with the posture task the motion is periodic
    assert held_log.max_error < 0.05 and free_log.max_error < 0.1
