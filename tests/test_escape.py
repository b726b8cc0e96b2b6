"""The saddle escape: it leaves exact saddles smoothly, within the URDF speeds, and never fires
at a minimum, where the arm comes to rest."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.accuracy import saddle_problems
from sjt_pin.escape import SaddleEscape

TRANSPOSE = [("sjt", {}), ("sjt", {"feedback": "transpose"}), ("jt", {})]


def run(solver, q, target, steps):
    """Steps until 1 % of the start error; (steps or None, peak |q_dot_j| / v_max_j, q)."""
    limits = solver.robot.velocity_limits
    start, peak = None, 0.0
    for k in range(steps):
        q = solver.step(q, target)
        start = solver.error_norm if start is None else start
        peak = max(peak, float(np.max(np.abs(solver.displacement) / solver.dt / limits)))
        if solver.error_norm < 0.01 * start:
            return k + 1, peak, q
    return None, peak, q


@pytest.mark.parametrize("saddle", [0, 1], ids=["q=0 roll", "q5=0 u_min"])
def test_default_sjt_leaves_exact_saddles_as_fast_as_dls(saddle):
    """Within 2x DLS's steps; at q = 0 the pose task's length makes the saddle one of fourth
    order, which no method leaves without the escape (nothing but round-off moves it): SJT's
    escape does, in at most 1,000 steps at 2 ms (398 when measured; DLS's 396)."""
    label, robot, q0, target = saddle_problems()[saddle]
    dls_steps, _, _ = run(sjt.DLSSolver(robot, dt=2e-3), q0, target, 5000)
    solver = sjt.SJTSolver(robot, dt=2e-3)
    steps, peak, _ = run(solver, q0, target, 5000)
    assert steps is not None and steps <= 2 * (dls_steps or 500), (label, steps, dls_steps)
    assert peak <= 1.0 + 1e-9  # never above the URDF speeds


@pytest.mark.parametrize("method", ["dls", "jp"])
def test_least_squares_methods_leave_exact_saddles_by_the_escape(method):
    """The damped and pseudoinverse steps map an error along the lost direction to zero as the
    transpose does: without the escape UR5 at q = 0 never leaves its saddle; with it (the
    default) it does, within the URDF speeds."""
    label, robot, q0, target = saddle_problems()[0]
    stuck = sjt.make_solver(method, robot, dt=2e-3, escape=False)
    assert run(stuck, q0, target, 2000)[0] is None
    solver = sjt.make_solver(method, robot, dt=2e-3)
    steps, peak, _ = run(solver, q0, target, 2000)
    assert steps is not None and steps <= 1000 and solver.escape.escapes >= 1, (label, steps)
    assert peak <= 1.0 + 1e-9


@pytest.mark.parametrize("method, options", TRANSPOSE[1:], ids=["sjt transpose", "jt"])
def test_transpose_feedback_escapes_smoothly_within_the_urdf_speeds(method, options):
    label, robot, q0, target = saddle_problems()[0]
    stuck = sjt.make_solver(method, robot, dt=2e-3, escape=False, **options)
    assert run(stuck, q0, target, 500)[0] is None  # J^T e = 0: without the escape, no motion
    solver = sjt.make_solver(method, robot, dt=2e-3, velocity_limits=False, **options)
    steps, peak, _ = run(solver, q0, target, 15_000)
    assert steps is not None and solver.escape.escapes >= 1
    assert peak <= 1.0 + 1e-9  # the escape keeps to the URDF speeds, speed limits off or not


@pytest.mark.parametrize("saddle", [0, 1], ids=["q=0 roll", "q5=0 u_min"])
def test_escape_velocity_ramps_without_jumps(saddle):
    """With the transpose feedback the arm's motion is the escape's: its joint accelerations
    stay at the ramp's (about 16 rad/s^2 on UR5), not the thousands of a 0.05 rad jump."""
    _, robot, q0, target = saddle_problems()[saddle]
    solver = sjt.SJTSolver(robot, dt=1e-3, feedback="transpose", velocity_limits=False)
    q, speeds = q0, []
    for _ in range(1500):
        q = solver.step(q, target)
        speeds.append(solver.displacement / solver.dt)
    accelerations = np.abs(np.diff(np.array(speeds), axis=0)).max(axis=1) / solver.dt
    assert solver.escape.escapes >= 1
    ramp = solver.escape.SPEED * robot.velocity_limits.max() / solver.escape.RAMP
    assert accelerations.max() < 2 * ramp  # rad/s^2


@pytest.mark.parametrize("method, options", TRANSPOSE, ids=["sjt", "sjt transpose", "jt"])
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_an_arm_that_cannot_reach_comes_to_rest(name, method, options):
    robot = sjt.Robot.from_example(name)
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2]) if name == "ur5" else robot.q0.copy()
    pose = robot.fk(q)
    far = pin.SE3(pose.rotation, pose.translation * (1.0 + 1.3 / np.linalg.norm(pose.translation)))
    solver = sjt.make_solver(method, robot, dt=2e-3, **options)
    speeds = []
    for _ in range(1500):  # 3 s
        q = solver.step(q, far)
        speeds.append(np.linalg.norm(solver.displacement) / solver.dt)
    assert solver.escape.escapes == 0  # a minimum, not a saddle: the escape never fires
    assert np.sqrt(np.mean(np.square(speeds[-500:]))) < 1e-3  # rad/s over the last second


@pytest.mark.parametrize("method, options", TRANSPOSE, ids=["sjt", "sjt transpose", "jt"])
def test_a_position_far_above_rests_with_short_wrist_levers(panda, method, options):
    """A position target 0.8 m straight above Panda's reach: the wrist joints' levers (about
    0.1 m) are much shorter than the error, whose curvature the gain and the damping must
    respect — without it the arm chattered at its speed limits."""
    solver = sjt.make_solver(method, panda, dt=2e-3, task=sjt.PositionTask(), **options)
    q, speeds = panda.q0.copy(), []
    for _ in range(2500):  # 5 s (JT: the joints held at their speed limits on the way leave
        # it in a valley of small curvature, where it settles more slowly)
        q = solver.step(q, np.array([0.0, 0.0, 2.0]))
        speeds.append(np.linalg.norm(solver.displacement) / solver.dt)
    assert solver.error_norm > 0.5 and solver.escape.escapes == 0
    assert np.sqrt(np.mean(np.square(speeds[-500:]))) < 1e-3


def test_an_escape_never_raises_the_error_by_more_than_ten_per_cent():
    """The example on which escapes raised the error 60-fold (a slow start on a random
    3-joint chain, the transpose feedback): each escape now yields as soon as the error grows."""
    from .test_pipeline import random_chain

    seed = 33554432
    robot = random_chain(seed, 3)
    rng = np.random.default_rng(seed)
    solver = sjt.SJTSolver(robot, dt=1e-2, task=sjt.PositionTask(), feedback="transpose",
                           position_limits=False, velocity_limits=False)
    q = robot.random_configuration(rng)
    target = robot.fk(pin.integrate(robot.model, q, rng.normal(scale=0.05, size=robot.nv)))
    start, worst = None, 1.0
    for _ in range(3000):
        q = solver.step(q, target.translation)
        if solver.escape.active:
            start = solver.error_norm if start is None else start
            worst = max(worst, solver.error_norm / start)
        else:
            start = None
    assert solver.escape.escapes > 0  # the case under test: escapes fired
    assert worst <= 1.1


def test_a_negative_curvature_the_error_does_not_follow_starts_no_escape():
    """xArm7 (JT, a target 0.26 m beyond reach, acceleration and jerk limits: ``sjt-pin bench
    settle``'s draw 19) stalls where f's curvature along a self-motion is negative by a few
    millionths of the largest and positive a few hundredths of a radian out. Each escape
    travelled 0.5 rad at 1.6 rad/s with f rising, a settling step took it back, and the next
    test left again: the arm still moved at 1.6 rad/s after 30 s. Confirmed further out, that
    direction is no escape and the arm stays put."""
    from sjt_pin.bench import settle

    row = settle.run(sjt.Robot.from_example("xarm7"), 19, "jt")
    assert row.scene == "beyond" and row.acceleration and row.jerk  # the case under test
    assert row.speed < 1e-4 and row.reversals == 0, row


@pytest.mark.parametrize("arm, seed, method", [("xarm7", 1, "sjt"), ("xarm7", 13, "jt"),
                                               ("kinova", 4, "dls"), ("kinova", 4, "jp")])
def test_at_a_minimum_the_feedback_rests_instead_of_creeping(arm, seed, method):
    """Arms beyond reach (``sjt-pin bench settle``'s draws, no acceleration limits): at the
    minimum the curvature test finds, the method's own feedback crept on along its flat
    directions after 30 s: xArm7 at 4e-4 rad/s (SJT) and 3e-5 (JT), lowering |e| by 1e-10 of
    itself a second; Kinova stretched, under DLS and JP, whose steps shrink with the singular
    value the straight elbow loses, at 5e-3 rad/s (they watch the stall as JT does now). Along
    those directions the arm rests within the run's 10 s, and the creep it gives up is worth
    nothing: 20 s more of the method without the escape lower the error by less than a
    millionth."""
    from sjt_pin.bench import settle

    robot = sjt.Robot.from_example(arm)
    row = settle.run(robot, seed, method)
    assert row.scene == "beyond" and row.state == "rest" and row.seconds == settle.SECONDS, row
    draw = settle.draw(robot, seed)
    assert draw.acceleration is None  # (the solver below is the run's)
    solver = sjt.make_solver(method, robot, task=sjt.PositionTask(), dt=settle.DT)
    q = draw.q0
    for _ in range(round(row.seconds / settle.DT)):
        q = solver.step(q, draw.targets[0][1])
    assert solver.last.stalled and np.abs(solver.last.dq).max() < 1e-6
    rested = solver.error_norm
    creeping = sjt.make_solver(method, robot, task=sjt.PositionTask(), dt=settle.DT,
                               escape=False)
    for _ in range(20000):
        q = creeping.step(q, draw.targets[0][1])
    assert rested - 1e-6 * rested < creeping.error_norm <= rested + 1e-12


@pytest.mark.parametrize("method", ["dls", "jp"])
def test_an_escape_goes_on_where_the_regular_update_creeps_along_it(method):
    """Kinova stretched toward a target out of reach under acceleration and jerk limits
    (``sjt-pin bench settle``'s draw 13): its wrist turned downhill at 0.01-0.02 rad/s for 30 s,
    the error falling by a millionth of itself a second. The curvature test found the descent,
    but each escape ended on its first step: the regular update moved faster than the escape's
    ramp had reached. Weighed against the escape's top speed instead, the escape travels the
    descent, and the arm rests at its bottom within 20 s."""
    from sjt_pin.bench import settle

    row = settle.run(sjt.Robot.from_example("kinova"), 13, method)
    assert row.scene == "beyond" and row.acceleration and row.jerk, row
    assert row.state == "rest" and row.rest_s < 20.0, row
    assert max(row.ratio_a, row.ratio_j) <= 1.0 + 1e-6, row


@pytest.mark.parametrize("dt", [1e-3, 4e-3])
@pytest.mark.parametrize("saddle", [2, 3], ids=["bravo7 q5=pi", "baxter arm singular"])
def test_default_sjt_leaves_wrist_and_redundant_saddles_within_twice_dls(saddle, dt):
    """Bravo 7 at its wrist singularity and Baxter's 7-joint arm at a singular configuration
    (its escape picks the sign with room before the elbow's limit): at most 2x DLS's steps."""
    label, robot, q0, target = saddle_problems()[saddle]
    dls_steps, _, _ = run(sjt.DLSSolver(robot, dt=dt), q0, target, int(10 / dt))
    solver = sjt.SJTSolver(robot, dt=dt)
    steps, peak, _ = run(solver, q0, target, int(10 / dt))
    assert dls_steps is not None and steps is not None, (label, steps, dls_steps)
    assert steps <= 2 * dls_steps, (label, steps, dls_steps)
    assert solver.escape.escapes >= 1 and peak <= 1.0 + 1e-9


def test_a_redundant_arm_rests_at_the_bottom_of_what_it_can_reach():
    """Baxter's 7-joint arm pulled 0.3 m beyond its reach: at rest (< 1e-3 rad/s over the last
    of 5 s at 1 ms), where 15 s more would not lower its error by a millionth."""
    from sjt_pin.bench.accuracy import _reach, baxter_arm

    robot, q = baxter_arm()
    pose = robot.fk(q)
    reach = _reach(robot, pose.translation)
    far = pin.SE3(pose.rotation, (reach + 0.3) * pose.translation
                  / np.linalg.norm(pose.translation))
    solver = sjt.SJTSolver(robot, dt=1e-3)
    speeds = []
    for _ in range(5000):
        q = solver.step(q, far)
        speeds.append(np.linalg.norm(solver.displacement) / solver.dt)
    assert np.sqrt(np.mean(np.square(speeds[-1000:]))) < 1e-3
    at_rest = solver.error_norm
    for _ in range(15_000):
        q = solver.step(q, far)
    assert solver.error_norm > at_rest * (1 - 1e-6)


def test_tiago_arm_and_torso_settle_at_a_target_out_of_reach():
    """TIAGo's arm and torso (8 joints) pulled 1 m outward at the tool's height: the regular
    update alone creeps along the flattest direction of the minimum (2e-2 rad/s after 5 s);
    the Newton steps of the escape's settling bring it to rest with no less error."""
    robot = sjt.Robot.from_example("tiago_no_hand", ee_frame="arm_tool_link")
    q = robot.q0.copy()
    pose = robot.fk(q)
    outward = pose.translation * [1.0, 1.0, 0.0]
    far = pin.SE3(pose.rotation, pose.translation + outward / np.linalg.norm(outward))
    settled, creeping = sjt.SJTSolver(robot, dt=1e-3), sjt.SJTSolver(robot, dt=1e-3)
    creeping.escape.curvature.SLOW = 0.0  # no settling: nothing counts as a slow curvature
    speeds, qc = [], q.copy()
    for _ in range(5000):
        q = settled.step(q, far)
        qc = creeping.step(qc, far)
        speeds.append(np.linalg.norm(settled.displacement) / settled.dt)
    assert settled.escape.settles >= 1 and creeping.escape.settles == 0
    assert np.sqrt(np.mean(np.square(speeds[-1000:]))) < 1e-3
    assert np.linalg.norm(creeping.displacement) / creeping.dt > 1e-3  # the case under test
    assert settled.error_norm <= creeping.error_norm * (1 + 1e-9)


def test_a_settling_step_starts_only_below_where_the_last_one_started():
    """The settling steps' gate, on a quadratic f = 1/2 |b - A q|^2 whose two flattest
    curvatures are slow: a settling step fires where f has a Newton step along them; back near
    where it started (within MAX_TRAVEL) with f no lower, none fires again, however long the
    step still is (the regular update bringing f back up each time cycled for good); once f is
    below that start, or beyond MAX_TRAVEL, one does."""
    model = pin.buildSampleModelManipulator()  # (6 revolute joints: q's differences are linear)
    s = np.array([1.0, 1.0, 1.0, 1.0, 0.1, 0.05])  # curvatures s^2: two below SLOW of the top
    b = np.array([0.2, -0.1, 0.3, 0.1, 0.0, 0.0])

    def rows(q):
        return np.diag(s), b - s * q

    escape = SaddleEscape(model, np.ones(6, dtype=bool), np.ones(6))
    start = np.concatenate([b[:4] / s[:4], [0.3, -0.3]])  # at the floor but along the slow two

    def f(q):
        e = rows(q)[1]
        return 0.5 * float(e @ e)

    assert escape.test(start, rows) and escape.settles == 1
    assert np.allclose(escape.direction[4:], [-1.0, 1.0] / np.sqrt(2.0))  # (Newton: to 0, 0)
    stiff = start + np.array([0.01, 0, 0, 0, 0, 0])  # f no lower than at the start: held
    assert f(stiff) > f(start)
    assert not escape.test(stiff, rows) and escape.settles == 1
    lower = start + np.array([0, 0, 0, 0, -0.1, 0.1])  # a third of the way down: f lower
    assert f(lower) < f(start)
    assert escape.test(lower, rows) and escape.settles == 2
    far = lower + np.array([0.0, 0.6, 0.0, 0.0, 0.0, 0.0])  # beyond MAX_TRAVEL: not held
    assert f(far) > f(lower)
    assert escape.test(far, rows) and escape.settles == 3


def on_each_evaluation(monkeypatch, hook):
    """Call ``hook()`` before each evaluation of the escape's test rows
    (:func:`~sjt_pin.step_checks.weighted_rows`)."""
    from sjt_pin import step_checks

    made = step_checks.weighted_rows

    def wrapped(*args):
        rows = made(*args)

        def each(q):
            hook()
            return rows(q)
        return each

    monkeypatch.setattr(step_checks, "weighted_rows", wrapped)


def test_a_curvature_test_evaluates_the_rows_once_a_step_at_most(monkeypatch):
    """The curvature test (2 n evaluations of the task rows, and a few more) is spread over
    the steps, one evaluation a step: UR5 on two frames' 1 cm circles stalls at the tasks'
    least-squares compromise and tests again and again; no step evaluates the rows more than
    once beyond its own (all at once, a test was one step of 0.3-0.6 ms), and the tests still
    find their settling steps."""
    from sjt_pin.bench.speed import TWO_FRAMES, _targets

    count = [0]

    def tally():
        count[0] += 1

    on_each_evaluation(monkeypatch, tally)
    robot = sjt.Robot.from_example("ur5")
    frames = TWO_FRAMES["ur5"]
    solver = sjt.SJTSolver(robot, task={f: sjt.PoseTask() for f in frames})
    q, per_step = robot.q0.copy(), []
    for targets in _targets(robot, q, frames, 1500, solver.dt):
        count[0] = 0
        q = solver.step(q, {f: pose for f, (pose, _) in targets.items()})
        per_step.append(count[0])
    assert max(per_step) == 1
    assert sum(per_step) >= 2 * 2 * robot.model.nv  # two tests at least, spread
    assert solver.escape.settles >= 2


def test_a_test_whose_rows_raise_ends_and_the_next_one_runs(monkeypatch):
    """An error raised by the task rows during a curvature test (a task's own ``compute``
    failing at a displaced q, or Ctrl-C) comes out of that step; the test ends there, the
    next steps run as usual, and the stall is tested again and escaped."""
    calls = [0]

    def fail_the_fourth():
        calls[0] += 1
        if calls[0] == 4:
            raise RuntimeError("a task's rows failed")

    on_each_evaluation(monkeypatch, fail_the_fourth)
    _, robot, q, target = saddle_problems()[0]
    solver = sjt.SJTSolver(robot, dt=2e-3, feedback="transpose")
    raised = False
    for _ in range(5000):
        try:
            q = solver.step(q, target)
        except RuntimeError:
            raised = True
            assert not solver.escape.testing
        if solver.escape.escapes:
            break
    assert raised and solver.escape.escapes == 1
