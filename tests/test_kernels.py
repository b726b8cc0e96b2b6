"""The compiled kernels agree with the numpy reference formulas of ``tests/reference/mappings.py``
and with Pinocchio."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sjt_pin import kernels as K
from sjt_pin.methods import DLS, JP, JT, SJT

from .reference import mappings


@settings(max_examples=120, deadline=None)
@given(m=st.integers(1, 8), n=st.integers(1, 10), seed=st.integers(0, 2**32 - 1),
       lost=st.sampled_from(["none", "column", "rank"]))
def test_the_compiled_method_matrices_are_the_reference_mappings(m, n, seed, lost):
    """M(J) of every method from the compiled mapping (``kernels.mapping_matrix``) is the numpy
    formula of the paper: SJT's D(q) J^T with D = diag(1 / |J_i|^2) (Eq. 3.4), JT's J^T, JP's
    pseudoinverse and DLS's damped least squares, also where a column vanishes (alpha_i = 0)
    or J loses rank (the transpose methods leave out a column below the column tolerance)."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, n))
    if lost == "column":
        J[:, 0] *= 1e-7  # below the column tolerance
    elif lost == "rank" and m > 1:
        J[-1] = J[0]
    sjt, dls = SJT(), DLS()
    kept = np.einsum("ij,ij->j", J, J) > mappings.COLUMN_TOL  # (J_i^T J_i, as Eq. 18)
    scale = 1.0 + np.abs(J).max()
    pairs = [(sjt.matrix(J), mappings.sjt_matrix(J, length=sjt.length)),
             (JT().matrix(J), mappings.jt_matrix(J * kept))]
    if lost != "column":  # (the least-squares methods' answer to a 1e-7 column is ill-posed)
        pairs += [(JP().matrix(J), mappings.jp_matrix(J)),
                  (dls.matrix(J), mappings.dls_matrix(J, dls.damping))]
    for got, want in pairs:
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * scale)


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


@pytest.mark.parametrize("n", [1, 2, 6, 7, 30])
def test_symmetric_eigen_decomposes_the_symmetric_part(n):
    """symmetric_eigen(H) holds the eigenvalues of (H + H^T) / 2 ascending, as numpy's eigh
    gives them, and orthonormal eigenvectors that diagonalise it; repeated eigenvalues (a
    projector's) and an empty matrix included."""
    from sjt_pin.kernels import symmetric_eigen

    rng = np.random.default_rng(n)
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    for H in (rng.normal(size=(n, n)), Q[:, : n // 2 + 1] @ Q[:, : n // 2 + 1].T,
              np.zeros((n, n))):
        values, vectors = np.empty(n), np.empty((n, n))
        symmetric_eigen(H, values, vectors)
        S = 0.5 * (H + H.T)
        np.testing.assert_allclose(values, np.linalg.eigvalsh(S), rtol=0, atol=1e-12)
        np.testing.assert_allclose(vectors.T @ vectors, np.eye(n), rtol=0, atol=1e-12)
        np.testing.assert_allclose(vectors.T @ S @ vectors, np.diag(values), rtol=0, atol=1e-12)
    symmetric_eigen(np.zeros((0, 0)), np.empty(0), np.empty((0, 0)))


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


def _least_value(cap_lo, cap_hi, hard_lo, hard_hi, a, s):
    """min a x over the acceleration/jerk box widened s times about its centre, within the hard
    box (numpy, as the stage widens it)."""
    with np.errstate(invalid="ignore", over="ignore"):
        c, h = 0.5 * (cap_lo + cap_hi), 0.5 * (cap_hi - cap_lo)
        lo = np.maximum(hard_lo, np.minimum(c - s * h, hard_hi))
        hi = np.minimum(hard_hi, np.maximum(c + s * h, hard_lo))
        finite = np.isfinite(c) & np.isfinite(h)
        lo, hi = np.where(finite, lo, hard_lo), np.where(finite, hi, hard_hi)
        terms = np.where(a > 0, a * lo, np.where(a < 0, a * hi, 0.0))
    return float(np.sum(terms))


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 8), seed=st.integers(0, 2**32 - 1))
def test_least_widening_is_the_least_factor_that_meets_the_row(n, seed):
    """``least_widening``: 1 where the acceleration/jerk box already meets the row, inf where the
    hard box cannot, else the least s (to 1e-9) at which the box widened s times meets it: the
    row's least value there is at most b, and just below s it is above b."""
    rng = np.random.default_rng(seed)
    centre, half = rng.normal(size=n), rng.uniform(0.0, 1.0, n)
    half[rng.random(n) < 0.15] = 0.0  # (a box of zero width: no widening moves it)
    cap_lo, cap_hi = centre - half, centre + half
    hard_lo, hard_hi = -rng.uniform(1.0, 20.0, n), rng.uniform(1.0, 20.0, n)
    hard_lo[rng.random(n) < 0.2] = -np.inf
    hard_hi[rng.random(n) < 0.2] = np.inf
    cap_lo[rng.random(n) < 0.1] = -np.inf  # (joints without acceleration limits)
    cap_hi[rng.random(n) < 0.1] = np.inf
    a = rng.normal(size=n) * (rng.random(n) < 0.8)
    at_one = _least_value(cap_lo, cap_hi, hard_lo, hard_hi, a, 1.0)
    widest = _least_value(cap_lo, cap_hi, hard_lo, hard_hi, a, 1e300)
    for b in (at_one + 1.0, at_one - rng.uniform(0.0, 5.0), widest - 1.0, widest + 1e-3):
        s = K.least_widening(cap_lo, cap_hi, hard_lo, hard_hi, a, b)
        if at_one <= b:
            assert s == 1.0
        elif not widest <= b:
            assert s == np.inf
        else:
            assert 1.0 <= s < np.inf
            assert _least_value(cap_lo, cap_hi, hard_lo, hard_hi, a, s) <= b
            assert _least_value(cap_lo, cap_hi, hard_lo, hard_hi, a, s * (1 - 2e-9)) > b


def test_least_widening_refuses_boxes_inside_out():
    one, two = np.ones(2), 2 * np.ones(2)
    with pytest.raises(ValueError, match="lo <= hi"):
        K.least_widening(two, one, -two, two, one, 0.0)
    with pytest.raises(ValueError, match="lo <= hi"):
        K.least_widening(-one, one, two, -two, one, 0.0)
