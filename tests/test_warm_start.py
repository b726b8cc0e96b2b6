"""The stage's nearest feasible velocity starts from the last step's dual point (a warm start):
the same velocities as a cold start, to rounding (amplified while an arm slides along an
obstacle, the same rest), in fewer Newton steps; copies carry it."""

import copy

import numpy as np
import pytest

import sjt_pin as sjt

COLD = (np.empty(0), [], -1, -1, -1)  # a projection state that starts the next solve cold


def far_reach(robot, seed):
    """A start and a target 0.4 m away (the method's step is far beyond the speed limits)."""
    rng = np.random.default_rng(seed)
    model = robot.model
    q = np.clip(robot.q0 + rng.uniform(-0.3, 0.3, robot.nv), model.lowerPositionLimit,
                model.upperPositionLimit)
    target = robot.fk(q)
    target.translation += 0.4 * rng.normal(size=3) / np.sqrt(3.0)
    return q, target


def side_by_side(warm, cold, q, inputs):
    """Step ``warm`` and ``cold`` (its warm start cleared before each step) from ``q`` over
    ``inputs`` (the step's arguments after q): the last configurations, the largest
    difference on the way, the Newton steps of each, and the steps the stage projected (task
    scale < 1) or held with a row."""
    qw = qc = q
    worst, newton, held = 0.0, {"warm": 0, "cold": 0}, 0
    for args in inputs:
        cold._controller.warm_state = COLD
        qw, qc = warm.step(qw, *args), cold.step(qc, *args)
        worst = max(worst, np.abs(qw - qc).max())
        newton["warm"] += warm._controller.iterations
        newton["cold"] += cold._controller.iterations
        held += warm.last.task_scale < 1.0 or bool(warm.last.active_rows)
    return qw, qc, worst, newton, held


def ball_scene():
    """The collision bench's first scene (Panda's hand along a line past a ball, then held),
    its solvers' limit and its inputs (pose, velocity) per step."""
    from sjt_pin.bench.collision import scenes

    scene = scenes()[0]
    inputs = [scene.target(k * 1e-3) for k in range(int(round(scene.duration / 1e-3)))]
    return scene, inputs, lambda: sjt.CollisionLimit(scene.robot, scene.obstacles,
                                                     self_collision=True, margin=0.01)


@pytest.mark.parametrize("method", ["sjt", "dls", "jp"])
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_a_warm_start_gives_the_cold_start_s_velocity_in_fewer_newton_steps(name, method):
    robot = sjt.Robot.from_example(name)
    q, target = far_reach(robot, seed=3)
    warm, cold = (sjt.make_solver(method, robot) for _ in range(2))
    _, _, worst, newton, projected = side_by_side(warm, cold, q, [(target,)] * 400)
    assert projected > 100  # (the stage projected the step: the start matters)
    assert worst <= 1e-9
    assert newton["warm"] < 0.75 * newton["cold"]


def test_a_copy_carries_the_warm_start(ur5):
    q, target = far_reach(ur5, seed=1)
    original = sjt.make_solver("sjt", ur5)
    for _ in range(30):
        q = original.step(q, target)
    assert original.last.task_scale < 1.0
    twin = copy.deepcopy(original)
    y, working, n, r, c = twin._controller.warm_state
    np.testing.assert_array_equal(y, original._controller.warm_state[0])
    assert (n, r, c) == (ur5.nv, 6, 0) and working == []
    a = b = q
    for _ in range(200):
        a, b = original.step(a, target), twin.step(b, target)
    np.testing.assert_array_equal(a, b)


def test_beside_an_obstacle_a_warm_start_comes_to_the_cold_start_s_rest():
    """The collision rows join and leave the projection's working set. Sliding along the
    ball, the arm amplifies the starts' rounding (1.5e-4 rad at most, measured, while the
    rest rule blends the step toward rest); both rest at the same configuration, in less than
    half the Newton steps warm."""
    scene, inputs, limit = ball_scene()
    warm, cold = (sjt.make_solver("sjt", scene.robot, limits=[limit()]) for _ in range(2))
    qw, qc, worst, newton, held = side_by_side(warm, cold, scene.q0, inputs)
    assert held > 1000  # (the rows or the limits held the step)
    assert worst < 3e-4
    np.testing.assert_allclose(qw, qc, rtol=0.0, atol=1e-9)
    assert newton["warm"] < 0.5 * newton["cold"]


def test_a_carried_working_set_keeps_only_the_rows_a_step_has():
    """Beside the ball, with collision rows in the step: a state naming rows 0-2 and 500 (no
    step has 500 rows) steps as a cold start does."""
    scene, inputs, limit = ball_scene()
    solver = sjt.make_solver("sjt", scene.robot, limits=[limit()])
    q = scene.q0
    for args in inputs[:1500]:
        q = solver.step(q, *args)
    assert solver.last.active_rows
    y, _, n, r, c = solver._controller.warm_state
    twin = copy.deepcopy(solver)
    solver._controller.warm_state = (y, [2, 0, 1, 500], n, r, c)
    twin._controller.warm_state = COLD
    np.testing.assert_allclose(solver.step(q, *inputs[1500]), twin.step(q, *inputs[1500]),
                               rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("state", [
    (np.zeros(3), [], 6, 6, 0),              # a dual point of the wrong length
    (np.zeros(6), [], 7, 6, 0),              # another robot's joints
    (np.zeros(6), [-1], 6, 6, 0),            # a row index below 0
    (np.zeros(6), [2, 0, 2], 6, 6, 0),       # a row twice
    (np.full(6, np.nan), [], 6, 6, 0),       # a dual point that is not finite
])
def test_a_warm_start_that_does_not_fit_is_refused(ur5, state):
    solver = sjt.make_solver("sjt", ur5)
    with pytest.raises(ValueError, match="does not fit"):
        solver._controller.warm_state = state


def test_reset_forgets_the_warm_start(ur5):
    q, target = far_reach(ur5, seed=1)
    solver = sjt.make_solver("sjt", ur5)
    for _ in range(30):
        q = solver.step(q, target)
    assert solver._controller.warm_state[2] == ur5.nv
    solver.reset()
    assert solver._controller.warm_state[2] == -1
