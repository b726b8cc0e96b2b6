import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt


def test_log_arrays_and_metrics(planar3):
    solver = sjt.SJTSolver(planar3, gain=300.0, dt=1e-3, task=sjt.PositionTask(axes="xy"))
    line = sjt.Line([-0.293, 0.986, 0.0], [0.507, 0.986, 0.0], duration=1.0)
    q0 = np.deg2rad([60.0, 45.0, 30.0])
    log = sjt.track(solver, line, q0)
    n = 1001
    assert (log.t.shape, log.q.shape, log.dq.shape) == ((n,), (n, 3), (n, 3))
    assert (log.position.shape, log.target.shape, log.error.shape) == ((n, 3), (n, 3), (n, 2))
    assert not log.diverged and log.reason == "" and log.method == "sjt"
    np.testing.assert_array_equal(log.q[0], q0)
    np.testing.assert_allclose(log.position[:, :2] + log.error, log.target[:, :2], atol=1e-12)
    assert log.max_error == pytest.approx(log.error_norm.max())
    assert log.rms_error <= log.max_error
    assert log.max_error < 1e-2  # high-gain SJT tracks the paper's task 1 within millimetres


def test_divergence_is_reported_not_raised(planar3):
    solver = sjt.JTSolver(planar3, gain=1e5, dt=1e-3, task=sjt.PositionTask(axes="xy"),
                          check_stability=False, velocity_limits=False)
    line = sjt.Line([-0.293, 0.986, 0.0], [0.507, 0.986, 0.0], duration=1.0)
    log = sjt.track(solver, line, np.deg2rad([60.0, 45.0, 30.0]))
    assert log.diverged and log.reason
    assert log.max_error == np.inf and log.rms_error == np.inf
    assert len(log) < 1001 and np.all(np.isfinite(log.q))


@pytest.mark.parametrize("accelerations", [None, 50.0])
def test_the_task_scale_is_logged_on_every_path(ur5, accelerations):
    """Slow speed limits scale the task down: ``solver.task_scale`` is the step's
    ``StepInfo.task_scale`` on the kernel's own path and with the compiled acceleration stage,
    and ``track()`` logs it."""
    q0 = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])
    target = ur5.fk(q0) * pin.SE3(np.eye(3), np.array([0.0, 0.2, 0.0]))
    options = dict(velocity_limits=np.full(ur5.nv, 0.2), acceleration_limits=accelerations)
    solver = sjt.SJTSolver(ur5, **options)
    q, scales = q0.copy(), []
    for _ in range(200):
        q = solver.step(q, target)
        assert solver.task_scale == solver.last.task_scale
        scales.append(solver.task_scale)
    assert min(scales) < 0.5
    log = sjt.track(sjt.SJTSolver(ur5, **options),
                    sjt.PoseInterpolation(ur5.fk(q0), target, duration=0.2), q0)
    assert log.task_scale.min() < 0.5


class _Wave(sjt.Trajectory):
    """A user's trajectory with ``sample`` only: the frame's start pose moved along y by a
    sine and turned about world z at a constant rate (the base class's ``samples``)."""

    def __init__(self, start: pin.SE3, duration: float):
        self.start, self.duration = start, duration

    def sample(self, t):
        t = min(max(t, 0.0), self.duration)
        angle, rate = 0.2 * t, 0.2 if t < self.duration else 0.0
        turn = pin.SE3(pin.utils.rotate("z", angle), np.zeros(3))
        pose = pin.SE3(turn.rotation @ self.start.rotation,
                       self.start.translation + [0.0, 0.02 * np.sin(8.0 * t), 0.0])
        velocity = [0.0, 0.16 * np.cos(8.0 * t) * (rate > 0.0), 0.0, 0.0, 0.0, rate]
        return pose, pin.Motion(np.array(velocity))


def _by_hand(solver, trajectory, q0, feedforward=True, duration=None):
    """The log that ``track`` must give, from ``step()`` called by hand on the samples."""
    times = trajectory.times(solver.dt, duration)
    positions, rotations, velocities = trajectory.samples(times)
    q, rows = q0.copy(), []
    for k in range(times.size):
        q_next = solver.step(q, pin.SE3(np.array(rotations[k]), positions[k]),
                             velocities[k] if feedforward else None)
        info = solver.last
        rows.append((q, info.dq, info.error, info.error_norm, info.task_scale,
                     info.pose.translation))
        q = q_next
    return [np.array(column) for column in zip(*rows, strict=True)]


def _assert_same(log, rows, end=None):
    columns = (log.q, log.dq, log.error, log.error_norm, log.task_scale, log.position)
    for logged, by_hand in zip(columns, rows, strict=True):
        np.testing.assert_array_equal(logged, by_hand[:end])


class _OwnPose(sjt.PoseTask):
    """A user's task (its own ``compute``): track reads its ``placement`` on every step."""

    def compute(self, kinematics, target, velocity):
        return super().compute(kinematics, target, velocity)


@pytest.mark.parametrize("case", ["circle", "no feed-forward", "posture", "user trajectory",
                                  "user task"])
def test_track_logs_bitwise_what_stepping_by_hand_gives(ur5, case):
    """Every logged row is the step's own values (``solver.last``), bitwise: the held
    orientation set once, the norms summed after the run, the configurations and poses stacked
    at the end change nothing."""
    q0 = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    start = ur5.fk(q0)
    options = dict(posture=sjt.PostureTask(weight=0.1)) if case == "posture" else {}
    if case == "user task":
        options = dict(task=_OwnPose())
    if case == "user trajectory":
        trajectory = _Wave(start, 0.6)
    elif case == "posture":  # an orientation that turns: set on every step
        trajectory = sjt.PoseInterpolation(start, start * pin.SE3(pin.utils.rotate("x", 0.3),
                                                                  np.array([0.0, 0.05, 0.02])),
                                           duration=0.6)
    else:
        trajectory = sjt.Circle(start.translation - [0.02, 0.0, 0.0], 0.02, duration=0.6,
                                rotation=start.rotation)
    feedforward = case != "no feed-forward"
    log = sjt.track(sjt.SJTSolver(ur5, **options), trajectory, q0, feedforward=feedforward)
    assert len(log) == 601 and not log.diverged
    _assert_same(log, _by_hand(sjt.SJTSolver(ur5, **options), trajectory, q0, feedforward))
    assert case == "posture" or log.max_error < 1e-3  # (and it tracks, but where a posture
    # pulls it away)


def test_track_stops_at_the_first_step_above_max_error(ur5):
    """Slow joints fall behind a fast line: the log ends at the first step whose error is
    above ``max_error`` — past the first block of steps — with the rows stepping by hand
    gives."""
    q0 = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    start = ur5.fk(q0)
    line = sjt.Line(start.translation, start.translation + [0.0, 0.5, 0.0], duration=2.0,
                    rotation=start.rotation)
    options = dict(velocity_limits=np.full(ur5.nv, 0.05))
    rows = _by_hand(sjt.SJTSolver(**options, robot=ur5), line, q0)
    limit = float(rows[3][1500])
    first = int(np.flatnonzero(rows[3] >= limit)[0])
    assert 1024 < first <= 1500  # (in a later block than the first)
    log = sjt.track(sjt.SJTSolver(ur5, **options), line, q0, max_error=limit)
    assert log.diverged and log.reason.startswith(f"error above {limit:g} at t = ")
    assert len(log) == first + 1
    _assert_same(log, rows, first + 1)


def test_displacement_is_one_array_on_every_path(ur5):
    """``solver.displacement`` is the same array after every step — the kernel's, the
    constraint stage's in Python (acceleration limits without the compiled stage) — holding
    that step's ``q_dot dt``."""
    q0 = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q0) * pin.SE3(np.eye(3), np.array([0.0, 0.1, 0.0]))
    for options in ({}, dict(acceleration_limits=5.0), dict(limits=[sjt.JointBand(0, -3, 3)])
                    if hasattr(sjt, "JointBand") else dict(velocity_limits=np.full(6, 0.1))):
        solver = sjt.SJTSolver(ur5, **options)
        buffer, q = solver.displacement, q0
        for _ in range(5):
            q = solver.step(q, target)
            assert solver.displacement is buffer
            np.testing.assert_array_equal(buffer, solver.last.dq * solver.dt)
