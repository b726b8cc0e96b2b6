"""Trajectories: analytic velocities match finite differences; ends are held."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

START = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.4, 0.3), np.array([0.4, -0.1, 0.5]))
END = pin.SE3(pin.rpy.rpyToMatrix(-0.5, 0.2, 1.2), np.array([0.1, 0.3, 0.2]))
TRAJECTORIES = [
    sjt.Line([0.1, 0.2, 0.3], [0.5, -0.2, 0.1], duration=2.0),
    sjt.Line([0.1, 0.2, 0.3], [0.5, -0.2, 0.1], duration=2.0, timing="min_jerk"),
    sjt.Circle([0.0, 0.986, 0.0], 0.194, duration=3.0, start_angle=-np.pi / 2),
    sjt.Circle([0.3, 0.0, 0.4], 0.1, duration=1.5, normal=[1, 1, 0], turns=2),
    sjt.PoseInterpolation(START, END, duration=2.0),
    sjt.PoseInterpolation(START, END, duration=2.0, timing="linear"),
]


@pytest.mark.parametrize("trajectory", TRAJECTORIES, ids=lambda t: type(t).__name__)
def test_velocity_matches_finite_differences(trajectory):
    h = 1e-6
    for t in np.linspace(0.05, trajectory.duration - 0.05, 7):
        pose, velocity = trajectory.sample(t)
        plus, _ = trajectory.sample(t + h)
        minus, _ = trajectory.sample(t - h)
        linear = (plus.translation - minus.translation) / (2 * h)
        # world angular velocity: R_dot R^T
        angular = pin.log3(plus.rotation @ minus.rotation.T) / (2 * h)
        np.testing.assert_allclose(velocity.linear, linear, atol=1e-6)
        np.testing.assert_allclose(velocity.angular, angular, atol=1e-6)


@pytest.mark.parametrize("trajectory", TRAJECTORIES, ids=lambda t: type(t).__name__)
def test_ends_are_held_with_zero_velocity(trajectory):
    end, _ = trajectory.sample(trajectory.duration)
    late, velocity = trajectory.sample(trajectory.duration + 1.0)
    np.testing.assert_allclose(late.homogeneous, end.homogeneous)
    assert np.all(velocity.vector == 0)


def test_shapes_of_paths():
    line, _, circle, _, geodesic, _ = TRAJECTORIES
    np.testing.assert_allclose(line.sample(1.0)[0].translation, [0.3, 0.0, 0.2])
    points = circle.positions(0.01)
    np.testing.assert_allclose(np.linalg.norm(points - [0.0, 0.986, 0.0], axis=1), 0.194)
    np.testing.assert_allclose(points[0], [0.0, 0.986 - 0.194, 0.0], atol=1e-12)
    np.testing.assert_allclose(geodesic.sample(0.0)[0].homogeneous, START.homogeneous)
    np.testing.assert_allclose(geodesic.sample(2.0)[0].homogeneous, END.homogeneous, atol=1e-12)
    times = line.times(0.1)
    assert times[0] == 0.0 and times[-1] == pytest.approx(2.0) and times.size == 21
    assert line.times(0.1, duration=3.0).size == 31


def test_a_circle_says_where_it_starts_and_track_warns_when_that_is_away_from_the_hand(ur5):
    """A circle starts at center + radius along its plane's first axis (or at start_angle):
    centred on the wrong side of the hand, its target jumps by the diameter at t = 0, and
    track() says so; one that starts at the hand, or a position task's free axes, does not."""
    import warnings

    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    hand = ur5.fk(q).translation
    wrong = sjt.Circle(hand + [0.1, 0.0, 0.0], 0.1, duration=0.2)
    np.testing.assert_allclose(wrong.start, hand + [0.2, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(wrong.sample(0.0)[0].translation, wrong.start, atol=1e-12)
    with pytest.warns(UserWarning, match=r"starts 0\.2 m from frame 'tool0'.*jumps"):
        sjt.track(sjt.SJTSolver(ur5), wrong, q)
    quarter = sjt.Circle(hand - [0.0, 0.1, 0.0], 0.1, duration=0.2, start_angle=np.pi / 2)
    np.testing.assert_allclose(quarter.start, hand, atol=1e-12)
    right = sjt.Circle(hand - [0.1, 0.0, 0.0], 0.1, duration=0.2)
    along_z = sjt.Line(hand + [0.3, 0.0, 0.0], hand + [0.3, 0.0, 0.1], duration=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sjt.track(sjt.SJTSolver(ur5), right, q)
        sjt.track(sjt.SJTSolver(ur5), quarter, q)
        # x is not tracked by a z-only position task: the line's x offset is no jump
        sjt.track(sjt.SJTSolver(ur5, task=sjt.PositionTask(axes="z")), along_z, q)
    with pytest.warns(UserWarning, match="jumps"):
        sjt.track(sjt.SJTSolver(ur5, task=sjt.PositionTask(axes="x")), along_z, q)
