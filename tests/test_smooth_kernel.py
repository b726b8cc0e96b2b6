"""The compiled acceleration/jerk stage (the step kernel's, used by a built-in method) equals
its Python reference (the constraint stage in sjt_pin/constraints.py and sjt_pin/limits, which
solvers made with ``sjt_pin.solver.COMPILED_SMOOTH_STAGE = False`` run): on random robots,
random motion states (velocities, accelerations, joints near and outside their position
limits), with and without jerk limits, for every built-in method — the same displacement,
motion state and StepInfo report."""

import pickle

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sjt_pin as sjt
import sjt_pin.kernels as K
import sjt_pin.solver as solver_module
from sjt_pin.bench.limits import PANDA_ACCELERATION, PANDA_JERK

from .test_random_urdfs import random_semantic_robot

#: each built-in method, and SJT's other updates
VARIANTS = [("sjt", {}), ("sjt", {"feedback": "transpose"}),
            ("sjt", {"feedback": "transpose", "feedforward": "transpose"}), ("jt", {}),
            ("jp", {}), ("dls", {})]


def reference_solver(method, robot, **options):
    """A solver that runs the Python stage, the compiled one's reference (the documented
    switch ``sjt_pin.solver.COMPILED_SMOOTH_STAGE``, read when a solver is made)."""
    solver_module.COMPILED_SMOOTH_STAGE = False
    try:
        return sjt.make_solver(method, robot, **options)
    finally:
        solver_module.COMPILED_SMOOTH_STAGE = True


def pair(method, robot, **options):
    """The compiled stage's solver and its Python reference, with the same options."""
    return sjt.make_solver(method, robot, **options), reference_solver(method, robot, **options)


def set_motion(solver, dq, ddq):
    """The commanded velocity and acceleration of a solver, through its copy protocol."""
    cls, args, state = solver.__reduce__()
    state = dict(state, motion=(dq, ddq))
    solver.__setstate__(state)


def assert_same_step(a, b, qa, qb, context):
    np.testing.assert_allclose(qa, qb, rtol=1e-9, atol=1e-9, err_msg=context)
    np.testing.assert_allclose(a.displacement, b.displacement, rtol=1e-9, atol=1e-12,
                               err_msg=context)
    ia, ib = a.last, b.last
    assert ia.active_limits == ib.active_limits, context
    assert ia.limit_conflicts == ib.limit_conflicts, context
    assert ia.task_scale == pytest.approx(ib.task_scale, rel=1e-9, abs=1e-12), context
    assert a.task_scale == pytest.approx(b.task_scale, rel=1e-9, abs=1e-12), context
    np.testing.assert_array_equal(ia.clamped, ib.clamped, err_msg=context)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(1, 9),
       variant=st.integers(0, len(VARIANTS) - 1), jerk=st.booleans(),
       feedforward=st.booleans())
def test_the_compiled_stage_equals_the_python_stage_on_random_robots(seed, joints, variant,
                                                                     jerk, feedforward):
    robot = random_semantic_robot(seed, joints)
    if robot is None:
        return
    rng = np.random.default_rng(seed)
    n = robot.nv
    accel = rng.uniform(1.0, 40.0, n)
    jerks = rng.uniform(200.0, 20000.0, n) if jerk else None
    if jerk and n > 1:
        jerks[rng.integers(n)] = np.inf  # a joint without a jerk limit
    method, options = VARIANTS[variant]
    a, b = pair(method, robot, dt=rng.choice([1e-3, 4e-3]), acceleration_limits=accel,
                jerk_limits=jerks, **options)
    assert a._compiled_smooth and not b._compiled_smooth  # noqa: SLF001 (the two paths)
    # a start near, at and outside the position limits, moving and accelerating
    q = robot.random_configuration(rng)
    lower, upper = robot.lower_limits, robot.upper_limits
    for i in np.flatnonzero(np.isfinite(lower) & np.isfinite(upper)):
        where = rng.integers(4)
        span = upper[i] - lower[i]
        if where == 0:
            q[i] = upper[i] - rng.uniform(0.0, 0.02) * span
        elif where == 1:
            q[i] = lower[i] - rng.uniform(0.0, 0.01) * span  # outside
    q = pin.normalize(robot.model, q)
    dq = rng.normal(size=n) * rng.uniform(0.0, 2.0)
    ddq = rng.normal(size=n) * rng.uniform(0.0, 30.0)
    set_motion(a, dq, ddq)
    set_motion(b, dq.copy(), ddq.copy())
    targets = [robot.fk(robot.random_configuration(rng)) for _ in range(2)]
    velocity = rng.normal(size=6) * 0.3 if feedforward else None
    qa, qb = q.copy(), q.copy()
    for k in range(40):
        target = targets[k // 20]
        qa, qb = a.step(qa, target, velocity), b.step(qb, target, velocity)
        assert_same_step(a, b, qa, qb, f"step {k}")
        qb = qa.copy()  # both go on from the same configuration
    state_a, state_b = a.__reduce__()[2]["motion"], b.__reduce__()[2]["motion"]
    np.testing.assert_allclose(state_a[0], state_b[0], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("method,options", VARIANTS)
@pytest.mark.parametrize("jerk", [False, True])
def test_the_compiled_stage_equals_the_python_stage_on_the_panda(panda, method, options, jerk):
    """Panda with its published limits, targets jumping (one out of reach): the same stream."""
    a, b = pair(method, panda, acceleration_limits=PANDA_ACCELERATION,
                jerk_limits=PANDA_JERK if jerk else None, **options)
    rng = np.random.default_rng(3)
    targets = [panda.fk(panda.random_configuration(rng)),
               pin.SE3(np.eye(3), np.array([1.5, 0.3, 0.9])),
               panda.fk(panda.random_configuration(rng))]
    q = panda.q0.copy()
    for k in range(600):
        qa, qb = a.step(q, targets[k // 200]), b.step(q, targets[k // 200])
        assert_same_step(a, b, qa, qb, f"step {k}")
        q = qa


def test_a_compiled_solver_copies_with_its_motion_state(panda):
    """The motion state lives in the kernel's work vector: a copy carries it, ``reset()``
    clears it."""
    solver = sjt.SJTSolver(panda, acceleration_limits=PANDA_ACCELERATION,
                           jerk_limits=PANDA_JERK)
    target = panda.fk(panda.random_configuration(np.random.default_rng(0)))
    q = panda.q0.copy()
    for _ in range(50):
        q = solver.step(q, target)
    twin = pickle.loads(pickle.dumps(solver))
    np.testing.assert_array_equal(twin.step(q, target), solver.step(q, target))
    solver.reset()
    q2 = solver.step(q, target)
    assert np.all(np.abs(q2 - q) / solver.dt <= PANDA_ACCELERATION * solver.dt * (1 + 1e-9))


@pytest.mark.parametrize("jerk", [False, True])
def test_an_arm_at_rest_reports_no_smoothness_limit(panda, jerk):
    """At rest on a held target the jerk bounds around q_dot = 0 contain the velocity but cut
    nothing: no limit is active. Moving off from rest toward a new target, they are."""
    solver = sjt.SJTSolver(panda, acceleration_limits=PANDA_ACCELERATION,
                           jerk_limits=PANDA_JERK if jerk else None)
    q = panda.q0.copy()
    target = panda.fk(q)
    for _ in range(20):
        q = solver.step(q, target)
    assert solver.last.active_limits == ()
    far = panda.fk(panda.random_configuration(np.random.default_rng(1)))
    solver.step(q, far)
    names = {name for name, _ in solver.last.active_limits}
    assert names & {"acceleration", "jerk"}


def test_a_work_vector_whose_stage_part_overlaps_the_scratch_is_refused():
    """The kernel checks the acceleration/jerk stage's part of ``work`` before it writes there:
    an offset that runs into the scratch space is a ValueError, not memory overwritten."""
    layout = K.Layout(6, 7, 0, smooth=True)
    work = layout.allocate()
    J, e, q, step = np.ones((6, 7)), np.ones(6), np.zeros(7), np.zeros(7)
    K.transpose_step(J, e, e, q, work, step)  # as laid out: accepted
    work[K.P_SMOOTH] = work[K.P_SCRATCH] - 3
    with pytest.raises(ValueError, match="work does not fit"):
        K.transpose_step(J, e, e, q, work, step)
