"""A solver's motion state (the velocity and acceleration it commanded last, which the
acceleration and jerk limits start from): a copy carries it, ``reset()`` clears it; at rest on
a held target no smoothness limit is reported active."""

import pickle

import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin.bench.limits import PANDA_ACCELERATION, PANDA_JERK


def test_a_compiled_solver_copies_with_its_motion_state(panda):
    """A copy carries the motion state (the next steps are bitwise the original's); ``reset()``
    clears it (the next step starts from rest)."""
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
