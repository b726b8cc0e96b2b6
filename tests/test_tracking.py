import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt


def test_log_arrays_and_metrics(planar3):
    solver = sjt.SJTSolver(planar3, gain=300.0, dt=1e-3, task=sjt.PositionTask("xy"))
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
    solver = sjt.JTSolver(planar3, gain=1e5, dt=1e-3, task=sjt.PositionTask("xy"),
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
