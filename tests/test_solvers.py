"""CLIK solvers: convergence, singular starts, feed-forward, unreachable targets, gain checks."""

import warnings

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .helpers import regulate
from .reference import mappings

METHODS = ["sjt", "jt", "jp", "dls"]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_set_point_regulation_converges_from_nearby_pose(method, name, rng):
    """From 0.1 rad per joint away, at goals where sigma_min(J) > 0.1 (transpose-type updates
    converge at the rate of the smallest loop eigenvalue, so near-singular goals take longer)."""
    robot = sjt.Robot.from_example(name)
    goals = 0
    while goals < 3:
        q_goal = robot.random_configuration(rng)
        if np.linalg.svd(robot.jacobian(q_goal), compute_uv=False)[5] < 0.1:
            continue
        goals += 1
        target = robot.fk(q_goal)
        q = q_goal + rng.uniform(-0.1, 0.1, robot.nq)
        solver = sjt.make_solver(method, robot, gain="auto", dt=0.01)
        q = regulate(solver, q, target, 20_000)
        final = pin.log6(robot.fk(q).actInv(target)).vector
        assert np.linalg.norm(final) < 1e-6


def ur5_roll_about_lost_axis(ur5, angle=0.2):
    """A target that UR5 at q = 0 (wrist and elbow singular) can only reach through a saddle."""
    q = np.zeros(6)
    U = np.linalg.svd(ur5.jacobian(q))[0]
    assert np.linalg.svd(ur5.jacobian(q), compute_uv=False)[-1] < 1e-12  # exactly singular
    return q, ur5.fk(q) * pin.exp6(pin.Motion(angle * U[:, -1]))


@pytest.mark.parametrize("method, options", [("sjt", {"feedback": "transpose"}), ("jt", {})])
def test_transpose_feedback_never_leaves_an_exact_saddle_without_the_escape(ur5, method, options):
    q0, target = ur5_roll_about_lost_axis(ur5)
    stuck = sjt.make_solver(method, ur5, dt=0.01, escape=False, **options)
    regulate(stuck, q0, target, 2000)
    assert stuck.last.error_norm == pytest.approx(0.2)  # J^T e = 0: it never moves


@pytest.mark.parametrize("method, gain", [("sjt", "auto"), ("jt", 20.0)])
def test_transpose_methods_converge_from_stretched_panda(panda, method, gain):
    q_stretched = np.zeros(panda.nq)  # joint 4 at 0: upper arm and forearm aligned
    assert np.linalg.svd(panda.jacobian(q_stretched), compute_uv=False)[5] < 1e-12
    target = panda.fk(panda.q0)
    # q4 = 0 lies beyond joint 4's URDF limit (-0.07 rad): the bare method, without limits
    solver = sjt.make_solver(method, panda, gain=gain, dt=0.01, position_limits=False)
    q = regulate(solver, q_stretched, target, 20_000)
    assert np.all(np.isfinite(q))
    assert solver.last.error_norm < 1e-6


def away_from_singularities(ur5):
    q0 = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    assert np.linalg.svd(ur5.jacobian(q0), compute_uv=False)[-1] > 0.05
    return q0, ur5.fk(q0)


def test_feedforward_makes_jp_track_ten_times_better(ur5):
    q0, T0 = away_from_singularities(ur5)
    radius = 0.1
    circle = sjt.Circle(T0.translation - [radius, 0, 0], radius, duration=2.0,
                        rotation=T0.rotation)
    with_ff = sjt.track(sjt.JPSolver(ur5, gain=10.0, dt=1e-3), circle, q0)
    without = sjt.track(sjt.JPSolver(ur5, gain=10.0, dt=1e-3), circle, q0, feedforward=False)
    assert not with_ff.diverged and not without.diverged
    assert with_ff.max_error * 10 < without.max_error
    speed = 2 * np.pi * radius / circle.duration
    assert without.max_error == pytest.approx(speed / 10.0, rel=0.1)  # lag = speed / gain


def test_unreachable_target_sjt_bounded_jp_reports_divergence(ur5):
    q0, T0 = away_from_singularities(ur5)
    p0 = T0.translation
    far = p0 + 1.5 * p0 / np.linalg.norm(p0)  # 1.5 m beyond: outside UR5's reach
    line = sjt.Line(p0, far, duration=1.0, rotation=T0.rotation)
    sjt_log = sjt.track(sjt.SJTSolver(ur5, gain="auto", dt=1e-3), line, q0, duration=3.0)
    assert not sjt_log.diverged
    assert np.all(np.isfinite(sjt_log.q))
    assert sjt_log.error_norm[-1] <= np.linalg.norm(far - p0) + 0.1  # pulled toward the goal
    # the bare method: UR5's URDF speed limits would otherwise cap JP's blow-up, and its
    # error's Levenberg-Marquardt damping would hold it back (error_damping=0: the textbook J^+)
    jp = sjt.JPSolver(ur5, gain=10.0, dt=1e-3, velocity_limits=False, error_damping=0.0)
    jp_log = sjt.track(jp, line, q0, duration=3.0)
    assert jp_log.diverged and "one step" in jp_log.reason
    assert len(jp_log) < 3001


def test_step_does_not_mutate_and_accepts_matrix_targets(ur5):
    q, T = away_from_singularities(ur5)
    q_copy = q.copy()
    target = T * pin.SE3(np.eye(3), np.array([0.01, 0.0, 0.0]))
    solver = sjt.SJTSolver(ur5, gain=50.0, dt=0.01)
    a = solver.step(q, target)
    b = solver.step(q, target.homogeneous)
    np.testing.assert_array_equal(q, q_copy)
    np.testing.assert_allclose(a, b)
    assert solver.last.dq.shape == (6,) and solver.last.alpha.shape == (6,)


def test_sjt_alpha_uses_the_weighted_task_rows(planar3, rng):
    weight = np.array([4.0, 0.25])
    solver = sjt.SJTSolver(planar3, gain=10.0, dt=1e-3,
                           task=sjt.PositionTask(axes="xy", weight=weight))
    q = rng.uniform(-1, 1, 3)
    solver.step(q, [0.5, 0.5, 0.0])
    J = pin.computeFrameJacobian(planar3.model, planar3.data, q, planar3.ee_frame_id,
                                 pin.LOCAL_WORLD_ALIGNED)[:2]
    expected = 1 / np.einsum("ij,i,ij->j", J, weight, J)
    np.testing.assert_allclose(solver.last.alpha, expected)


@pytest.mark.parametrize("feedback", ["transpose", "damped"])
def test_gain_above_the_stability_bound_warns_once(planar3, feedback):
    q = np.deg2rad([60.0, 45.0, 30.0])
    dt = 1e-3
    solver = sjt.SJTSolver(planar3, gain=1.0, dt=dt, task=sjt.PositionTask(axes="xy"),
                           feedback=feedback)
    solver.step(q, [0.0, 1.0, 0.0])
    Jw = planar3.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:2]
    if feedback == "transpose":
        bound = mappings.stable_gain_bound(Jw, solver.method.matrix(Jw), dt)
        assert 2 / (3 * dt) < bound  # the SJT bound 2 / (n dt) holds everywhere
    else:  # the damped loop's eigenvalues are below 1, so 2 / dt is the bound
        assert solver.method.bound(3) == 1.0
        bound = 2 / dt
    solver.gain = 0.99 * bound
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver.step(q, [0.0, 1.0, 0.0])
    if feedback == "damped":  # the bound quoted is the damped loop's: just above 2 / dt
        Jw = planar3.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:2]
        bound = mappings.stable_gain_bound(Jw, solver.method.matrix(Jw), dt)
        assert 2 / dt < bound < 2.01 / dt
    solver.gain = 1.01 * bound
    with pytest.warns(sjt.GainWarning, match=f"{bound:.4g}") as caught:
        solver.step(q, [0.0, 1.0, 0.0])
    assert caught[0].filename == __file__  # the warning points at the caller of step()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver.step(q, [0.0, 1.0, 0.0])  # once per solver


def test_auto_gain(panda):
    dt = 2e-3
    solver = sjt.SJTSolver(panda, dt=dt)
    solver.step(panda.q0, panda.fk(panda.q0))
    assert np.count_nonzero(solver.last.alpha) == 7  # the fingers do not move panda_hand
    assert solver.last.gain == pytest.approx(1 / dt)  # damped SJT: loop eigenvalues below 1
    transpose = sjt.SJTSolver(panda, dt=dt, feedback="transpose")
    transpose.step(panda.q0, panda.fk(panda.q0) * pin.SE3(np.eye(3), np.array([0.01, 0, 0])))
    Jw = transpose.stack.sqrt_weight[:, None] * panda.jacobian(panda.q0)[:, :7]  # [J_v; L J_w]
    lam = np.linalg.eigvalsh(Jw @ transpose.method.matrix(Jw))[-1]
    info = transpose.last
    assert lam <= info.loop_bound <= 1.25 * lam  # a guaranteed, tight upper bound
    assert info.gain == pytest.approx(1 / (dt * info.loop_bound))
    assert 2 / (7 * dt) < 2 / (dt * info.loop_bound)  # above the configuration-free bound


def test_per_row_gains_set_per_row_rates(planar3):
    """With JP the loop is e_dot = -K e: each row decays at its own gain (the textbook J^+:
    the error's Levenberg-Marquardt damping would slow the rows while the error is large)."""
    gains = np.array([5.0, 50.0])
    solver = sjt.JPSolver(planar3, gain=gains, dt=1e-3, task=sjt.PositionTask(axes="xy"),
                          error_damping=0.0)
    q = np.deg2rad([60.0, 45.0, 30.0])
    target = [-0.25, 0.95, 0.0]
    solver.step(q, target)
    e0 = solver.last.error
    for _ in range(100):
        q = solver.step(q, target)
    np.testing.assert_allclose(solver.last.error / e0, (1 - gains * 1e-3) ** 100, rtol=0.05)


@pytest.mark.parametrize("method", METHODS)
def test_per_row_gains_converge(method, planar3):
    solver = sjt.make_solver(method, planar3, gain=[5.0, 50.0], dt=1e-2,
                             task=sjt.PositionTask(axes="xy"))
    regulate(solver, np.deg2rad([60.0, 45.0, 30.0]), [-0.2, 0.9, 0.0], 5000)
    assert solver.last.error_norm < 1e-6


def test_make_solver_names_and_options(ur5):
    assert isinstance(sjt.make_solver("SJT", ur5), sjt.SJTSolver)
    assert sjt.make_solver("dls", ur5, damping=0.2).damping == 0.2
    with pytest.raises(ValueError, match="one of"):
        sjt.make_solver("newton", ur5)


def test_every_common_option_is_declared_once(ur5):
    """SolverOptions is the one place a common option lives: each field is documented there,
    every public solver's documentation carries it and takes it, copies keep it, and an
    unknown name is refused naming the solver."""
    import copy
    import dataclasses

    names = [field.name for field in dataclasses.fields(sjt.SolverOptions)]
    assert {"gain", "dt", "task", "posture", "limits", "acceleration_limits"} <= set(names)
    for name in names:
        assert f"\n        {name}:" in sjt.SolverOptions.__doc__
    for cls in sjt.solvers.SOLVERS.values():
        for name in names:
            assert f"\n        {name}:" in cls.__doc__
        solver = cls(ur5, dt=2e-3, check_stability=False, velocity_limits=False)
        assert solver.options.dt == 2e-3 and solver.options.velocity_limits is False
        twin = copy.deepcopy(solver)
        assert twin.options.dt == 2e-3 and twin.options.check_stability is False
        with pytest.raises(TypeError, match=rf"{cls.__name__}.*\['dtt'\]"):
            cls(ur5, dtt=1e-3)
