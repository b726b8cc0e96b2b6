"""StepInfo.stalled: a solver that comes to rest short of its target says so, and says why
(limits, or a minimum of the error); one on its way or at the target does not."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .helpers import full_range_pair

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "urdf"

#: UR10 with its elbow exactly straight, and a pose 6.6 cm off along the direction the
#: stretched arm cannot move in (``fk(Q_STRETCHED) * exp6(TWIST)``): a true minimum of the
#: error there (the Hessian of 1/2 |e_w|^2 is positive definite, smallest eigenvalue 0.0125 on
#: the solver's columns), the pose reachable only on another branch of the inverse kinematics
Q_STRETCHED = np.array([3.262729092196741, 4.024037875477934, 0.0, 1.779163105587596,
                        -0.855391043348777, -2.6077009270651046])
TWIST = np.array([-0.03458026054141369, -0.05230447601438341, 0.01537230502673318,
                  -0.01005255087355244, 0.00481348349846092, 0.00181223011624114])


def far_target(robot, q):
    pose = robot.fk(q)
    return pin.SE3(pose.rotation,
                   pose.translation * (1.0 + 1.3 / np.linalg.norm(pose.translation)))


@pytest.mark.parametrize("method, options", [("sjt", {}), ("sjt", {"feedback": "transpose"}),
                                             ("jt", {})], ids=["sjt", "sjt transpose", "jt"])
def test_an_arm_at_rest_short_of_a_target_out_of_reach_says_it_stalled(method, options):
    ur5 = sjt.Robot.from_example("ur5")
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    solver = sjt.make_solver(method, ur5, dt=2e-3, **options)
    far = far_target(ur5, q)
    for _ in range(1500):  # 3 s
        q = solver.step(q, far)
    info = solver.last
    assert info.error_norm > 1.0  # metres short of the target
    assert np.abs(info.dq).max() < 1e-6  # at rest
    # why: no limit holds it (the whole task, no bound), no escape: a minimum of the error
    assert info.stalled and not info.escaped
    assert info.task_scale == 1.0 and info.active_limits == ()


@pytest.mark.parametrize("method", ["sjt", "jt", "dls", "jp"])
def test_an_arm_on_its_way_or_at_its_target_has_not_stalled(method):
    ur5 = sjt.Robot.from_example("ur5")
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q) * pin.exp6(pin.Motion(np.array([0.05, 0.02, -0.03, 0.1, 0.0, 0.2])))
    solver = sjt.make_solver(method, ur5, dt=1e-3)
    for _ in range(1500):
        q = solver.step(q, target)
        assert not solver.last.stalled, solver.last
    assert solver.error_norm < 1e-9  # converged: below the floor, not a stall


def test_an_arm_braking_after_a_target_jumped_has_not_stalled():
    """With acceleration and jerk limits a target that jumps back the other way leaves the arm
    moving against its error while it brakes: it is on its way, not stalled (z1, 30 cm)."""
    z1 = sjt.Robot.from_example("z1")
    q = z1.q0.copy()
    q[1], q[2] = q[1] + 0.6, q[2] - 0.6
    there = z1.fk(q) * pin.SE3(np.eye(3), np.array([0.0, 0.15, 0.0]))
    back = z1.fk(q) * pin.SE3(np.eye(3), np.array([0.0, -0.15, 0.0]))
    solver = sjt.SJTSolver(z1, acceleration_limits=5.0, jerk_limits=500.0)
    for k in range(600):
        q = solver.step(q, there if k < 300 else back)
        info = solver.last
        assert not (info.stalled and np.abs(info.dq).max() > 1e-3), (k, info)


def test_tracking_a_moving_target_is_not_a_stall():
    """The rate counts the motion beyond the target's own velocity: following a circle with a
    steady lag is progress, not a stall."""
    ur5 = sjt.Robot.from_example("ur5")
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    start = ur5.fk(q)
    solver = sjt.JTSolver(ur5, dt=1e-3)
    radius, omega = 0.05, 2.0
    for k in range(2000):
        t = k * solver.dt
        offset = radius * np.array([np.cos(omega * t) - 1.0, np.sin(omega * t), 0.0])
        speed = radius * omega * np.array([-np.sin(omega * t), np.cos(omega * t), 0.0])
        target = pin.SE3(start.rotation, start.translation + offset)
        q = solver.step(q, target, np.concatenate([speed, np.zeros(3)]))
        assert not solver.last.stalled
    assert solver.error_norm > 1e-7  # JT lags the circle: the error is steady, not converged


def test_a_stretched_elbow_at_a_minimum_rests_and_says_so():
    """The straight-elbow stall of UR10: not a saddle the escape misses but a minimum, so the
    escape rightly stays off; the step says it stalled, and solve() (restarts from other
    configurations) finds the pose on another branch."""
    ur10 = sjt.Robot.from_example("ur10")
    target = ur10.fk(Q_STRETCHED) * pin.exp6(pin.Motion(TWIST))
    for method, options in (("sjt", {}), ("sjt", {"feedback": "transpose"}), ("jt", {})):
        solver = sjt.make_solver(method, ur10, dt=1e-3, **options)
        q = Q_STRETCHED.copy()
        for _ in range(3000):
            q = solver.step(q, target)
        assert abs(q[2]) < 1e-6  # the elbow still straight
        assert solver.escape.escapes == 0
        assert 0.06 < solver.error_norm < 0.07
        assert solver.last.stalled and solver.last.task_scale == 1.0
    found = sjt.SJTSolver(ur10).solve(target, Q_STRETCHED)
    assert found.success and found.restarts >= 1 and abs(found.q[2]) > 0.5


LIMITS = [{}, {"acceleration_limits": 10.0, "jerk_limits": 5000.0}]


@pytest.mark.parametrize("options", LIMITS, ids=["bounds", "acceleration and jerk"])
def test_an_arm_with_a_joint_at_its_limit_still_reaches_its_target(options):
    """UR5 whose wrist 1 sits at its lower limit, asked for a pose that the limit blocks on the
    way: the method's step pushes the wrist into the limit. Scaling the task along its own
    direction (Saturation in the Null Space) gives scale 0 here and froze the arm 1.4 away for
    good; the stage's least-distortion step keeps going, and the arm arrives."""
    ur5 = sjt.Robot.from_example("ur5")
    q_target = np.array([-6.072386126449824, 5.387477139779545, -3.068270570368208,
                         -6.281078043905902, 3.6155887483706675, 0.10398509194774963])
    q = q_target.copy()
    q[2] = 0.0
    solver = sjt.SJTSolver(ur5, dt=1e-3, **options)
    speeds = ur5.velocity_limits
    for _ in range(4000):
        q = solver.step(q, ur5.fk(q_target))
        assert np.all(np.abs(solver.last.dq) <= speeds * (1 + 1e-9))
        assert np.all(q >= ur5.lower_limits) and np.all(q <= ur5.upper_limits)
    assert solver.error_norm < 1e-9 and not solver.last.stalled


@pytest.mark.parametrize("options", LIMITS, ids=["bounds", "acceleration and jerk"])
def test_an_arm_held_by_a_position_limit_says_it_stalled_and_which_limit(options):
    """A one-joint arm asked to turn past its upper limit (2 rad): it turns to the limit and
    stops there, a minimum of its error against the limit; the step says it stalled and names
    the limit that holds it."""
    arm = sjt.Robot.from_urdf(str(FIXTURES / "one_joint.urdf"), load_visuals=False)
    target = arm.fk(np.array([2.6]))
    solver = sjt.SJTSolver(arm, task=sjt.PositionTask(axes="xy"), dt=1e-3, **options)
    q = np.array([1.0])
    for _ in range(3000):
        q = solver.step(q, target.translation)
    info = solver.last
    # at rest, at the limit (under acceleration limits 5e-11 rad short of it: braking into the
    # limit, the last of the approach lowers the error by less than the stage's rest rate)
    assert q[0] == pytest.approx(2.0, abs=1e-9) and np.abs(info.dq).max() < 1e-12
    assert info.error_norm > 0.1 and info.stalled
    assert ("position", "shoulder") in info.active_limits


#: pairs of the reach benchmark (random start and reachable target over the full ranges,
#: ``sjt_pin.bench.reach``, seed 0) that end at a minimum against the joint limits, far from
#: the target. The stage held each there in a limit cycle: UR5 kicked its wrist to 0.9 rad/s
#: every 9 steps, xArm7 swung three joints by +-3.1 rad/s on alternate steps, Panda, UR10 and
#: Kinova chattered at 0.01-1 rad/s, all for as long as they ran.
FAR_MINIMA = [("ur5", 27), ("xarm7", 1), ("panda", 4), ("ur10", 16), ("kinova", 27)]


@pytest.mark.parametrize("method", ["sjt", "dls"])
@pytest.mark.parametrize("name, pair", FAR_MINIMA)
def test_an_arm_held_far_from_its_target_by_its_limits_comes_to_rest(name, pair, method):
    robot = sjt.Robot.from_example(name)
    rng = np.random.default_rng(0)
    draws = [(robot.random_configuration(rng), robot.random_configuration(rng))
             for _ in range(pair + 1)]
    q, goal = draws[pair]
    target = robot.fk(goal)
    solver = sjt.make_solver(method, robot)
    speeds = []
    for _ in range(7000):
        q_next = solver.step(q, target)
        speeds.append(np.abs(pin.difference(robot.model, q, q_next)).max() / solver.dt)
        q = q_next
    assert max(speeds[-1000:]) < 1e-9  # at rest over the last second
    info = solver.last
    assert info.error_norm > 0.05 and info.stalled and info.active_limits


def _descent_rate(robot, q, target, sqrt_weight) -> tuple[float, float]:
    """f = 1/2 |W e|^2 of the pose error e = log6(oMf^-1 oMd) at q, and its rate of change
    (per radian, by a forward difference of f itself) along the steepest descent of its exact
    rows (Pinocchio's Jlog6 J) that the position ranges leave free."""
    model, data = robot.model, robot.model.createData()
    fid = robot.ee_frame_id

    def f(x):
        pin.framesForwardKinematics(model, data, x)
        e = pin.log6(data.oMf[fid].actInv(target)).vector
        return 0.5 * float(np.sum((sqrt_weight * e) ** 2))

    pin.framesForwardKinematics(model, data, q)
    oMf = data.oMf[fid]
    e = pin.log6(oMf.actInv(target)).vector
    rows = pin.Jlog6(target.actInv(oMf)) @ pin.computeFrameJacobian(model, data, q, fid,
                                                                    pin.LOCAL)
    g = rows.T @ (sqrt_weight**2 * e)  # (the descent: the rows are -de/dq)
    g[(q >= robot.upper_limits - 1e-12) & (g > 0)] = 0.0
    g[(q <= robot.lower_limits + 1e-12) & (g < 0)] = 0.0
    h = 1e-6
    step = np.clip(q + h * g / np.linalg.norm(g), robot.lower_limits, robot.upper_limits)
    return f(q), (f(step) - f(q)) / h


def test_a_pose_task_rests_only_where_the_true_error_cannot_fall():
    """Panda, random full-range reaches (starts and targets drawn as ``bench reach`` draws
    them, seed 3): where the arm comes to rest short of its target, no direction the ranges
    leave free lowers the weighted pose error faster than 1e-3 of itself per radian. In the
    CLIK model alone (the frame's J for the pose error) the stage rested at 40 of 40 such rests
    of 100 pairs where a direction lowered it at 1e-3 to 3e-2 per radian (pairs 61, 62 and 86:
    0.13, 0.10 and 0.32 of itself); from such a rest the step takes the exact rows Jlog6 J, and
    pair 62 goes on to its target."""
    panda = sjt.Robot.from_example("panda")
    reached = 0
    for pair in (61, 62, 86):
        q, goal = full_range_pair(panda, 3, pair)
        target = panda.fk(goal)
        solver = sjt.make_solver("sjt", panda)
        for _ in range(5000):
            q = solver.step(q, target)
        if solver.error_norm < 1e-9:
            reached += 1
            continue
        assert np.abs(solver.last.dq).max() == 0.0 and solver.last.stalled  # at rest
        f, rate = _descent_rate(panda, q, target, solver.stack.sqrt_weight)
        assert rate > -1e-3 * f, (pair, f, rate)
    assert reached == 1  # (pair 62; the others rest short: the case under test)


def test_the_exact_rows_of_a_rest_belong_to_its_target():
    """From a rest short of its target (Panda, seed-3 pair 61, above) the step takes the pose
    error's exact rows; sent to a new target it starts again in the CLIK rows, as a solver
    made anew at that rest does (the basins of the targets that follow stay the CLIK law's)."""
    panda = sjt.Robot.from_example("panda")
    q, goal = full_range_pair(panda, 3, 61)
    solver = sjt.make_solver("sjt", panda)
    for _ in range(2000):
        q = solver.step(q, panda.fk(goal))
    assert solver.error_norm > 0.5 and np.abs(solver.last.dq).max() == 0.0  # at rest
    target = panda.fk(full_range_pair(panda, 3, 40)[1])
    fresh = sjt.make_solver("sjt", panda)
    a, b = q.copy(), q.copy()
    for _ in range(300):
        a, b = solver.step(a, target), fresh.step(b, target)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9)
    assert np.abs(a - q).max() > 0.1  # (it went somewhere)
