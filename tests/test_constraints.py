"""The constraint stage: every limit's bounds and rows hold after any method; saturated joints
are held and the others take over; an infeasible task is scaled along its direction; the
stage agrees with a reference QP; acceleration and jerk limits hold on the returned stream."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import minimize

import sjt_pin as sjt
from sjt_pin.bench.limits import PANDA_ACCELERATION, PANDA_JERK  # Franka's published limits
from sjt_pin.constraints import project, rest_target, saturate
from sjt_pin.limits import Limit
from sjt_pin.methods import Method


class Pinv(Method):
    """A method of a user's own: only its matrix."""

    name = "pinv"

    def matrix(self, J):
        return np.linalg.pinv(J, rcond=1e-10)


class JointBand(Limit):
    name = "band"

    def __init__(self, robot, joint, lower, upper):
        j = robot.model.joints[robot.model.getJointId(joint)]
        self.iq, self.iv, self.nv = j.idx_q, j.idx_v, robot.nv
        self.lower, self.upper = lower, upper

    def bounds(self, kinematics, motion):
        lo, hi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        x = motion.q[self.iq]
        lo[self.iv], hi[self.iv] = (self.lower - x) / motion.dt, (self.upper - x) / motion.dt
        return lo, hi


class Floor(Limit):
    """A frame's origin stays above ``z_min`` (m): ``z_dot >= -gain (z - z_min) / dt``."""

    name = "floor"

    def __init__(self, robot, frame, z_min, gain=0.5):
        self.frame_id, self.z_min, self.gain = robot.frame_id(frame), z_min, gain

    def rows(self, kinematics, motion):
        z = kinematics.placement(self.frame_id).translation[2]
        J_z = kinematics.world_aligned_jacobian(self.frame_id)[2]
        return -J_z[None, :], np.array([self.gain * (z - self.z_min) / motion.dt])


def pinv_solve(J, xdot):
    """The pseudoinverse's re-solve on the free joints, the held ones at their velocities."""

    def solve(free, held):
        held = np.zeros(J.shape[1]) if held is None else held
        out = np.zeros(J.shape[1])
        out[free] = np.linalg.pinv(J[:, free]) @ (xdot - J @ held)
        return out

    return solve


def qp(objective, gradient, x0, lower, upper, **constraint):
    """scipy's SLSQP on a box and one block of constraints, to tight tolerance."""
    return minimize(objective, x0, jac=gradient, method="SLSQP",
                    bounds=list(zip(lower, upper, strict=True)), constraints=[constraint],
                    options={"ftol": 1e-14, "maxiter": 500})


def test_a_method_of_ones_own_keeps_the_urdf_limits(ur5):
    q = np.array([0.3, -1.2, 3.0, -1.8, -1.5, 0.2])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.08]))  # elbow outward
    solver = sjt.Solver(ur5, Pinv(), task=sjt.PositionTask())
    for _ in range(2000):
        q = solver.step(q, target.translation)
        assert ur5.lower_limits[2] <= q[2] <= ur5.upper_limits[2]
        assert np.all(np.abs(solver.last.dq) <= ur5.velocity_limits * (1 + 1e-12))
    assert solver.error_norm < 1e-6  # the other joints reached it


def test_solve_honours_the_limits_step_honours(ur5):
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    band = JointBand(ur5, "elbow_joint", 0.5, 1.53)
    solver = sjt.SJTSolver(ur5, task=sjt.PositionTask(), limits=[band])
    target = ur5.fk(q).translation + [-0.15, 0.0, 0.0]  # without the band: elbow at 1.578
    for _ in range(3000):
        q = solver.step(q, target)
        assert q[2] <= 1.53 + 1e-12
    assert solver.error_norm < 1e-6
    result = solver.solve(target, np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2]))
    assert result.success and result.q[2] <= 1.53 + 1e-9
    free = sjt.SJTSolver(ur5, task=sjt.PositionTask()).solve(target, result.q * 0 + q)
    assert free.success


def test_a_general_row_limit_in_step_and_solve(panda):
    """A floor under the hand: the rows come from the step's kinematics."""
    floor = Floor(panda, "panda_hand", z_min=0.25)
    solver = sjt.SJTSolver(panda, task=sjt.PositionTask(), limits=[floor])
    q = panda.q0.copy()
    start = panda.fk(q).translation
    target = start + [0.1, 0.0, -0.6]  # below the floor
    low = np.inf
    for _ in range(6000):
        q = solver.step(q, target)
        low = min(low, panda.fk(q).translation[2])
    assert low >= 0.25 - 1e-5  # first order: the row is linear in q_dot
    assert "floor" in solver.last.active_rows
    assert np.linalg.norm(solver.last.dq) < 1e-3  # at rest against the floor
    reachable = start + [0.1, 0.05, -0.1]
    result = solver.solve(reachable, panda.q0)
    assert result.success and panda.fk(result.q).translation[2] >= 0.25 - 1e-9


def test_the_stage_equals_a_reference_qp_where_one_joint_saturates():
    """With the pseudoinverse and one joint over its bound, Saturation in the Null Space gives
    the minimum-norm joint velocity that meets the task within the box: the QP's solution."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(40):
        J = rng.normal(size=(3, 7))
        xdot = rng.normal(size=3)
        dq0 = np.linalg.pinv(J) @ xdot
        k = int(np.argmax(np.abs(dq0)))
        lower, upper = np.full(7, -10.0), np.full(7, 10.0)
        if dq0[k] > 0:
            upper[k] = 0.5 * dq0[k]
        else:
            lower[k] = 0.5 * dq0[k]

        outcome = saturate(dq0, pinv_solve(J, xdot), lower, upper, np.ones(7, dtype=bool),
                           lambda J=J: J)
        reference = qp(lambda x: x @ x, lambda x: 2 * x, dq0, lower, upper, type="eq",
                       fun=lambda x, J=J, xdot=xdot: J @ x - xdot, jac=lambda x, J=J: J)
        if not (reference.success and np.all(np.abs(reference.x) < 9.9)):
            continue  # another bound became active: not the case under test
        assert outcome.scale == 1.0
        np.testing.assert_allclose(J @ outcome.dq, xdot, atol=1e-9)  # the task is kept
        np.testing.assert_allclose(outcome.dq, reference.x, atol=1e-5)
        checked += 1
    assert checked >= 20


def test_an_infeasible_task_is_scaled_along_its_direction():
    rng = np.random.default_rng(3)
    for _ in range(30):
        J = rng.normal(size=(3, 5))
        xdot = rng.normal(size=3) * 10
        dq0 = np.linalg.pinv(J) @ xdot
        lower, upper = np.full(5, -1.0), np.full(5, 1.0)

        outcome = saturate(dq0, pinv_solve(J, xdot), lower, upper, np.ones(5, dtype=bool),
                           lambda J=J: J)
        assert np.all(outcome.dq >= lower - 1e-12) and np.all(outcome.dq <= upper + 1e-12)
        made = J @ outcome.dq
        if outcome.scale < 1:
            np.testing.assert_allclose(made, outcome.scale * xdot, atol=1e-9)  # not distorted


def test_the_row_projection_meets_every_row_at_least_cost():
    rng = np.random.default_rng(4)
    for _ in range(30):
        n = 6
        Jw = rng.normal(size=(4, n))
        A, b = rng.normal(size=(3, n)), rng.uniform(0.0, 0.5, 3)
        dq = rng.normal(size=n)
        lower, upper = np.full(n, -2.0), np.full(n, 2.0)
        out = project(dq, Jw, A, b, lower, upper, np.ones(n, dtype=bool))
        assert np.all(A @ out <= b + 1e-9) and np.all(np.abs(out) <= 2 + 1e-12)
        H = Jw.T @ Jw
        H += np.trace(H) / n * np.eye(n)

        def least(start, H=H, A=A, b=b, n=n, lower=lower, upper=upper):
            return qp(lambda v: (v - start) @ H @ (v - start), lambda v: 2 * H @ (v - start),
                      np.zeros(n), lower, upper, type="ineq", fun=lambda v: b - A @ v,
                      jac=lambda v: -A)

        ref = least(dq)
        # a corrected step starts again from dq with its self-motion scaled (rest_target)
        target = rest_target(dq, ref.x, Jw, np.ones(n, dtype=bool))
        if target is not None and not np.all(A @ dq <= b):
            dq = target
            ref = least(dq)
        cost = (out - dq) @ H @ (out - dq)
        assert cost <= (ref.x - dq) @ H @ (ref.x - dq) + 1e-7


def test_tiago_holds_its_slow_torso_and_the_arm_takes_over():
    """TIAGo's torso lift allows 0.07 m/s; a 15 cm circle that needs 0.14 m/s of it is still
    tracked by the arm within every limit."""
    tiago = sjt.Robot.from_example("tiago_no_hand", ee_frame="arm_tool_link")
    q0 = tiago.q0.copy()
    q0[:8] = [0.201, 1.436, 0.208, -1.368, 1.266, 0.445, -0.493, -0.092]
    start = tiago.fk(q0)
    around = sjt.Circle(start.translation, 0.075, 3.0, normal=[1, 0, 0], rotation=start.rotation)
    first, _ = around.sample(0.0)
    circle = sjt.Circle(2 * start.translation - first.translation, 0.075, 3.0, normal=[1, 0, 0],
                        rotation=start.rotation)
    for name in ["sjt", "dls"]:
        log = sjt.track(sjt.make_solver(name, tiago), circle, q0)
        assert log.max_error < 1e-5, name
        assert np.all(np.abs(log.dq) <= tiago.velocity_limits * (1 + 1e-9))
        assert np.abs(log.dq[:, 0]).max() == pytest.approx(0.07)  # the torso at its limit


def test_franka_conditions_acceleration_and_jerk_limits_hold_on_the_stream(panda):
    """Targets jumping every 0.5 s (one out of reach), then held: the finite differences of
    the returned q stay within the position, speed, acceleration and jerk limits; the arm
    reaches the last target and comes to rest."""
    dt = 1e-3
    solver = sjt.SJTSolver(panda, dt=dt, acceleration_limits=PANDA_ACCELERATION,
                           jerk_limits=PANDA_JERK)
    rng = np.random.default_rng(11)
    q = panda.q0.copy()
    qs = [q]
    near = panda.q0 + np.r_[rng.uniform(-0.3, 0.3, 7), 0]  # the fingers: one coordinate
    targets = [panda.fk(panda.random_configuration(rng)),
               pin.SE3(np.eye(3), np.array([1.5, 0.3, 0.9])),  # out of reach
               panda.fk(np.clip(near, panda.lower_limits, panda.upper_limits))]
    for target, steps in zip(targets, [500, 500, 3000], strict=True):
        for _ in range(steps):
            q = solver.step(q, target)
            qs.append(q)
    qs = np.array(qs)
    v = np.diff(qs, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    j = np.diff(a, axis=0) / dt
    assert np.all(qs >= panda.lower_limits) and np.all(qs <= panda.upper_limits)
    assert np.all(np.abs(v) <= panda.velocity_limits * 1.01)
    assert np.all(np.abs(a) <= PANDA_ACCELERATION * 1.01)
    assert np.all(np.abs(j) <= PANDA_JERK * 1.01)
    assert np.abs(v[0]).max() <= PANDA_ACCELERATION.max() * dt  # it starts from rest
    assert solver.error_norm < 1e-3
    assert np.sqrt(np.mean(v[-500:] ** 2)) < 1e-3  # and ends at rest
    solver.reset()
    q2 = solver.step(q, targets[0])
    assert np.all(np.abs(q2 - q) / dt <= PANDA_ACCELERATION * dt * 1.0001)  # from rest again


def test_the_dual_qp_of_a_degenerate_step_is_finite_and_optimal():
    """The dual QP of a Panda self-collision step on its meshes (18 rows, Q singular, one row no
    motion can change, broken) once made y NaN — a 0/0 step ratio — and then stalled on that row, so
    the correction vanished. Its answer is finite and optimal on every row that motion can
    change: the KKT conditions of min 1/2 y^T Q y + r^T y over y >= 0 hold there (gradient >= 0,
    and 0 where y > 0); the inert row keeps y = 0."""
    from pathlib import Path

    from sjt_pin.constraints import nonnegative_qp

    data = np.load(Path(__file__).parent / "fixtures" / "qp" / "degenerate_panda_meshes.npz")
    Q, r = data["Q"], data["r"]
    with np.errstate(all="raise"):
        y = nonnegative_qp(Q, r)
    assert np.all(np.isfinite(y)) and np.all(y >= 0)
    inert = np.diag(Q) <= 1e-14 * np.diag(Q).max()
    assert np.any(r[inert] < 0) and np.all(y[inert] == 0)  # one broken, nothing to move it
    gradient = (Q @ y + r)[~inert]
    scale = 1e-9 * (1.0 + np.abs(r).max())
    assert np.all(gradient >= -scale)
    assert np.all(np.abs(gradient[y[~inert] > 1e-12]) <= scale)


def test_a_step_whose_task_motion_the_rows_stop_keeps_none_of_its_self_motion():
    """Rows that forbid every task motion (``Jw x = 0``): the least-cost point from ``dq`` would
    be ``dq``'s self-motion, on which a blocked arm drifts in its null space; the projection
    starts again from ``dq`` with its self-motion scaled by the share of task motion kept (none)
    and returns rest. A step the rows do not cut keeps its self-motion exactly."""
    rng = np.random.default_rng(21)
    for _ in range(20):
        Jw = rng.normal(size=(2, 5))
        null = np.linalg.svd(Jw)[2][2:].T  # a basis of Jw's null space
        dq = Jw.T @ rng.normal(size=2) + null @ rng.normal(size=3)
        A, b = np.vstack([Jw, -Jw]), np.zeros(4)
        lower, upper = np.full(5, -10.0), np.full(5, 10.0)
        out = project(dq, Jw, A, b, lower, upper, np.ones(5, dtype=bool))
        np.testing.assert_allclose(out, 0.0, atol=1e-9)
        free = null @ rng.normal(size=3)  # self-motion alone meets the rows: untouched
        np.testing.assert_array_equal(project(free, Jw, A, b, lower, upper,
                                              np.ones(5, dtype=bool)), free)
