"""Far from a pose target, with joints at their ranges, an arm rests where its own error has no
feasible descent: a stationary point of ``1/2 |e_w|^2``, ``e = log6(oMf^-1 oMd)``, in the
error's exact rows ``Jlog6(N^-1) J``, not in the CLIK rows ``J`` (the error's first order near
the target only). UR10 rested where ``J^T e_w`` had no feasible descent while the error itself
still fell (first-order rate 0.56 |e_w|^2 per second; a local search from there found 0.643
for 0.657). A rate below the stage's rest rate counts as none. (Under acceleration limits the
stage still judges in the CLIK rows: see ``Controller::exact_rows``.)"""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

DT = 1e-3
#: 1/s: a step that lowers 1/2 |e_w|^2 by less than this share of |e_w|^2 per second is no
#: motion worth making (the stage's kRestRate, docs/limits.md)
REST_RATE = 1e-3
CASES = {
    "ur10_limited, no acceleration limits": (
        "ur10_limited",
        [2.3663149834363795, -0.01649465736208278, 0.16889667626315852, -0.650225137361157,
         -1.0831448872537672, 2.3191473680424766],
        [6.8793455318216146e-01, -1.4472776153517746e-04, 1.1354767404115286e-01],
        [0.06064645904384771, -0.24775191289163911, -0.5771460905268635], {}),
}


def exact_descent_rate(robot, solver, q, target):
    """The largest first-order decrease of 1/2 |e_w|^2 per second over the velocities within
    the speed limits that move no joint at its position range further out, in the error's
    exact rows; and |e_w|^2."""
    model, data = robot.model, robot.model.createData()
    N = robot.fk(q).actInv(target)
    e = pin.log6(N).vector
    J = pin.computeFrameJacobian(model, data, q, robot.ee_frame_id, pin.LOCAL)
    w = solver.stack.sqrt_weight
    e_w, X_w = w * e, w[:, None] * (pin.Jlog6(N.inverse()) @ J)
    g = X_w.T @ e_w  # d/dt 1/2 |e_w|^2 = -g . v
    lo, hi = -robot.velocity_limits, robot.velocity_limits.copy()
    hi[q >= robot.upper_limits - 1e-9] = 0.0
    lo[q <= robot.lower_limits + 1e-9] = 0.0
    return float(np.sum(np.maximum(g * hi, g * lo))), float(e_w @ e_w)


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("method", ["dls", "sjt"])
def test_an_arm_rests_only_where_its_error_has_no_feasible_descent(case, method):
    name, q0, translation, rotation, limits = CASES[case]
    robot = sjt.Robot.from_example(name)
    target = pin.SE3(pin.exp3(np.array(rotation)), np.array(translation))
    solver = sjt.make_solver(method, robot, dt=DT, **limits)
    q = np.array(q0)
    speeds = []
    for _ in range(10000):
        q_next = solver.step(q, target)
        speeds.append(np.abs(q_next - q).max() / DT)
        q = q_next
    assert max(speeds[-1000:]) < 1e-6  # at rest
    rate, e2 = exact_descent_rate(robot, solver, q, target)
    assert e2 > 1e-2  # (out of reach: a rest against the ranges)
    # (the stage rests where a step lowers it by less than twice its rest rate: kRestRate)
    assert rate <= 2 * REST_RATE * e2, (rate, e2)
