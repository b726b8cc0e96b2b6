"""The generated planar arms: committed URDF up to date, Pinocchio FK = closed-form planar FK."""

import numpy as np
import pytest
from sjt_pin.robots import planar3 as generator

import sjt_pin as sjt


def planar_fk(lengths, q):
    angles = np.cumsum(q)
    return np.array([np.sum(lengths * np.cos(angles)), np.sum(lengths * np.sin(angles)), 0.0])


def test_committed_urdf_is_what_the_generator_writes():
    assert generator.PLANAR3_URDF.read_text() == generator.to_xml(generator.planar3())


def test_planar3_forward_kinematics_is_closed_form(planar3, rng):
    lengths = np.array([0.3, 0.4, 0.28 + 0.2])  # the gripper extends link 3
    assert planar3.fk(np.zeros(3)).translation == pytest.approx([1.18, 0.0, 0.0])
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, 3)
        np.testing.assert_allclose(planar3.fk(q).translation, planar_fk(lengths, q), atol=1e-12)
    np.testing.assert_allclose(planar3.lower_limits, -np.pi)
    np.testing.assert_allclose(planar3.upper_limits, np.pi)
    # the paper's start point: elbow up at (60, 45, 30) deg
    start = planar3.fk(np.deg2rad([60.0, 45.0, 30.0])).translation
    np.testing.assert_allclose(start[:2], [-0.293, 0.986], atol=1e-3)


def test_two_link_arm_and_long_chains(rng):
    arm = sjt.Robot.from_urdf(generator.to_xml(generator.planar2()))
    q = rng.uniform(-np.pi, np.pi, 2)
    np.testing.assert_allclose(arm.fk(q).translation, planar_fk(np.ones(2), q), atol=1e-12)
    chain = sjt.Robot.from_urdf(generator.to_xml(generator.serial_chain([0.05] * 50)))
    assert chain.nv == 50
    q = rng.uniform(-0.1, 0.1, 50)
    np.testing.assert_allclose(chain.fk(q).translation, planar_fk(np.full(50, 0.05), q), atol=1e-12)
    with pytest.raises(ValueError, match="one non-zero 3-vector per link"):
        generator.serial_chain([1.0, 1.0], axes=[[0, 0, 1]])
