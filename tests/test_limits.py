"""Joint limits inside step(): positions never crossed, speeds scaled, tracking still converges."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .helpers import full_range_pair


@pytest.mark.parametrize("method", ["sjt", "dls", "jp"])
def test_random_targets_never_violate_panda_limits(panda, method, rng):
    solver = sjt.make_solver(method, panda, gain="auto" if method == "sjt" else 50.0, dt=5e-3)
    assert solver.position_limit is not None and solver.velocity_limit is not None
    lower, upper, vmax = panda.lower_limits, panda.upper_limits, panda.velocity_limits
    q = panda.q0.copy()
    clamped = 0
    steps = 3000 if method == "sjt" else 1000
    for k in range(steps):
        if k % 100 == 0:  # a new random target, half of them beyond the reach
            target = pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-1.2, 1.2, 3))
        q = solver.step(q, target)
        info = solver.last
        clamped += len(info.clamped)
        assert np.all(q >= lower - 1e-12) and np.all(q <= upper + 1e-12)
        assert np.all(np.abs(info.dq) <= vmax * (1 + 1e-9))
    assert clamped > 0  # the limits were really in play


def test_reachable_targets_still_converge_within_limits(panda, rng):
    solver = sjt.SJTSolver(panda, dt=0.01)
    for _ in range(3):
        goal = np.clip(panda.q0 + rng.uniform(-0.3, 0.3, panda.nq), panda.lower_limits,
                       panda.upper_limits)
        target = panda.fk(goal)
        q = panda.q0.copy()
        for _ in range(20_000):
            q = solver.step(q, target)
            if solver.last.error_norm < 1e-6:
                break
        assert solver.last.error_norm < 1e-6


def test_a_joint_at_its_limit_is_clamped_out_and_the_others_take_over(ur5):
    elbow_max = ur5.upper_limits[2]  # the URDF's 3.14159265359
    q = np.array([0.3, -1.2, elbow_max, -1.8, -1.5, 0.2])  # elbow at its upper limit
    # a position target: five joints without the elbow can still reach it
    target = (ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.05]))).translation
    solver = sjt.JPSolver(ur5, gain=20.0, dt=0.01, task=sjt.PositionTask())
    free = sjt.JPSolver(ur5, gain=20.0, dt=0.01, task=sjt.PositionTask(), position_limits=False)
    free.step(q, target)
    assert free.last.dq[2] > 0  # the unconstrained update pushes the elbow outward
    q_next = solver.step(q, target)
    info = solver.last
    assert 2 in info.clamped and ("position", "elbow_joint") in info.active_limits
    assert np.all(np.abs(info.dq) <= ur5.velocity_limits * (1 + 1e-12))
    assert q_next[2] == elbow_max  # stays on the limit
    for _ in range(500):
        q = solver.step(q, target)
        assert q[2] <= elbow_max
    assert solver.last.error_norm < 1e-6  # the other joints reached the target


def test_a_joint_at_its_speed_limit_is_held_and_the_others_keep_the_task(ur5):
    """Saturation in the Null Space: one slow joint does not slow the whole arm."""
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.002, 0.0, 0.0]))
    speeds = np.full(6, np.inf)
    speeds[0] = 0.2  # the base joint is slow
    free = sjt.SJTSolver(ur5, dt=1e-3, velocity_limits=False, task=sjt.PositionTask())
    limited = sjt.SJTSolver(ur5, dt=1e-3, velocity_limits=speeds,
                            task=sjt.PositionTask())
    free.step(q, target.translation)
    limited.step(q, target.translation)
    assert abs(free.last.dq[0]) > 0.2  # the base joint would be too fast
    info = limited.last
    assert ("velocity", "shoulder_pan_joint") in info.active_limits
    assert abs(info.dq[0]) == pytest.approx(0.2)
    # the other five joints make up for it, as far as the method's damping lets them (the stage
    # solves its damped least squares within the limits: 0.982 of the task motion here)
    assert 0.95 < info.task_scale < 1.0
    J = ur5.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:3]
    made, wanted = J @ info.dq, J @ free.last.dq
    assert np.linalg.norm(made - wanted) <= 0.05 * np.linalg.norm(wanted)
    with pytest.raises(ValueError, match=r"velocity_limits must have shape \(6,\)"):
        sjt.SJTSolver(ur5, velocity_limits=[1.0, 2.0])


def _beyond_every_speed(ur5, **options):
    """The first step toward a target 30 cm away with K = 150/s under 0.5 rad/s speed limits:
    the step taken, the unlimited one, and the Jacobian."""
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.0]))
    limited = sjt.SJTSolver(ur5, gain=150.0, dt=1e-3, velocity_limits=np.full(6, 0.5),
                            **options)
    free = sjt.SJTSolver(ur5, gain=150.0, dt=1e-3, velocity_limits=False)
    limited.step(q, target)
    free.step(q, target)
    return limited.last, free.last.dq, ur5.jacobian(q)


def test_a_task_beyond_every_speed_takes_the_nearest_feasible_velocity(ur5):
    """Not the step scaled as a whole into the box (one joint at its limit, the others in
    proportion): the nearest feasible velocity drives every joint the task can use, and moves
    the task further along the motion asked for (1.34 times here)."""
    info, unlimited, J = _beyond_every_speed(ur5)
    assert 0 < info.task_scale < 1
    assert np.abs(info.dq).max() <= 0.5 * (1 + 1e-12)
    assert np.sum(np.isclose(np.abs(info.dq), 0.5)) >= 3
    wanted = J @ unlimited
    scaled = 0.5 / np.abs(unlimited).max() * wanted
    assert wanted @ (J @ info.dq) > 1.2 * (wanted @ scaled)


def test_under_acceleration_limits_a_task_beyond_every_speed_keeps_its_direction(ur5):
    """Each joint then brakes toward the displacement the method asks of it, along the
    method's direction: the step keeps that direction (a motion off it costs the stage 1e4
    times more), slower."""
    info, unlimited, J = _beyond_every_speed(ur5, acceleration_limits=1e6)
    assert 0 < info.task_scale < 1
    wanted, made = J @ unlimited, J @ info.dq
    cosine = wanted @ made / np.linalg.norm(wanted) / np.linalg.norm(made)
    assert cosine > 1 - 1e-5
    assert np.linalg.norm(made) == pytest.approx(info.task_scale * np.linalg.norm(wanted),
                                                 rel=1e-3)


@pytest.mark.parametrize("name", ["ur5", "panda", "kinova"])
def test_far_targets_progress_faster_than_the_step_scaled_along_its_direction(name):
    """Random configurations, random targets over the full ranges, random speed limits
    (0.1-3 rad/s), position limits off: the task progress of the first step along the motion
    asked for, over that of the unlimited step scaled as a whole into the box. Measured over 200
    draws each: at least 1.03 (UR5), 1.13 (Panda), 1.14 (Kinova), median 1.5-1.6."""
    robot = sjt.Robot.from_example(name)
    rng = np.random.default_rng(1)
    ratios = []
    for _ in range(60):
        q = robot.random_configuration(rng)
        target = robot.fk(robot.random_configuration(rng))
        speed = np.full(robot.nv, 10 ** rng.uniform(-1, 0.5))
        limited = sjt.SJTSolver(robot, velocity_limits=speed, position_limits=False)
        free = sjt.SJTSolver(robot, velocity_limits=False, position_limits=False)
        limited.step(q, target)
        free.step(q, target)
        assert np.all(np.abs(limited.last.dq) <= speed * (1 + 1e-12))
        J, unlimited = robot.jacobian(q), free.last.dq
        wanted = J @ unlimited
        scale = min(1.0, float(speed[0] / np.abs(unlimited).max()))
        ratios.append((wanted @ (J @ limited.last.dq)) / (scale * (wanted @ wanted)))
    assert min(ratios) > 0.95
    assert np.median(ratios) > 1.3


def test_a_far_reach_under_speed_limits_arrives_as_fast_as_pinks():
    """Kinova, start and target of the reach benchmark's eighth random pair: scaled along its
    direction into the speed box, the step moved one joint at its speed limit and the rest in
    proportion, and the hand was still 2.1 cm away after 5 s (pink's QP arrives in 3.3 s);
    the nearest feasible velocity drives the other joints too and arrives in about 3.5 s."""
    kinova = sjt.Robot.from_example("kinova")
    q, goal = full_range_pair(kinova, 0, 8)
    target = kinova.fk(goal)
    solver = sjt.SJTSolver(kinova)
    for _ in range(4000):
        q = solver.step(q, target)
        assert np.all(np.abs(solver.last.dq) <= kinova.velocity_limits * (1 + 1e-12))
    pose = kinova.fk(q)
    assert np.linalg.norm(pose.translation - target.translation) < 1e-6
    assert np.linalg.norm(pin.log3(pose.rotation.T @ target.rotation)) < 1e-6


def test_a_start_outside_the_limits_returns_at_the_allowed_speed():
    """Kinova's SRDF pose puts joint 3 at -1.571 rad, outside its URDF range [0.33, 5.95]:
    Robot clips q0 (with a warning), and a start out of range is brought back at the joint's
    speed limit, never jumped into range."""
    with pytest.warns(UserWarning, match=r"\['j2s6s200_joint_3'\] outside their URDF limits"):
        kinova = sjt.Robot.from_example("kinova")
    assert np.all(kinova.q0 >= kinova.lower_limits) and np.all(kinova.q0 <= kinova.upper_limits)
    joint = kinova.model.getJointId("j2s6s200_joint_3")
    i, v = kinova.model.idx_qs[joint], kinova.model.idx_vs[joint]
    q = kinova.q0.copy()
    q[i] = -1.571  # the SRDF's value
    target = kinova.fk(kinova.q0)
    vmax = kinova.velocity_limits[v]
    solver = sjt.SJTSolver(kinova, dt=1e-3)
    for _ in range(200):
        q = solver.step(q, target)
        assert abs(solver.last.dq[v]) <= vmax * (1 + 1e-12)  # never faster than allowed
        assert v in solver.last.clamped  # held to its return motion while outside
    assert q[i] == pytest.approx(-1.571 + 200 * 1e-3 * vmax)  # moving back at the limit
    result = solver.solve(target, q)  # a seed out of range works too
    assert result.success
    assert np.all(result.q >= kinova.lower_limits) and np.all(result.q <= kinova.upper_limits)


def _run(solver, q, targets):
    steps, clamped = [], 0
    for target in targets:
        q = solver.step(q, target)
        steps.append(solver.displacement.copy())
        clamped += len(solver.last.clamped)
    return np.array(steps), clamped


class _Box(sjt.limits.Limit):
    """The URDF's position range and a speed, as a user's bounds (one step never leaves the
    range, no joint faster than ``speed``)."""

    name = "box"
    uses_motion = True

    def __init__(self, robot, speed):
        self.lower, self.upper, self.speed = robot.lower_limits, robot.upper_limits, speed

    def bounds(self, kinematics, motion):
        room_up = (self.upper - motion.q) / motion.dt
        room_down = (motion.q - self.lower) / motion.dt
        return np.maximum(-room_down, -self.speed), np.minimum(room_up, self.speed)


def test_the_built_in_limits_and_the_same_bounds_as_a_user_limit_take_the_same_steps(ur5, rng):
    """The position range and a speed given as a user's limit's bounds take the steps of the
    built-in position and speed limits: both are hard bounds of the same stage."""
    q = np.array([0.3, -1.2, ur5.upper_limits[2] - 0.02, -1.8, -1.5, 0.2])
    targets = [ur5.fk(q) * pin.exp6(pin.Motion(rng.normal(scale=0.05, size=6)))
               for _ in range(60)]
    speeds = np.full(6, 0.3)
    built_in = sjt.SJTSolver(ur5, dt=0.01, velocity_limits=speeds)
    user = sjt.SJTSolver(ur5, dt=0.01, velocity_limits=False, position_limits=False,
                         limits=[_Box(ur5, speeds)])
    reference, clamped = _run(built_in, q, targets)
    assert clamped > 0  # the limits acted
    np.testing.assert_allclose(_run(user, q, targets)[0], reference, atol=1e-12)


def test_extra_limits_must_be_limit_objects(ur5):
    with pytest.raises(TypeError, match="Limit"):
        sjt.SJTSolver(ur5, limits=[object()])


class _Band(sjt.limits.Limit):
    """A joint band whose upper bound on joint 1 is ``value`` (rad/s), inf elsewhere."""

    name = "band"

    def __init__(self, value):
        self.value = value

    def bounds(self, kinematics, motion):
        n = kinematics.model.nv
        upper = np.full(n, np.inf)
        upper[1] = self.value
        return np.full(n, -np.inf), upper


class _Row(sjt.limits.Limit):
    """One row ``q_dot_1 <= value``."""

    name = "row"

    def __init__(self, value):
        self.value = value

    def rows(self, kinematics, motion):
        A = np.zeros((1, kinematics.model.nv))
        A[0, 1] = 1.0
        return A, np.array([self.value])


@pytest.mark.parametrize("acceleration", [None, 10.0])
def test_a_limit_that_returns_nan_is_refused_naming_it(ur5, acceleration):
    """A NaN bound or row bounds nothing: the joint would move freely. The step raises,
    naming the limit; inf (no bound) is fine."""
    q = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.1, 0.0, -0.1]))
    for good in (_Band(np.inf), _Row(np.inf), _Band(0.0), _Row(0.0)):
        sjt.SJTSolver(ur5, limits=[good], acceleration_limits=acceleration).step(q, target)
    for bad, match in ((_Band(np.nan), r"_Band.*bounds\(\)"), (_Row(np.nan), r"_Row.*rows\(\)")):
        solver = sjt.SJTSolver(ur5, limits=[bad], acceleration_limits=acceleration)
        with pytest.raises(ValueError, match=match):
            solver.step(q, target)


class _Hold(sjt.limits.Limit):
    """Two rows that hold joint 1 still: ``0 <= q_dot_1 <= 0``."""

    name = "hold"

    def rows(self, kinematics, motion):
        A = np.zeros((2, kinematics.model.nv))
        A[0, 1], A[1, 1] = 1.0, -1.0
        return A, np.zeros(2)


@pytest.mark.parametrize("acceleration", [None, 10.0])
def test_a_row_held_at_its_bound_is_reported_on_every_step(ur5, acceleration):
    """A row that holds joint 1 still is active on every step, also when the kernel's step
    already met it (nothing to correct): StepInfo.active_rows names it each time."""
    q = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.1, 0.0, -0.1]))
    solver = sjt.SJTSolver(ur5, limits=[_Hold()], acceleration_limits=acceleration)
    for _ in range(200):
        q = solver.step(q, target)
        assert solver.last.active_rows == ("hold",)


class _Caps(sjt.limits.Limit):
    """Speed bounds ``|q_dot| <= caps`` on every step, declared as ``speed_caps`` or not."""

    name = "caps"
    uses_motion = False

    def __init__(self, caps, declared):
        self.caps, self.declared = np.asarray(caps, dtype=float), declared

    def bounds(self, kinematics, motion):
        return -self.caps, self.caps

    def speed_caps(self, dt):
        return self.caps if self.declared else None


_CAPS = np.array([0.5, 0.4, 0.8, 1.0, 1.0, 1.0])


def _cap_run(ur5, declared, method="sjt", steps=600, **options):
    """UR5 without its own speed limits sent 27 cm away under ``_CAPS``: the configurations
    and each step's (active limits, task scale)."""
    solver = sjt.make_solver(method, ur5, dt=1e-3, velocity_limits=False,
                             limits=[_Caps(_CAPS, declared)], **options)
    q = np.array([0.3, -1.2, 1.4, -0.5, 0.8, 0.1])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.2, -0.1, 0.15]))
    qs, infos = [q], []
    for _ in range(steps):
        q = solver.step(q, target)
        qs.append(q)
        infos.append((solver.last.active_limits, solver.last.task_scale))
    return np.array(qs), infos


@pytest.mark.parametrize("method", ["sjt", "jt", "jp", "dls"])
def test_speed_caps_hold_as_the_same_bounds_do(ur5, method):
    """A limit that declares its bounds as speed caps (held with the speed limits, its bounds
    not asked) takes exactly the steps, and gets the StepInfo, of the same bounds asked every
    step."""
    asked, asked_info = _cap_run(ur5, False, method)
    held, held_info = _cap_run(ur5, True, method)
    np.testing.assert_array_equal(held, asked)
    assert held_info == asked_info
    speeds = np.abs(np.diff(held, axis=0)) / 1e-3
    assert (speeds <= _CAPS * (1 + 1e-12)).all()
    assert speeds[:, 0].max() == pytest.approx(0.5)  # the caps acted, named
    assert ("caps", ur5.velocity_names[0]) in held_info[10][0]


@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_speed_caps_beside_acceleration_and_jerk_limits_keep_all_three(ur5, method):
    """Under acceleration and jerk limits, caps held with the speed limits are approached
    within both (the stage brakes to them as to its own speed limits)."""
    qs, _ = _cap_run(ur5, True, method, steps=1500, acceleration_limits=10.0,
                     jerk_limits=5000.0)
    v = np.diff(qs, axis=0) / 1e-3
    a = np.diff(v, axis=0) / 1e-3
    jerk = np.diff(a, axis=0) / 1e-3
    assert (np.abs(v) <= _CAPS * (1 + 1e-9)).all()
    assert np.abs(v[:, 0]).max() > 0.49  # the first joint's cap bound it
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    assert np.abs(jerk).max() <= 5000.0 * (1 + 1e-6)


def test_speed_caps_that_are_no_speeds_are_refused_naming_the_limit(ur5):
    for caps in (np.ones(5), np.full(6, np.nan), np.zeros(6)):
        with pytest.raises(ValueError, match=r"_Caps.*speed_caps\(\)"):
            sjt.SJTSolver(ur5, limits=[_Caps(caps, True)])


class _FirstJointBack(sjt.limits.Limit):
    """One row, ``q_dot_0 <= 0``, as float arrays, as lists of ints or as one float vector
    (the row alone), and speed caps that bound nothing: the solver asks such a lone limit for
    its rows directly."""

    name = "back"
    uses_motion = False

    def __init__(self, form):
        self.form = form

    def rows(self, kinematics, motion):
        if self.form == "lists":
            return [[1, 0, 0, 0, 0, 0]], [0]
        if self.form == "vector":
            return np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), np.zeros(1)
        return np.array([[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]), np.zeros(1)

    def speed_caps(self, dt):
        return np.full(6, np.inf)


def test_a_lone_limit_s_rows_as_lists_are_taken_as_arrays_are(ur5):
    """Rows given as lists of ints, or one row as a vector, hold as the same rows as float
    arrays (the same steps, the same StepInfo.active_rows; as the stage takes them from a
    limit without speed caps), and the row holds: the first joint never turns forward."""
    runs = []
    for form in ("arrays", "lists", "vector"):
        solver = sjt.SJTSolver(ur5, dt=1e-3, limits=[_FirstJointBack(form)])
        q = np.array([0.3, -1.2, 1.4, -0.5, 0.8, 0.1])
        target = ur5.fk(q + [0.3, 0.1, 0.0, 0.0, 0.0, 0.0])
        qs, rows = [q], []
        for _ in range(300):
            q = solver.step(q, target)
            qs.append(q)
            rows.append(solver.last.active_rows)
        runs.append((np.array(qs), rows))
    for qs, rows in runs[1:]:
        np.testing.assert_array_equal(runs[0][0], qs)
        assert rows == runs[0][1]
    assert ("back",) in runs[0][1]
    assert (np.diff(runs[0][0][:, 0]) <= 1e-12).all()


def test_under_acceleration_limits_a_joint_without_a_speed_limit_takes_the_fastest_one():
    """Bravo 7's URDF gives three continuous joints no speed limit and the others 0.5 rad/s.
    Beyond reach under acceleration and jerk limits (``sjt-pin bench settle``'s draw 19), DLS
    whipped its base to 9.7 rad/s, past where the feedback sent it and back, the error rising,
    and still moved at 2.1 rad/s after 30 s. Given the fastest limit, 0.5 rad/s, it comes to
    rest (at 32 s: it leaves a saddle at those speeds); an array the user passes stays as
    given."""
    from sjt_pin.bench import settle

    robot = sjt.Robot.from_example("bravo7_no_ee", ee_frame="contact_point")
    unlimited = ~np.isfinite(robot.velocity_limits)
    assert unlimited.sum() == 3 and np.all(robot.velocity_limits[~unlimited] == 0.5)
    draw = settle.draw(robot, 19)
    assert draw.scene == "beyond" and draw.jerk is not None  # the case under test
    for given, seconds in [(True, 35.0), (robot.velocity_limits, 7.0)]:
        solver = sjt.DLSSolver(robot, task=sjt.PositionTask(), velocity_limits=given,
                               acceleration_limits=draw.acceleration, jerk_limits=draw.jerk)
        path = [draw.q0]
        for _ in range(round(seconds / solver.dt)):
            path.append(solver.step(path[-1], draw.targets[0][1]))
        speeds = np.abs(np.diff(settle.joint_angles(robot.model, np.array(path)), axis=0))
        speeds /= solver.dt
        top = speeds[:, unlimited].max()
        if given is True:
            assert top <= 0.5 * (1 + 1e-9) and speeds[-1000:].max() < 1e-6, top
        else:
            assert top > 9.0, top
