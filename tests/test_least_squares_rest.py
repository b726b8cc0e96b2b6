"""DLS and JP come to rest at a target they cannot reach (their Levenberg-Marquardt term
``w |e_w| L``) and still converge at one they can; ``error_damping=0`` is the textbook update,
which oscillates at the speed limits there."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

DT = 1e-3
#: Franka's published acceleration (rad/s^2) and jerk (rad/s^3) limits, and the same order of
#: magnitude for UR5's six joints
SMOOTH = {
    "panda": {"acceleration_limits": [15, 7.5, 10, 12.5, 15, 20, 20, 1],
              "jerk_limits": [7500, 3750, 5000, 6250, 7500, 10000, 10000, 500]},
    "ur5": {"acceleration_limits": 10.0, "jerk_limits": 5000.0},
}
STARTS = {"panda": None, "ur5": np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])}


@pytest.fixture(scope="module")
def robots():
    return {name: sjt.Robot.from_example(name) for name in STARTS}


def start(robot, name):
    return robot.q0.copy() if STARTS[name] is None else STARTS[name].copy()


def beyond_reach(robot, q, distance=0.8):
    """The pose at ``q`` moved ``distance`` (m) radially outward: out of reach."""
    pose = robot.fk(q)
    radial = pose.translation / np.linalg.norm(pose.translation)
    return pin.SE3(pose.rotation, pose.translation + distance * radial)


def run(solver, q, target, seconds):
    qs = []
    for _ in range(int(round(seconds / DT))):
        q = solver.step(q, target)
        qs.append(q.copy())
    return q, np.array(qs)


def rms_speed(qs, seconds=1.0):
    """RMS joint speed (rad/s) of the returned stream over its last ``seconds``."""
    v = np.diff(qs[-int(round(seconds / DT)) - 1:], axis=0) / DT
    return float(np.sqrt(np.mean(v**2)))


CASES = [(name, method, smooth) for name in STARTS for method in ("dls", "jp")
         for smooth in (False, True)]
IDS = [f"{n}-{m}-{'smooth' if s else 'urdf'}" for n, m, s in CASES]


@pytest.mark.parametrize("name, method, smooth", CASES, ids=IDS)
def test_rests_at_a_target_out_of_reach(robots, name, method, smooth):
    robot = robots[name]
    q = start(robot, name)
    solver = sjt.make_solver(method, robot, dt=DT, **(SMOOTH[name] if smooth else {}))
    # (with Panda's published acceleration and jerk limits each joint's braking toward where
    # the feedback sends it makes the last centimetres slow: at rest after 7 s (JP), 11 s (DLS))
    q, qs = run(solver, q, beyond_reach(robot, q), 12.0 if smooth else 6.0)
    assert solver.error_norm > 0.1  # well short of the target ...
    assert rms_speed(qs) < 1e-3  # ... and at rest
    # says why: a minimum of the error (and, without the braking, nothing holds the arm)
    assert solver.last.stalled and (smooth or solver.last.task_scale == 1.0)


@pytest.mark.parametrize("method", ["dls", "jp"])
def test_the_textbook_update_oscillates_there(robots, method):
    """``error_damping=0`` is the textbook update (the paper's baselines): the linear model's
    one-step correction overshoots back and forth at the workspace's boundary. (The update
    alone, without the joint limits: where they act, the stage takes no step past the linear
    model's minimum along its own direction, and JP's textbook update then rests too.)"""
    robot = robots["panda"]
    q = robot.q0.copy()
    solver = sjt.make_solver(method, robot, dt=DT, error_damping=0.0, position_limits=False,
                             velocity_limits=False)
    _, qs = run(solver, q, beyond_reach(robot, q), 3.0)
    assert rms_speed(qs) > 0.1
    assert not solver.last.stalled


@pytest.mark.parametrize("name, method, smooth", CASES, ids=IDS)
def test_converges_at_a_target_in_reach(robots, name, method, smooth):
    robot = robots[name]
    q = start(robot, name)
    target = robot.fk(q) * pin.exp6(pin.Motion(np.array([0.05, 0.02, -0.03, 0.1, 0.0, 0.2])))
    solver = sjt.make_solver(method, robot, dt=DT, **(SMOOTH[name] if smooth else {}))
    q, qs = run(solver, q, target, 3.0)
    assert solver.error_norm < 1e-9
    assert not solver.last.stalled  # converged, not stalled
    assert rms_speed(qs, 0.5) < 1e-6


def test_error_damping_is_checked_and_the_default_follows_the_rows(robots):
    ur5 = robots["ur5"]
    for bad in (-1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="error_damping"):
            sjt.DLSSolver(ur5, error_damping=bad)
    with pytest.raises(TypeError, match="error_damping"):
        sjt.JPSolver(ur5, error_damping="large")
    # the SJT damped feedback's weights: 0.5 with pose rows only, 1 with position rows
    assert sjt.DLSSolver(ur5).method.lm_weight == 0.5
    assert sjt.JPSolver(ur5, task=sjt.PositionTask()).method.lm_weight == 1.0
    assert sjt.DLSSolver(ur5, error_damping=0.2).method.lm_weight == 0.2


def _far_draw(robot, seed, distance=1.5):
    """A start in the middle half of the ranges and a target ``distance`` (m) from its hand in a
    random direction (out of Panda's reach)."""
    rng = np.random.default_rng(seed)
    middle = 0.5 * (robot.lower_limits + robot.upper_limits)
    half = 0.25 * (robot.upper_limits - robot.lower_limits)
    q = rng.uniform(middle - half, middle + half)
    pose = robot.fk(q)
    direction = rng.normal(size=3)
    return q, pin.SE3(pose.rotation, pose.translation + distance * direction /
                      np.linalg.norm(direction))


@pytest.mark.parametrize("method", ["dls", "jp", "sjt"])
def test_a_posture_keeps_its_whole_share_beside_a_task_of_full_rank(robots, method):
    """Away from singular configurations the posture's share is whole: its level keeps all
    of the self-motion it asks (no limit acts), as the step reports."""
    robot = robots["panda"]
    q0 = 0.5 * (robot.lower_limits + robot.upper_limits)
    target = robot.fk(q0 + 1e-3)
    solver = sjt.make_solver(method, robot, dt=DT, posture=sjt.PostureTask(q0 + 1e-2))
    solver.step(q0, target)
    assert solver.last.active_limits == ()
    assert solver.last.levels[1].scale == pytest.approx(1.0, abs=1e-12)
    assert np.linalg.norm(solver.last.dq) > 0.0


@pytest.mark.parametrize("method", ["dls", "jp", "sjt"])
@pytest.mark.parametrize("seed", range(4))
def test_a_posture_rests_with_the_arm_at_a_target_out_of_reach(robots, method, seed):
    """The arm rests stretched at a singular configuration there, whose two nearly null
    directions the exact null-space projector split anew each step: the posture's velocity
    along the one called null swung sign from step to step, +-2.5 rad/s at the speed limits
    for good, where the arm alone rests. The posture fades where the task's rows lose rank.
    (SJT: its saddle escape's settling step, taken again every 0.24 s though it left the error
    where it was, swung the arm at up to 0.6 rad/s.)"""
    robot = robots["panda"]
    q0, target = _far_draw(robot, seed)
    alone = sjt.make_solver(method, robot, dt=DT)
    _, qs = run(alone, q0, target, 10.0)
    settling = np.abs(np.diff(qs[-1001:], axis=0)).max() / DT  # (SJT's seed 2: 1.5e-6 rad/s)
    solver = sjt.make_solver(method, robot, dt=DT, posture=sjt.PostureTask(q0))
    _, qs = run(solver, q0, target, 10.0)
    v = np.diff(qs[-1001:], axis=0) / DT
    assert np.abs(v).max() < max(1e-6, 2.0 * settling), (np.abs(v).max(), settling)
    assert solver.last.stalled
    assert solver.last.levels[1].scale == 0.0  # (the step says the posture faded)
    assert solver.error_norm == pytest.approx(alone.error_norm, abs=1e-3)


@pytest.mark.parametrize("method", ["dls", "jp", "sjt", "jt"])
def test_a_posture_rests_with_a_joint_at_its_range_below_a_target_out_of_reach(robots, method):
    """Panda from ``q0`` sent 1.5 m straight down: its joint 2 stops at its range and the
    joints left free could move the hand only across the error (their vertical row 1e-2 of the
    others). Rows of unit norm hid that rank loss from the posture's share, and DLS and SJT
    swung joints 1 and 3 at their speed limits from step to step for good. The posture fades,
    the step says so, and the arm rests where the arm alone does."""
    robot = robots["panda"]
    q0 = robot.q0.copy()
    target = robot.fk(q0).translation + np.array([0.0, 0.0, -1.5])
    alone = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask())
    run(alone, q0, target, 10.0)
    solver = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask(),
                             posture=sjt.PostureTask(q0))
    _, qs = run(solver, q0, target, 10.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.last.levels[1].scale < 1e-6
    assert solver.error_norm == pytest.approx(alone.error_norm, abs=1e-4)


@pytest.mark.parametrize("method", ["dls", "jp", "sjt", "jt"])
def test_an_arm_that_can_move_only_across_its_error_rests(robots, method):
    """The same Panda, no posture: with joint 2 at its range the free joints move the hand
    only across the error, where the Gauss-Newton model's neglected second-order term is as
    large as its first-order decrease. JT's projected step moved the hand at 1.3 m/s (joints
    at 2.3 rad/s), turning back every step, for good; the step the last one's measured
    curvature trusts lets the error fall, and the arm rests at the constrained minimum."""
    robot = robots["panda"]
    q0 = robot.q0.copy()
    target = robot.fk(q0).translation + np.array([0.0, 0.0, -1.5])
    solver = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask())
    _, qs = run(solver, q0, target, 10.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.error_norm == pytest.approx(0.570208, abs=1e-5)
    assert ("position", "panda_joint2") in solver.last.active_limits


@pytest.mark.parametrize("method", ["dls", "jp", "sjt", "jt"])
def test_the_steepest_descent_fallback_trusts_the_measured_curvature_too(method):
    """UR10 (its limited variant), a target 0.82 m beyond what the arm can reach with its
    shoulder-lift and elbow joints at their ranges: the projected step, cut by the last step's
    measured curvature, made too little progress and gave way to the Cauchy point (the
    linearised model's minimum along the steepest descent), which jumped across the error's
    minimum along that line; the next step's jumped back. DLS swung three joints between
    their speed limits on alternate steps for good (error 0.82266 m, unchanged). The Cauchy
    point is cut by the same measured curvature: every method rests."""
    robot = sjt.Robot.from_example("ur10_limited")
    q0 = np.array([-2.7245747881163958, -3.090091190197629, 1.5129310051765694,
                   -0.08989546605742982, 0.731208282649074, 0.6874916910057705])
    target = np.array([0.01750625470197027, 0.2430731303082949, -0.8403957517174037])
    solver = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask())
    _, qs = run(solver, q0, target, 4.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.last.stalled


@pytest.mark.parametrize("seed", [3, 6, 7])
def test_a_posture_rests_beside_sjt_under_acceleration_limits_out_of_reach(robots, seed):
    """SJT's saddle escape tests the error of the first level, the one its step lowers. With
    the posture's rows in its test, Panda stretched toward a target out of reach under
    acceleration limits took a settling step back toward the posture every 0.25 s, which the
    first level undid: these three draws swung at 0.13-0.8 rad/s after 20 s."""
    robot = robots["panda"]
    q0, target = _far_draw(robot, seed)
    solver = sjt.make_solver("sjt", robot, dt=DT, acceleration_limits=20.0,
                             posture=sjt.PostureTask(q0))
    _, qs = run(solver, q0, target, 10.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.last.stalled


@pytest.mark.parametrize("method", ["jp", "dls", "sjt", "jt"])
def test_the_bounded_displacement_rests_where_the_error_bends_more_than_its_model(method):
    """UR10 (its limited variant) under acceleration limits, its elbow and wrist-1 joints at
    their ranges, a position target 0.32 m beyond what it can reach from there: the bounded
    least-squares displacement (Gauss-Newton, J^T J) passed the constrained minimum along the
    free joints, whose error bends about 2.3 times as much as the model says, and the next
    step's came back: every method flipped the shoulder-pan and wrist-1 joints every step at
    1e-3 rad/s for good (a held-out survey's run). With the curvature the last step measured
    along its own motion in the displacement's model, each rests there, at the error's
    constrained minimum, within 3 s."""
    robot = sjt.Robot.from_example("ur10_limited")
    q0 = np.array([1.052134154603551, 1.0389815965005873, -3.14159265359, 3.14159265359,
                   0.4069966469478188, -0.19869091645815784])
    target = np.array([-0.05091831756104724, 0.21548144416700105, 0.5955539052975662])
    acceleration = [5.349236002685152, 37.424108149327246, 1.1517618010608863,
                    5.175935935079475, 23.30313154808343, 1.2634258154695082]
    solver = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask(),
                             acceleration_limits=acceleration)
    _, qs = run(solver, q0, target, 4.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.last.stalled
    assert solver.error_norm == pytest.approx(0.32327054753, abs=1e-9)


@pytest.mark.parametrize("method", ["jp", "jt", "dls", "sjt"])
def test_a_folded_arm_with_joints_of_unequal_limits_rests_beyond_reach(method):
    """UR3 (its limited variant) folded with its shoulder-lift and elbow joints at their ranges,
    a position target 0.26 m beyond what the other joints reach from there, under acceleration
    and jerk limits of very different joints (shoulder pan 23.7 rad/s^2, wrist 1 2.3): the
    bounded least-squares displacement asked pan and wrist 1 to turn together, 1.6-1.9 rad
    where the error's minimum along it lay at 0.1-0.25 of that, and each joint brakes toward
    its own share at its own limits, so the pan ran ahead alone, uphill, and the arm swung at
    the pan's 2.16 rad/s speed limit for good (a held-out survey's run; the displacement's
    Levenberg-Marquardt term was 0.5, now 3). Every method rests at the constrained minimum
    within 3 s."""
    robot = sjt.Robot.from_example("ur3_limited")
    q0 = np.array([0.89, -np.pi, np.pi, 0.501, 1.813, -1.229])
    target = np.array([-0.07116328179566639, -0.00739453026520089, -0.21222505620584883])
    solver = sjt.make_solver(method, robot, dt=DT, task=sjt.PositionTask(),
                             acceleration_limits=[23.7043, 4.5301, 1.1998, 2.3464, 7.5929, 2.4142],
                             jerk_limits=[1869.78, 357.33, 94.64, 185.08, 598.92, 190.43])
    _, qs = run(solver, q0, target, 4.0)
    assert np.abs(np.diff(qs[-1001:], axis=0)).max() / DT < 1e-6
    assert solver.last.stalled
    assert solver.error_norm == pytest.approx(0.248587263, abs=1e-8)
