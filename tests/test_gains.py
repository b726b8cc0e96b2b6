"""The automatic gain: below the stability bound on random chains, and a stable loop."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import sjt_pin as sjt

from .reference import mappings
from .test_pipeline import random_chain

DT = 1e-3


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(2, 9),
       method=st.sampled_from(["sjt", "sjt transpose", "jt", "jp", "dls"]),
       position=st.booleans())
def test_auto_gain_stays_below_the_stability_bound(seed, joints, method, position):
    """k dt lambda_max(J M) <= 1 < 2 at every configuration: the bound lambda_hat the gain
    divides by is a guaranteed upper bound of lambda_max (and 1 for JP, DLS, damped SJT)."""
    robot = random_chain(seed, joints)
    rng = np.random.default_rng(seed)
    name, options = (("sjt", {"feedback": "transpose"}) if method == "sjt transpose"
                     else (method, {}))
    task = sjt.PositionTask() if position else sjt.PoseTask()
    solver = sjt.make_solver(name, robot, dt=DT, task=task, position_limits=False,
                             velocity_limits=False, **options)
    for _ in range(3):
        q = robot.random_configuration(rng)
        target = robot.fk(q) * pin.exp6(pin.Motion(rng.normal(scale=0.05, size=6)))
        solver.step(q, target.translation if position else target)
        info = solver.last
        Jw = robot.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:3] if position \
            else robot.jacobian(q)
        Jw = solver.stack.sqrt_weight[:, None] * Jw * solver.stack.chain  # [J_v; L J_w]
        if name == "sjt" and options:  # the transpose loop J D J^T
            M = mappings.sjt_matrix(Jw, length=solver.method.length)
        elif name == "jt":
            M = mappings.jt_matrix(Jw)
        else:  # JP, DLS and the damped SJT: their loop eigenvalues are at most 1
            assert info.loop_bound == 1.0
            assert info.gain * DT <= 1.0 + 1e-12
            continue
        lam = mappings.max_loop_eigenvalue(Jw, M)
        assert info.loop_bound >= lam * (1 - 1e-9)  # a guaranteed upper bound ...
        assert info.gain * DT * lam <= 1.0 + 1e-9  # ... so k dt lambda_max <= 1 < 2


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(3, 8),
       method=st.sampled_from(["sjt", "sjt transpose", "jt"]))
@example(seed=33554432, joints=3, method="sjt transpose")  # escapes that made it 60x worse
def test_the_loop_with_the_auto_gain_is_stable(seed, joints, method):
    robot = random_chain(seed, joints)
    rng = np.random.default_rng(seed)
    name, options = (("sjt", {"feedback": "transpose"}) if method == "sjt transpose"
                     else (method, {}))
    solver = sjt.make_solver(name, robot, dt=1e-2, task=sjt.PositionTask(),
                             position_limits=False, velocity_limits=False, **options)
    q = robot.random_configuration(rng)
    target = robot.fk(pin.integrate(robot.model, q, rng.normal(scale=0.05, size=robot.nv)))
    errors = []
    for _ in range(3000):
        q = solver.step(q, target.translation)
        errors.append(solver.error_norm)
        if errors[-1] < 1e-7:
            break
    errors = np.array(errors)
    assert np.all(np.isfinite(errors))
    assert errors.max() <= 1.5 * errors[0]  # stable: no growth, at most a small overshoot
    assert errors[-1] < 0.1 * errors[0] or errors[-1] < 1e-7  # and it converges


def test_a_fixed_gain_object_needs_no_row_count_but_must_fit_the_tasks(ur5):
    assert sjt.SJTSolver(ur5, gain=sjt.FixedGain(5.0)).gain == 5.0
    rows = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert list(sjt.SJTSolver(ur5, gain=sjt.FixedGain(rows)).gain) == rows
    with pytest.raises(ValueError, match="gain has 3 rows, the tasks have 6"):
        sjt.SJTSolver(ur5, gain=sjt.FixedGain([1.0, 2.0, 3.0]))
