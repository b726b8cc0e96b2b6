"""The constraint stage: every limit's bounds and rows hold after any method; saturated joints
are held and the others take over; the stage's projection is the reference QP's optimum (the
feasible velocity nearest the method's in its metric); acceleration and jerk limits hold on the
returned stream."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import nnls

import sjt_pin as sjt
from sjt_pin.bench.limits import PANDA_ACCELERATION, PANDA_JERK  # Franka's published limits
from sjt_pin.kernels import project
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


class FloorWithRoom(Floor):
    """Floor whose row also says how far a displacement may lower the hand: z - z_min."""

    def __init__(self, robot, frame, z_min, size=1):
        super().__init__(robot, frame, z_min)
        self.size = size

    def rows(self, kinematics, motion):
        self.z = kinematics.placement(self.frame_id).translation[2]
        return super().rows(kinematics, motion)

    def room(self):
        return np.full(self.size, self.z - self.z_min)


@pytest.mark.parametrize("jerk, beside", [(None, False), (5000.0, False), (None, True)])
def test_a_general_row_with_room_under_acceleration_limits_comes_to_rest(panda, jerk, beside):
    """A floor under a target below it, with Panda's acceleration (and jerk) limits: the
    hand comes to rest on the floor (at most 0.1 mm below it), within every limit; also with
    a row without room beside it (NaN in the stacked room: the row bounds velocity only)."""
    floor = FloorWithRoom(panda, "panda_hand", z_min=0.25)
    limits = [floor, Floor(panda, "panda_link5", z_min=-1.0)] if beside else [floor]
    n, dt, accel = panda.nv, 1e-3, 10.0
    smooth = {} if jerk is None else {"jerk_limits": np.full(n, jerk)}
    solver = sjt.SJTSolver(panda, task=sjt.PositionTask(), limits=limits, dt=dt,
                           acceleration_limits=np.full(n, accel), **smooth)
    q = panda.q0.copy()
    target = panda.fk(q).translation + [0.15, -0.1, -0.6]
    qs = [q]
    for _ in range(5000):
        q = solver.step(q, target)
        qs.append(q)
        assert panda.fk(q).translation[2] >= 0.25 - 1e-4
    v = np.diff(np.array(qs), axis=0) / dt
    assert np.max(np.abs(np.diff(v, axis=0)) / dt) <= accel * (1 + 1e-9)
    assert np.sqrt(np.mean(v[-1000:] ** 2)) < 1e-6  # at rest by the 4th second
    assert abs(panda.fk(q).translation[2] - 0.25) < 1e-3  # on the floor, not held above it


def test_a_room_of_the_wrong_size_is_refused_naming_its_limit(panda):
    solver = sjt.SJTSolver(panda, task=sjt.PositionTask(), dt=1e-3,
                           limits=[FloorWithRoom(panda, "panda_hand", z_min=0.0, size=2)])
    with pytest.raises(ValueError, match=r"FloorWithRoom.*room\(\) must return one value per row"):
        solver.step(panda.q0, panda.fk(panda.q0).translation)


class Lift(Floor):
    """A row asking the hand to rise at ``speed`` (m/s), within what Panda's speed limits give
    but far beyond what its acceleration limits reach in a step from rest; with ``needs``,
    the limit gives it up (its need below the bound)."""

    name = "lift"

    def __init__(self, robot, frame, speed, needs=None):
        super().__init__(robot, frame, z_min=0.0)
        self.speed, self._needs = speed, needs

    def rows(self, kinematics, motion):
        A, _ = super().rows(kinematics, motion)
        return A, np.array([-self.speed])

    def needs(self):
        return None if self._needs is None else np.asarray(self._needs, dtype=float)


@pytest.mark.parametrize("given_up", [False, True])
def test_a_row_its_limit_gives_up_never_makes_the_acceleration_limits_yield(panda, given_up):
    """A row no step within Panda's acceleration limits keeps (the hand rising at 0.5 m/s from
    rest): kept, the acceleration limits yield to it; given up (``Limit.needs`` below its
    bound), the stage asks only its best within them, the hand rises faster every step, and
    ``rows_exceeded`` measures the step against the need (0.6 m/s less the rise)."""
    n, dt = panda.nv, 1e-3
    accelerations = np.full(n, 10.0)
    limit = Lift(panda, "panda_hand", 0.5, needs=[-0.6] if given_up else None)
    solver = sjt.SJTSolver(panda, task=sjt.PositionTask(), limits=[limit], dt=dt,
                           acceleration_limits=accelerations)
    q, target = panda.q0.copy(), panda.fk(panda.q0).translation
    qs, excess = [q], []
    for _ in range(20):
        q = solver.step(q, target)
        qs.append(q)
        excess.append(dict(solver.last.rows_exceeded).get("lift", 0.0))
    v = np.diff(np.array(qs), axis=0) / dt
    worst = np.max(np.abs(np.diff(np.vstack([np.zeros(n), v]), axis=0)) / dt / accelerations)
    rise = np.diff([panda.fk(x).translation[2] for x in qs]) / dt
    if not given_up:
        assert worst > 10.0  # (the premise: a kept row makes the limits yield)
        return
    assert worst <= 1.0 + 1e-9
    assert np.all(np.diff(rise) > 0.0)  # rising faster every step: its best within them
    np.testing.assert_allclose(excess, 0.6 - rise, rtol=1e-4)


def test_needs_of_the_wrong_size_are_refused_naming_their_limit(panda):
    solver = sjt.SJTSolver(panda, task=sjt.PositionTask(), dt=1e-3,
                           limits=[Lift(panda, "panda_hand", 0.0, needs=[-1.0, -1.0])])
    with pytest.raises(ValueError, match=r"Lift.*needs\(\) must return one value per row"):
        solver.step(panda.q0, panda.fk(panda.q0).translation)


def projection_problem(rng, n, rows, equalities, task_rows):
    """A random projection whose constraints a known point meets: (xb, lam, B, lo, hi, A, b,
    C, d)."""
    inside = rng.uniform(-0.5, 0.5, n)
    lo, hi = inside - rng.uniform(0.1, 1.0, n), inside + rng.uniform(0.1, 1.0, n)
    A = rng.normal(size=(rows, n))
    b = A @ inside + rng.uniform(0.0, 0.3, rows)
    C = rng.normal(size=(equalities, n))
    d = C @ inside
    xb = rng.normal(scale=2.0, size=n)
    lam = rng.uniform(0.01, 2.0, n)
    B = rng.normal(size=(task_rows, n))
    return xb, lam, B, lo, hi, A, b, C, d


@pytest.mark.parametrize("seed", range(6))
def test_the_projection_is_the_reference_qp_s_optimum(seed):
    """min 1/2 (x - xb)^T (diag(lam) + B^T B) (x - xb) within the box, A x <= b, C x = d: the
    stage's projection meets every constraint and the QP's optimality conditions (KKT) hold
    there, over random sizes, metrics and constraints, with and without equalities."""
    rng = np.random.default_rng(seed)
    for _ in range(15):
        n = int(rng.integers(2, 9))
        args = projection_problem(rng, n, int(rng.integers(0, 6)),
                                  int(rng.integers(0, min(3, n))), int(rng.integers(0, 7)))
        xb, lam, B, lo, hi, A, b, C, d = args
        x, _, converged = project(*args)
        assert converged
        assert np.all(x >= lo - 1e-12) and np.all(x <= hi + 1e-12)
        assert np.all(A @ x <= b + 1e-9) and np.allclose(C @ x, d, atol=1e-9)
        assert kkt_residual(x, *args) <= 1e-8 * (1.0 + np.abs(xb).max())


def kkt_residual(x, xb, lam, B, lo, hi, A, b, C, d, active=1e-9):
    """How far x is from the QP's optimality conditions: the least |H (x - xb) + A_W^T nu +
    C^T eta - mu_lo + mu_hi| over multipliers of the right signs (nu, mu >= 0 on the rows and
    box sides x touches, eta free) - zero at the optimum of a convex QP, and only there."""
    n = x.size
    columns = [A[i] for i in range(len(b)) if A[i] @ x >= b[i] - active]
    columns += [c for row in C for c in (row, -row)]
    columns += [-np.eye(n)[j] for j in range(n) if x[j] <= lo[j] + active]
    columns += [np.eye(n)[j] for j in range(n) if x[j] >= hi[j] - active]
    gradient = lam * (x - xb) + B.T @ (B @ (x - xb))
    if not columns:
        return float(np.linalg.norm(gradient))
    return float(nnls(np.array(columns).T, -gradient)[1])


def test_a_feasible_step_is_returned_as_it_is():
    """Where the method's step meets every constraint, the projection returns it exactly."""
    rng = np.random.default_rng(5)
    for _ in range(30):
        n = int(rng.integers(2, 9))
        xb, lam, B, lo, hi, A, b, _, _ = projection_problem(rng, n, 3, 0, 4)
        xb = np.clip(rng.normal(scale=0.05, size=n) + 0.5 * (lo + hi), lo, hi)
        b = np.maximum(b, A @ xb)
        x, _, converged = project(xb, lam, B, lo, hi, A, b, np.zeros((0, n)), np.zeros(0))
        assert converged
        np.testing.assert_array_equal(x, xb)


def test_a_held_joint_stays_at_its_velocity_and_the_others_take_over():
    """lam = inf holds a joint at the method's velocity (clipped into its box); the task's rows
    as equalities are then met by the other joints alone."""
    rng = np.random.default_rng(8)
    for _ in range(20):
        n = 6
        J = rng.normal(size=(3, n))
        xb = rng.normal(size=n)
        lam = np.ones(n)
        lam[2] = np.inf
        lo, hi = np.full(n, -10.0), np.full(n, 10.0)
        hi[2] = 0.5 * abs(xb[2])
        x, _, converged = project(xb, lam, np.zeros((0, n)), lo, hi, np.zeros((0, n)),
                                  np.zeros(0), J, J @ xb)
        assert converged
        assert x[2] == min(xb[2], hi[2])
        np.testing.assert_allclose(J @ x, J @ xb, atol=1e-9)


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


class Push(Limit):
    """A row ``-q_dot_0 <= -speed`` (an obstacle pushing joint 0), or the same as a bound."""

    name = "push"

    def __init__(self, nv: int, speed: float, as_bound: bool):
        self.nv, self.speed, self.as_bound = nv, speed, as_bound

    def rows(self, kinematics, motion):
        if self.as_bound:
            return None
        A = np.zeros((1, self.nv))
        A[0, 0] = -1.0
        return A, np.array([-self.speed])

    def bounds(self, kinematics, motion):
        if not self.as_bound:
            return None
        lo, hi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        lo[0] = self.speed
        return lo, hi


@pytest.mark.parametrize("as_bound", [False, True])
@pytest.mark.parametrize("speed_limits", [True, False])
def test_a_row_needs_a_joint_without_a_speed_limit_faster_than_the_methods_step(
        ur5, as_bound, speed_limits):
    """At the target the method asks for nothing: the stage caps joints without a speed limit
    at the method's step while it projects, but a row (or a bound) of 0.5 rad/s still holds."""
    q = ur5.q0 + 0.3
    solver = sjt.SJTSolver(ur5, position_limits=False, velocity_limits=speed_limits,
                           limits=[Push(ur5.nv, 0.5, as_bound)])
    q_next = solver.step(q, ur5.fk(q))
    assert (q_next - q)[0] / solver.dt == pytest.approx(0.5, abs=1e-9)
    assert solver.last.rows_exceeded == ()
