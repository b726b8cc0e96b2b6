"""The four mappings M(J) and the SJT facts of eq. (18)-(25)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sjt_pin.robots.planar3 import serial_chain, to_xml

import sjt_pin as sjt

from .reference import mappings


def check_sjt_properties(J, chain_mask, revolute=True):
    alpha = mappings.scaling_factors(J)
    assert np.all(np.isfinite(alpha))
    if revolute:  # eq. (19): J_i^T J_i = |z_i x (p_e - p_i)|^2 + 1 >= 1
        assert np.all(alpha[chain_mask] > 0) and np.all(alpha[chain_mask] <= 1 + 1e-12)
    assert np.all(alpha[~chain_mask] == 0)
    n_active = np.count_nonzero(alpha)
    eig = np.linalg.eigvalsh(J @ mappings.sjt_matrix(J))
    assert eig.min() >= -1e-10 and eig.max() <= n_active + 1e-10
    # eq. (25): J D J^T is the sum of rank-one projectors alpha_i J_i J_i^T (trace = n_active)
    assert np.trace(J @ mappings.sjt_matrix(J)) == pytest.approx(n_active)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_sjt_scaling_on_example_robots(name, rng):
    robot = sjt.Robot.from_example(name)
    # Panda: the fingers (last two joints) come after panda_hand and do not move it
    chain = np.arange(robot.nv) < (7 if name == "panda" else 6)
    for _ in range(50):
        check_sjt_properties(robot.jacobian(robot.random_configuration(rng)), chain)


unit_vectors = st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.floats(0.0, 2.0), min_size=1, max_size=8),
    axes_seed=st.integers(0, 2**32 - 1),
    q_seed=st.integers(0, 2**32 - 1),
)
def test_sjt_scaling_on_random_chains(lengths, axes_seed, q_seed):
    rng = np.random.default_rng(axes_seed)
    axes = rng.normal(size=(len(lengths), 3))
    xml = to_xml(serial_chain(lengths, axes=axes, gripper=0.1))
    # a side branch hanging off the base: its joint must get alpha = 0
    xml = xml.replace("</robot>", (
        '<link name="side"/><joint name="side_joint" type="revolute"><parent link="base"/>'
        '<child link="side"/><axis xyz="0 1 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'))
    robot = sjt.Robot.from_urdf(xml, ee_frame="ee", load_visuals=False)
    q = robot.random_configuration(np.random.default_rng(q_seed))
    J = robot.jacobian(q)
    side = robot.model.getJointId("side_joint") - 1
    chain = np.ones(robot.nv, dtype=bool)
    chain[robot.model.idx_vs[side + 1]] = False
    check_sjt_properties(J, chain)


def test_zero_columns_give_zero_alpha_not_nan():
    J = np.zeros((2, 3))
    J[:, 1] = [0.3, 0.4]
    np.testing.assert_array_equal(mappings.scaling_factors(J), [0.0, 1 / 0.25, 0.0])
    assert np.all(np.isfinite(mappings.sjt_matrix(J)))


def test_matrices_agree_with_textbook_forms(rng):
    J = rng.normal(size=(6, 7))
    np.testing.assert_allclose(mappings.jp_matrix(J), np.linalg.pinv(J), atol=1e-12)
    lam = 0.1
    np.testing.assert_allclose(
        mappings.dls_matrix(J, lam), J.T @ np.linalg.inv(J @ J.T + lam**2 * np.eye(6)), atol=1e-12)
    np.testing.assert_allclose(mappings.sjt_matrix(J),
                               np.diag(1 / np.sum(J**2, axis=0)) @ J.T, atol=1e-12)
    alpha = mappings.scaling_factors(J)
    damped = mappings.damped_sjt_matrix(J, lam**2)
    np.testing.assert_allclose(  # D J^T (J D J^T + l^2 I)^-1 = sqrt(D) DLS(J sqrt(D)) ...
        damped, np.sqrt(alpha)[:, None] * mappings.dls_matrix(J * np.sqrt(alpha), lam),
        atol=1e-12)
    np.testing.assert_allclose(  # ... and tends to D J^T / l^2 as the damping grows
        1e8 * mappings.damped_sjt_matrix(J, 1e8), mappings.sjt_matrix(J), rtol=1e-6)


def test_jp_drops_lost_directions_at_exact_singularity():
    J = np.array([[1.0, 1.0], [0.0, 0.0]])
    np.testing.assert_allclose(mappings.jp_matrix(J), [[0.5, 0.0], [0.5, 0.0]])
    # damped by the error's term, the lost direction stays dropped: sigma / (sigma^2 + lm)
    np.testing.assert_allclose(mappings.jp_matrix(J, lm=0.5), [[0.4, 0.0], [0.4, 0.0]])


def test_the_error_term_is_a_damping_added_to_lambda_squared(rng):
    J = rng.normal(size=(6, 7))
    lam, lm = 0.1, 0.02
    np.testing.assert_allclose(mappings.dls_matrix(J, lam, lm),
                               J.T @ np.linalg.inv(J @ J.T + (lam**2 + lm) * np.eye(6)),
                               atol=1e-12)
    # full row rank: the damped pseudoinverse is DLS with lambda^2 = lm
    np.testing.assert_allclose(mappings.jp_matrix(J, lm=lm),
                               J.T @ np.linalg.inv(J @ J.T + lm * np.eye(6)), atol=1e-12)


def test_stable_gain_bound(rng):
    J = rng.normal(size=(3, 5))
    lam = np.linalg.svd(J, compute_uv=False)[0] ** 2
    assert mappings.stable_gain_bound(J, J.T, dt=0.01) == pytest.approx(2 / (0.01 * lam))
