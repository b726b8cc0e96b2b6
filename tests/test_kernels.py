"""The compiled kernels agree with the numpy reference formulas of ``mappings`` and Pinocchio."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sjt_pin import kernels as K

from .reference import mappings

DT = 1e-3


def problem(seed, m, n):
    """Random rows with some masked joints, weights and per-row gains."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, n))
    mask = (rng.random(n) > 0.25).astype(float)
    e, ff = rng.normal(size=m), rng.normal(size=m)
    rows = np.vstack([rng.uniform(0.5, 2.0, m), rng.uniform(1.0, 3.0, m)])  # sqrt(w), K
    return J, e, ff, rows, mask


def run(kernel, J, e, ff, rows, mask, **params):
    m, n = J.shape
    layout = K.Layout(m, n, 0)
    work = layout.allocate()
    layout.sqrt_weight(work)[:], layout.gains(work)[:] = rows
    layout.joint_mask(work)[:] = mask
    work[K.P_DT] = DT
    work[K.P_ERROR_ROWS] = m
    work[K.P_STALL_RATIO] = -1.0
    if params.get("ff_mode"):  # 0: no desired velocity in this step
        work[K.P_HAS_FF] = 1.0
    for name, value in params.items():
        work[getattr(K, "P_" + name.upper())] = value
    step = np.full(n, np.nan)
    status = kernel(J, e, ff, np.zeros(n), work, step)
    assert status == 0  # no limits here: nothing clamped or scaled
    return step, layout.info(work)


shapes = dict(m=st.integers(1, 8), n=st.integers(1, 10), seed=st.integers(0, 2**32 - 1))


@settings(max_examples=80, deadline=None)
@given(**shapes, scaled=st.booleans(), ff_mode=st.sampled_from([0, 1, 2]),
       length=st.sampled_from([0.0, 0.5]))
def test_transpose_step_is_the_reference_mapping(m, n, seed, scaled, ff_mode, length):
    J, e, ff, rows, mask = problem(seed, m, n)
    J[:, 0] *= 1e-7  # a column below column_tol: alpha = 0
    step, info = run(K.transpose_step, J, e, ff, rows, mask, scaled=float(scaled),
                     ff_mode=ff_mode, mu=0.01, col_tol=mappings.COLUMN_TOL,
                     length2=length**2)
    sw, k = rows
    Jw = sw[:, None] * J * mask
    alpha = mappings.scaling_factors(Jw, mappings.COLUMN_TOL, length)
    S = alpha if scaled else mask * (np.einsum("ij,ij->j", Jw, Jw) > 0)
    expected = DT * S * (Jw.T @ (k * sw * e))  # fixed gain: S J_w^T K e_w
    if ff_mode == K.FF_TRANSPOSE:
        expected += DT * S * (Jw.T @ (sw * ff))
    elif ff_mode == K.FF_DAMPED:
        A = Jw @ np.diag(alpha) @ Jw.T
        expected += DT * alpha * (Jw.T @ np.linalg.solve(A + 1e-4 * np.eye(m), sw * ff))
    np.testing.assert_allclose(step, expected, rtol=1e-9, atol=1e-12)
    assert info[K.I_E_SQ] == pytest.approx(e @ e)
    assert info[K.I_TRACE] == pytest.approx(np.sum(S * np.einsum("ij,ij->j", Jw, Jw)))


@settings(max_examples=60, deadline=None)
@given(**shapes)
def test_damped_feedback_is_the_damped_solve_of_the_whole_velocity(m, n, seed):
    J, e, ff, rows, mask = problem(seed, m, n)
    c = 0.8
    step, info = run(K.transpose_step, J, e, ff, rows, mask, scaled=1.0, ff_mode=K.FF_DAMPED,
                     mu=0.01, col_tol=mappings.COLUMN_TOL, fb_mode=K.FB_DAMPED, lm=1.0,
                     gain_mode=K.GAIN_AUTO, gain_arg=c)
    sw, k = rows
    Jw = sw[:, None] * J * mask
    alpha = mappings.scaling_factors(Jw)
    A = Jw @ np.diag(alpha) @ Jw.T
    damping = 1e-4 + np.sqrt(np.sum((sw * e) ** 2) * alpha.max())  # mu^2 + |e_w| sqrt(alpha)
    v = sw * (ff + c / DT * k * e)
    expected = DT * alpha * (Jw.T @ np.linalg.solve(A + damping * np.eye(m), v))
    np.testing.assert_allclose(step, expected, rtol=1e-8, atol=1e-12)
    assert info[K.I_GAIN] == pytest.approx(c / DT)


@settings(max_examples=60, deadline=None)
@given(**shapes, damping=st.sampled_from([0.0, 0.05, 1.0]), lm=st.sampled_from([0.0, 0.3]))
def test_least_squares_step_is_jp_or_dls(m, n, seed, damping, lm):
    J, e, ff, rows, mask = problem(seed, m, n)
    step, _ = run(K.least_squares_step, J, e, ff, rows, mask, ff_mode=1, mu=damping,
                  rcond=mappings.JP_RCOND, lm=lm)
    sw, k = rows
    Jw = sw[:, None] * J * mask
    v = sw * ff + k * sw * e
    error = lm * np.linalg.norm(sw * e)  # the Levenberg-Marquardt term w L |e_w|
    expected = (mappings.dls_matrix(Jw, damping, error) if damping
                else mappings.jp_matrix(Jw, mappings.JP_RCOND, error)) @ v
    np.testing.assert_allclose(step, DT * expected, rtol=1e-7, atol=1e-10)


def test_least_squares_drops_exactly_lost_directions():
    J = np.array([[1.0, 1.0], [0.0, 0.0]])  # row 2 lost
    rows = np.ones((2, 2))
    step, _ = run(K.least_squares_step, J, np.array([1.0, 1.0]), np.zeros(2), rows,
                  np.ones(2), rcond=mappings.JP_RCOND)
    np.testing.assert_allclose(step, DT * np.array([0.5, 0.5]))
    # damped by the error, the pseudoinverse still drops the lost row: (J J^T + d)^-1 on the
    # kept one, d = lm |e_w| = 0.5 sqrt(2)
    step, _ = run(K.least_squares_step, J, np.array([1.0, 1.0]), np.zeros(2), rows,
                  np.ones(2), rcond=mappings.JP_RCOND, lm=0.5)
    np.testing.assert_allclose(step, DT * np.array([1.0, 1.0]) / (2.0 + 0.5 * np.sqrt(2.0)))


@settings(max_examples=80, deadline=None)
@given(p=st.integers(1, 9), rank=st.integers(0, 9), seed=st.integers(0, 2**32 - 1),
       products=st.integers(0, 3))
def test_loop_bound_is_a_guaranteed_upper_bound(p, rank, seed, products):
    rng = np.random.default_rng(seed)
    rank = min(rank, p)
    B = rng.normal(size=(p, rank)) * rng.uniform(0.01, 3.0, rank)
    A = B @ B.T
    lam = np.linalg.eigvalsh(A)[-1] if rank else 0.0
    bound = K.loop_bound(A.copy(), products, np.empty((p, p)), np.empty((p, p)))
    assert bound >= lam * (1 - 1e-10)
    assert bound <= max(rank, 1) ** (1 / 2 ** (products + 1)) * lam * (1 + 1e-10) + 1e-300


@settings(max_examples=40, deadline=None)
@given(p=st.integers(1, 8), seed=st.integers(0, 2**32 - 1))
def test_small_dense_algebra(p, seed):
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(p, p))
    A = B @ B.T
    rhs = rng.normal(size=p)
    out = np.empty(p)
    assert K.cholesky_solve(A.copy(), 0.1, rhs, out)
    np.testing.assert_allclose(out, np.linalg.solve(A + 0.1 * np.eye(p), rhs), rtol=1e-8)
    D, V = A.copy(), np.empty((p, p))
    K.symmetric_eigen(D, V)
    np.testing.assert_allclose(np.sort(np.diag(D)), np.linalg.eigvalsh(A), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(V @ np.diag(np.diag(D)) @ V.T, A, atol=1e-9)


def test_frame_velocity_is_the_twist_seen_from_the_frame(rng):
    oMf, oMd = pin.SE3.Random(), pin.SE3.Random()
    velocity = rng.normal(size=6)  # [p_dot_d, omega_d], world axes at the desired origin
    out = np.empty(6)
    K.frame_velocity(oMf.np, oMd.np, velocity, out)
    # the same twist with Pinocchio: world axes at the desired origin -> LOCAL axes of f
    at_desired = pin.SE3(np.eye(3), oMd.translation)
    expected = oMf.actInv(at_desired.act(pin.Motion(velocity)))
    np.testing.assert_allclose(out, expected.vector, atol=1e-12)


def test_rotation_defect():
    assert K.rotation_defect(pin.SE3.Random().np) < 1e-14
    scaled = pin.SE3.Random().np
    scaled[:3, :3] *= 1.1
    assert K.rotation_defect(scaled) == pytest.approx(0.21)
    reflected = np.diag([1.0, 1.0, -1.0, 1.0])
    assert K.rotation_defect(reflected) == np.inf
    bad_row = np.eye(4)
    bad_row[3, 0] = 0.5
    assert K.rotation_defect(bad_row) == np.inf
    assert np.isnan(K.rotation_defect(np.full((4, 4), np.nan)))


def test_position_rows(rng):
    J6, oMf = rng.normal(size=(6, 4)), pin.SE3.Random()
    p_d, velocity = rng.normal(size=3), rng.normal(size=6)
    axes = np.array([2, 0])  # the axes z, x
    J_out, e_out, ff_out = np.zeros((2, 4)), np.zeros(2), np.zeros(2)
    K.position_rows(J6, oMf.np, p_d, velocity, axes, J_out, e_out, ff_out)
    np.testing.assert_array_equal(J_out, J6[[2, 0]])
    np.testing.assert_allclose(e_out, (p_d - oMf.translation)[[2, 0]])
    np.testing.assert_array_equal(ff_out, velocity[[2, 0]])


def test_the_slots_are_the_compiled_module_s_and_no_python_module_numbers_one():
    """The slot numbers come from the compiled module (src/kernels.h names each slot once):
    the parameters are 0..INFO-1, the results 0..size-1, and no module of the package assigns
    a number to a slot name."""
    import re
    from pathlib import Path

    from sjt_pin.kernels import _kernels, layout

    names = [n for n in dir(_kernels) if re.fullmatch(r"[PI]_[A-Z0-9_]+", n)]
    for prefix, size in (("P_", _kernels.INFO), ("I_", _kernels.INFO_SIZE)):
        slots = sorted(getattr(_kernels, n) for n in names if n.startswith(prefix))
        assert slots == list(range(size)), prefix
        assert all(getattr(layout, n) == getattr(_kernels, n) for n in names
                   if n.startswith(prefix) and hasattr(layout, n))
    source = Path(layout.__file__).parents[1]
    assignment = re.compile(r"^\s*\(?\s*[PIS]_[A-Z0-9_]+\b[^=\n]*=\s*(range\(|\d)", re.M)
    for path in source.rglob("*.py"):
        assert not assignment.search(path.read_text()), path
    # the modes, status bits and tolerances the kernels share with Python are theirs too
    shared = ("GAIN_FIXED", "GAIN_AUTO", "FF_TRANSPOSE", "FF_DAMPED", "FB_TRANSPOSE", "FB_DAMPED",
              "NON_FINITE", "STALLED", "CLAMPED", "SCALED", "EIGEN_FLOOR", "BOUND_TOL", "RANK_TOL",
              "BRAKING_TOL", "BRAKING_STEPS", "DUAL_RIDGE", "BOUND_PRODUCTS")
    searched = ("CONTINUE", "CONVERGED", "SEARCH_STALLED")  # the search's (the module _core)
    names = "|".join(shared + searched)
    constant = re.compile(rf"^\s*(?:[A-Z_]+,\s*)*({names})\b[^=\n]*=\s*[-\d(]", re.M)
    for path in source.rglob("*.py"):
        assert not constant.search(path.read_text()), path
    assert all(getattr(layout, name) == getattr(_kernels, name) for name in shared)
    from sjt_pin.kernels import _core

    assert [getattr(K, name) for name in searched] == [getattr(_core, name) for name in searched]


def test_bad_arguments_raise_instead_of_crashing():
    J, e, ff, rows, mask = problem(0, 3, 5)
    work = K.Layout(3, 5, 0).allocate()
    step = np.zeros(5)
    with pytest.raises(TypeError, match="J must be a float64 array"):
        K.transpose_step("J", e, ff, np.zeros(5), work, step)
    with pytest.raises(TypeError, match="float64"):
        K.transpose_step(J.astype(np.float32), e, ff, np.zeros(5), work, step)
    with pytest.raises(ValueError, match="do not fit"):
        K.transpose_step(J, e[:2], ff, np.zeros(5), work, step)
    with pytest.raises(ValueError, match="work does not fit"):
        K.transpose_step(J, e, ff, np.zeros(5), np.zeros(10), step)
    with pytest.raises(TypeError, match="writable"):
        readonly = np.zeros(5)
        readonly.flags.writeable = False
        K.transpose_step(J, e, ff, np.zeros(5), work, readonly)
    with pytest.raises(TypeError, match="takes 6 arguments"):
        K.transpose_step(J, e, ff)
    with pytest.raises(ValueError, match=r"M must have shape \(4, 4\)"):
        K.rotation_defect(np.eye(3))


def test_strided_inputs_give_the_contiguous_results():
    """Inputs may be views with any strides (a column of a matrix, a transposed J)."""
    J, e, ff, rows, mask = problem(1, 4, 6)
    contiguous, _ = run(K.least_squares_step, J, e, ff, rows, mask, ff_mode=1.0)
    strided, _ = run(K.least_squares_step, np.asfortranarray(J), np.c_[e, e][:, 0],
                     np.c_[ff, ff][:, 0], rows, mask, ff_mode=1.0)
    np.testing.assert_array_equal(strided, contiguous)


def test_numpy_arrays_are_read_as_the_buffer_protocol_reads_them():
    """The kernels read numpy's arrays in place (numpy's C API): a one-row output sliced out
    of a bigger array (numpy calls it C-contiguous whatever the row stride) is written as a
    contiguous one, a byte-swapped or non-float64 array is refused as through the buffer
    protocol, and any other buffer (a memoryview) still works."""
    rng = np.random.default_rng(3)
    J, support = rng.standard_normal((6, 3)), np.ones((2, 3))
    pairs = np.zeros((1, 13))
    pairs[0, :4] = 0.03, 0.01, 1.0, 0.0
    pairs[0, 4:7] = 0.0, 0.0, 1.0
    pairs[0, 7:] = rng.standard_normal(6)
    A, b = np.zeros((1, 3)), np.zeros(1)
    K.damper_rows(J, support, pairs, 2.0, A, b)
    sliced = np.zeros((2, 3))[::2]  # shape (1, 3), row stride 48 bytes
    assert sliced.flags.c_contiguous and sliced.strides[0] != 24
    K.damper_rows(J, support, pairs, 2.0, sliced, np.zeros(1))
    np.testing.assert_array_equal(sliced, A)
    viewed = np.zeros((1, 3))
    K.damper_rows(memoryview(J), memoryview(support), pairs, 2.0, memoryview(viewed), b)
    np.testing.assert_array_equal(viewed, A)
    with pytest.raises(TypeError, match="float64"):
        K.damper_rows(J.astype(">f8"), support, pairs, 2.0, A, b)
    with pytest.raises(TypeError, match="float64"):
        K.damper_rows(J, support.astype(np.int64), pairs, 2.0, A, b)


@pytest.mark.parametrize("joints", [7, 30, 100])
@pytest.mark.parametrize("method, options", [("sjt", {}), ("sjt", {"feedback": "transpose"}),
                                             ("dls", {}), ("jp", {})])
def test_posture_rows_solved_linear_in_n_give_the_dense_solution(joints, method, options):
    """A posture task's identity rows make the normal matrix diagonal plus rank m_t: the
    Woodbury solve equals the dense one (and the loop bound stays an upper bound)."""
    import sjt_pin as sjt

    from .test_pipeline import random_chain

    robot = random_chain(joints, joints)
    rng = np.random.default_rng(joints)
    solver = sjt.make_solver(method, robot, posture=sjt.PostureTask(weight=1e-2),
                             position_limits=False, velocity_limits=False, **options)
    stack = solver.stack
    assert stack.identity_rows == robot.nv
    q = robot.random_configuration(rng)
    target = robot.fk(robot.random_configuration(rng))
    targets, velocities = stack.targets(target, rng.normal(size=6))
    J, e, ff = (a.copy() for a in stack.evaluate(q, targets, velocities))
    kernel = solver.method.kernel
    work = solver._work.copy()  # noqa: SLF001 (the test compares two settings of one kernel)
    work[K.P_HAS_FF] = 1.0
    transpose_auto = options.get("feedback") == "transpose"
    if transpose_auto:  # its auto gain divides by a bound that the block form computes anew
        auto = work.copy()
        kernel(J, e, ff, q, auto, np.zeros(robot.nv))
        Jw = stack.sqrt_weight[:, None] * J
        alpha = mappings.scaling_factors(Jw, length=solver.method.length)
        lam = np.linalg.eigvalsh((Jw * alpha) @ Jw.T)[-1]
        assert auto[K.INFO + K.I_LOOP] >= lam * (1 - 1e-9)  # still an upper bound
        work[K.P_GAIN_MODE] = K.GAIN_FIXED  # the same fixed gain for both solves below
    dense = work.copy()
    dense[K.P_IDENTITY_ROWS] = 0.0
    fast_step, dense_step = np.zeros(robot.nv), np.zeros(robot.nv)
    assert kernel(J, e, ff, q, work, fast_step) == kernel(J, e, ff, q, dense, dense_step)
    # both to rounding (the dense Cholesky of a 100 x 100 with weights 1e-2 is the worse)
    np.testing.assert_allclose(fast_step, dense_step, atol=1e-8 * np.abs(dense_step).max())
    # the column norms summed over the task rows and the one posture entry: the zeros of the
    # identity rows add nothing, so the trace and the stall ratio are the dense ones, bitwise
    for i in (K.I_TRACE, K.I_STALL, K.I_E_SQ, K.I_EW_SQ):
        assert work[K.INFO + i] == dense[K.INFO + i]


def test_unit_defect_is_the_largest_squared_norm_defect(rng):
    """The door's manifold check of a step: max |sum(q[block]^2) - 1| over the blocks, NaN
    when a block is NaN, an error for a block outside q."""
    from sjt_pin.kernels import unit_defect

    q = rng.normal(size=12)
    blocks = [(0, 4), (5, 2), (9, 2)]
    expected = max(abs(float(q[a:a + n] @ q[a:a + n]) - 1.0) for a, n in blocks)
    table = np.array(blocks)
    assert unit_defect(q, table) == pytest.approx(expected, rel=1e-15)
    q[[0, 1, 2, 3]] = [0.5, 0.5, 0.5, 0.5]
    assert unit_defect(q, np.array([[0, 4]])) < 1e-15
    assert unit_defect(q, np.zeros((0, 2), dtype=np.int64)) == 0.0
    q[10] = np.nan
    assert np.isnan(unit_defect(q, table))
    with pytest.raises(ValueError, match="outside q"):
        unit_defect(q, np.array([[11, 2]]))


def test_a_work_vector_or_table_that_does_not_fit_raises_instead_of_reading_past_it():
    """The kernels check the index tables they read against q and the velocity: a q shorter
    than the limit box indexes and a box index past q raise ValueError (before, some read or
    wrote out of bounds)."""
    rng = np.random.default_rng(3)
    layout = K.Layout(6, 7, 7)
    work = layout.allocate()
    work[K.P_DT] = 1e-3
    for part, value in enumerate((np.arange(7), np.arange(7), -1.0, 1.0, 1.0)):
        layout.box_part(work, part)[:] = value
    J, e, ff, step = rng.random((6, 7)), rng.random(6), np.zeros(6), np.zeros(7)
    assert K.transpose_step(J, e, ff, np.zeros(7), work, step) >= 0  # it fits
    with pytest.raises(ValueError, match="q of 1 coordinates"):
        K.transpose_step(J, e, ff, np.zeros(1), work, step)
    layout.box_part(work, 0)[:] = 10**9
    with pytest.raises(ValueError, match="work does not fit"):
        K.least_squares_step(J, e, ff, np.zeros(7), work, step)


def test_the_search_refuses_rows_and_limits_that_do_not_fit():
    """SetPointSearch checks the rows it is given against its own shape and its limits table
    against q and the velocity, before it reads them: ValueError naming them."""
    rng = np.random.default_rng(3)
    none, box = np.zeros(0, dtype=np.int64), (np.array([-1.0]), np.array([1.0]))
    search = K.SetPointSearch(np.ones(6), np.ones(6), 6, none, none, np.zeros(0), np.zeros(0),
                              damping=1e-6, column_tol=0.0)
    with pytest.raises(ValueError, match=r"J must have shape \(6, 6\), got \(5, 6\)"):
        search.iterate(rng.random((5, 6)), rng.random(6), np.zeros(6))
    with pytest.raises(ValueError, match="q must have length 6"):
        search.iterate(rng.random((6, 6)), rng.random(6), np.zeros(5))
    with pytest.raises(ValueError, match=r"limit_q: entry 0 is 9, outside \[0, 6\)"):
        K.SetPointSearch(np.ones(6), np.ones(6), 6, np.array([9]), np.array([0]), *box,
                         damping=1e-6, column_tol=0.0)  # a q index past q's end


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 0.0099, 0.0101, 0.29, 0.31, 1.0, 2.0, 3.0,
                                   np.pi - 1e-6])
def test_jlog6_inverse_is_pinocchio_s(angle):
    """jlog6_inverse(log6(N)) is Pinocchio's Jlog6(N^-1), on both sides of its series' and
    closed forms' thresholds (0.01 and 0.3 rad) and near pi."""
    from sjt_pin.kernels import jlog6_inverse

    rng = np.random.default_rng(int(angle * 1e4))
    for _ in range(10):
        axis = rng.normal(size=3)
        N = pin.SE3(pin.exp3(angle * axis / np.linalg.norm(axis)), rng.normal(size=3))
        G = np.zeros((6, 6))
        jlog6_inverse(pin.log6(N).vector, G)
        np.testing.assert_allclose(G, pin.Jlog6(N.inverse()), rtol=0, atol=1e-12)


def test_follow_motion_is_the_numpy_formula_bitwise(rng):
    """follow_motion(step, dt, dq, ddq): dq = step / dt and ddq = (dq_new - dq_old) / dt,
    the numbers numpy's division gives (the motion state a user's limits read)."""
    from sjt_pin.kernels import follow_motion

    step, dq, ddq, dt = rng.normal(size=9) * 1e-3, rng.normal(size=9), np.zeros(9), 1e-3
    expected_dq = step / dt
    expected_ddq = (expected_dq - dq) / dt
    follow_motion(step, dt, dq, ddq)
    assert np.array_equal(dq, expected_dq) and np.array_equal(ddq, expected_ddq)
    with pytest.raises(ValueError, match="one length"):
        follow_motion(step, dt, dq[:3], ddq)


@pytest.mark.parametrize("m, n, posture", [(6, 7, False), (3, 3, False), (9, 4, False),
                                           (6 + 7, 7, True), (3 + 30, 30, True),
                                           (12 + 4, 4, True)])
@pytest.mark.parametrize("scaled", [True, False])
def test_the_search_step_is_the_damped_formula(m, n, posture, scaled):
    """SetPointSearch's step from a first iteration (no limits) is
    D J_w^T (J_w D J_w^T + (mu^2 + nu |W e|^2) I)^-1 W e, D the columns' scales (SJT's, or 1;
    0 for masked joints and columns under the tolerance): whichever of its solves the rows
    take (m x m, n x n, or a posture task's identity rows through the Woodbury identity)."""
    rng = np.random.default_rng(m * 100 + n)
    J, e = rng.normal(size=(m, n)), rng.normal(size=m)
    if posture:
        J[m - n:] = np.eye(n)
    J[:, 1] = 0.0  # a column under the tolerance
    sw, mask = rng.uniform(0.5, 2.0, m), (rng.random(n) > 0.2).astype(float)
    none = np.zeros(0, dtype=np.int64)
    search = K.SetPointSearch(sw, mask, n, none, none, np.zeros(0), np.zeros(0), damping=1e-3,
                              column_tol=1e-10, length=0.3, scaled=scaled,
                              identity_rows=n if posture else 0)
    search.tol, search.max_step, search.error_rows, search.nu_start = 0.0, np.inf, m, 0.7
    search.start()
    assert search.iterate(J, e, np.zeros(n)) == K.CONTINUE
    Jw = sw[:, None] * J
    norms = np.sum(Jw**2, axis=0)
    alpha = np.where((mask != 0) & (norms > 1e-10),
                     1.0 / np.maximum(norms, 0.3**2) if scaled else 1.0, 0.0)
    damping = 1e-3**2 + 0.7 * float(np.sum((sw * e) ** 2))
    expected = alpha * (Jw.T @ np.linalg.solve((Jw * alpha) @ Jw.T + damping * np.eye(m), sw * e))
    np.testing.assert_allclose(search.step, expected, rtol=1e-9,
                               atol=1e-12 * np.abs(expected).max())
