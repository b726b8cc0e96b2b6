"""The compiled inner loops agree with the numpy formulas they replace."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sjt_pin import mappings
from sjt_pin.kernels import outside_box, sjt_step


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 6), n=st.integers(1, 12), seed=st.integers(0, 2**32 - 1))
def test_sjt_step_is_k_dt_D_Jt_e(m, n, seed):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, n))
    chain = (rng.random(n) > 0.3).astype(float)
    J[:, chain == 0] = 0.0  # joints off the chain have zero columns
    e = rng.normal(size=m)
    k_dt = 0.37
    out = np.empty(n)
    J[:, 0] *= 1e-7  # a chain column below the threshold gets alpha = 0, as in mappings
    ee = sjt_step(J, e, k_dt * chain, 1.0 - chain, out, mappings.COLUMN_TOL)
    expected = k_dt * mappings.sjt_apply(J, e, mappings.scaling_factors(J))
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-15)
    assert abs(ee - e @ e) <= 1e-12 * (e @ e)


def test_sjt_step_reports_non_finite_errors():
    out = np.empty(2)
    ee = sjt_step(np.eye(2), np.array([np.nan, 0.0]), np.ones(2), np.zeros(2), out)
    assert not np.isfinite(ee)


def test_outside_box():
    mid, inv_half = np.zeros(3), np.ones(3)  # limits [-1, 1]
    speed = np.full(3, 10.0)  # |step| * 10 > 1 is too fast
    inside, small = np.array([0.5, -0.9, 0.0]), np.full(3, 0.01)
    assert not outside_box(inside, small, mid, inv_half, speed)
    assert outside_box(np.array([0.5, -1.1, 0.0]), small, mid, inv_half, speed)
    assert outside_box(np.array([1.0, 0.0, 0.0]), small, mid, inv_half, speed)  # on the limit
    assert outside_box(inside, np.array([0.0, 0.2, 0.0]), mid, inv_half, speed)
    assert not outside_box(inside, np.array([0.0, 0.2, 0.0]), mid, inv_half, np.zeros(3))


def test_cgls_first_iterate_is_the_sjt_direction_and_later_ones_least_squares(rng):
    from sjt_pin.kernels import cgls

    J, e = rng.normal(size=(6, 7)), rng.normal(size=6)
    scale = np.sqrt(mappings.scaling_factors(J))
    d1 = cgls(J, e, scale, 1, 0.0)
    direction = mappings.sjt_apply(J, e, mappings.scaling_factors(J))  # D J^T e
    t = (e @ J @ direction) / np.sum((J @ direction) ** 2)  # the best step along it
    np.testing.assert_allclose(d1, t * direction, rtol=1e-10)
    d = cgls(J, e, scale, 50, 0.0)  # enough iterations: a least-squares solution
    np.testing.assert_allclose(J @ d, e, atol=1e-8)


def test_sqrt_scaling(rng):
    from sjt_pin.kernels import sqrt_scaling

    J = rng.normal(size=(6, 5))
    J[:, 1] = 0.0
    J[:, 3] *= 1e-8  # below the column threshold
    chain = np.array([1.0, 1.0, 1.0, 1.0, 0.0])
    expected = np.sqrt(mappings.scaling_factors(J)) * chain
    np.testing.assert_allclose(sqrt_scaling(J, chain, mappings.COLUMN_TOL), expected)


def test_clamp_pass():
    from sjt_pin.kernels import clamp_pass

    q = np.array([0.0, 0.9, 1.5, -1.5])  # joints 3 and 4 start outside [-1, 1]
    dq = np.array([0.5, 0.5, -0.2, -0.2])  # joint 2 would cross; 3 moves back in; 4 goes out
    index = np.arange(4)
    lower, upper = -np.ones(4), np.ones(4)
    fixed, fixed_dq = np.zeros(4, dtype=bool), np.zeros(4)
    assert clamp_pass(q, dq, index, index, lower, upper, 1.0, fixed, fixed_dq) == 3
    np.testing.assert_array_equal(fixed, [False, True, True, True])
    np.testing.assert_allclose(fixed_dq, [0.0, 0.1, -0.2, 0.0])  # land on 1, inward, stop
    assert clamp_pass(q, dq, index, index, lower, upper, 1.0, fixed, fixed_dq) == 0
