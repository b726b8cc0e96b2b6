"""A user's rows with room beside acceleration and jerk limits: the stage lowers their bounds to
closing speeds the arm can stop within the room (``kernels.stoppable_rows`` with ``room``), so
an arm sent through a floor reaches it and rests there without the limits yielding; the
feedback's displacement along such a row is bounded by its room alone."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
from sjt_pin.constraints import UserLimits
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits import Limit
from sjt_pin.limits.base import BRAKING_SHARE, EASING_SLACK, Motion

DT = 1e-3


class Floors(Limit):
    """Frames' origins stay above ``z_min`` (m): one row each, approached at most at ``speed``
    (m/s) and damped to the floor, ``z_dot >= -min(speed, gain (z - z_min) / dt)``; the room
    of each row is its frame's height above the floor."""

    name = "floors"

    def __init__(self, robot, frames, z_min, speed, gain=0.5):
        self.ids = [robot.frame_id(f) for f in frames]
        self.z_min, self.speed, self.gain = z_min, speed, gain
        self.z = np.zeros(len(self.ids))

    def rows(self, kinematics, motion):
        self.z = np.array([kinematics.placement(i).translation[2] for i in self.ids])
        A = np.array([-kinematics.world_aligned_jacobian(i)[2] for i in self.ids])
        return A, np.minimum(self.speed, self.gain * (self.z - self.z_min) / motion.dt)

    def room(self):
        return self.z - self.z_min


@pytest.mark.parametrize("jerk", [False, True])
def test_a_users_rows_keep_their_bound_cut_to_what_stops_within_their_room(jerk):
    """Random rows with room: each bound is the user's, lowered to what a collision damper
    row of the same room and no bound of its own is given (``stoppable_rows`` with a rate so
    high that the damper never binds), never raised; rows without room (NaN) are left."""
    rng = np.random.default_rng(3 + jerk)
    n, k = 7, 300
    A = rng.normal(size=(k, n)) * rng.uniform(0.01, 0.5, (k, 1))
    room = rng.uniform(-0.004, 0.05, k)
    room[:10] = np.nan
    asked = rng.uniform(-0.05, 2.0, k)
    dq, ddq = rng.normal(size=n) * 1.5, rng.normal(size=n) * 8.0
    acc = rng.uniform(5.0, 20.0, n)
    jerks = rng.uniform(2000.0, 8000.0, n) if jerk else None
    rate = 1e12  # (the damper rate * room is far above any stoppable speed)
    free = rate * np.nan_to_num(room)
    kernels.stoppable_rows(A, free, dq, ddq, acc, jerks, rate, DT, BRAKING_SHARE, EASING_SLACK)
    b = asked.copy()
    kernels.stoppable_rows(A, b, dq, ddq, acc, jerks, 1.0 / DT, DT, BRAKING_SHARE, EASING_SLACK,
                           room=room)
    expected = np.where(np.isnan(room), asked, np.minimum(asked, free))
    np.testing.assert_allclose(b, expected, rtol=1e-9, atol=1e-15)
    assert np.all(b <= asked)
    assert np.sum(b < asked) > 50 and np.sum(b == asked) > 50  # (both cases drawn)
    with pytest.raises(ValueError, match="room must hold one number per row"):
        kernels.stoppable_rows(A, b, dq, ddq, acc, jerks, 1.0 / DT, DT, BRAKING_SHARE,
                               EASING_SLACK, room=room[:-1])
    with pytest.raises(ValueError, match="room .* comes without carried, speeds and needs"):
        kernels.stoppable_rows(A, b, dq, ddq, acc, jerks, 1.0 / DT, DT, BRAKING_SHARE,
                               EASING_SLACK, carried=np.zeros(k), room=room)


class Braked(Floors):
    """The floors, saying that their rows are braked already (their bounds dampers)."""

    brakes_rows = True


class GivenUp(Floors):
    """The floors, the first row given up (its need below its bound)."""

    def needs(self):
        return np.array([-1.0] + [np.nan] * (len(self.ids) - 1))


def test_the_stage_brakes_only_the_rows_their_limits_leave_to_it(panda):
    """Rows of three limits, stacked: the stage lowers the bounds of the floors' rows with
    room (not the given-up one, not those of a limit that brakes its own) and says which rows
    it braked (``dampers`` 0); the limits' own bounds are not written, and ``last_rows``
    (what ``rows_exceeded`` measures against) keeps them as asked. Without acceleration
    limits nothing is braked."""
    z = panda.fk(panda.q0).translation[2]
    frames = ["panda_hand", "panda_link7"]
    limits = [Floors(panda, frames, z - 0.05, 5.0), Braked(panda, frames, z - 0.05, 5.0),
              GivenUp(panda, frames, z - 0.05, 5.0)]
    user = UserLimits(limits, panda.nv)
    kinematics = Kinematics(panda.model)
    kinematics.update(panda.q0)
    dq = np.full(panda.nv, 0.3)  # (closing on the floors: braking bites)
    motion = Motion(q=panda.q0, dq=dq, ddq=np.zeros(panda.nv), dt=DT,
                    acceleration_limits=np.full(panda.nv, 10.0))
    _, _, A, b, owners = user.evaluate(kinematics, motion)
    asked = np.concatenate([limit.rows(kinematics, motion)[1] for limit in limits])
    assert owners == ["floors"] * 6
    np.testing.assert_array_equal(user.dampers, [0, 0, 1, 1, 0, 0])
    braked = b < asked
    np.testing.assert_array_equal(braked, [True, True, False, False, False, True])
    assert np.all(b <= asked)
    np.testing.assert_array_equal(user.last_rows[1], asked)
    plain = UserLimits(limits, panda.nv)
    motion.acceleration_limits = None
    _, _, _, b_plain, _ = plain.evaluate(kinematics, motion)
    np.testing.assert_array_equal(b_plain, asked)
    assert plain.dampers is None


FRAMES = {"ur5": ["ee_link", "wrist_3_link"], "panda": ["panda_hand", "panda_link7"],
          "kinova": ["j2s6s200_end_effector", "j2s6s200_link_6"], "xarm7": ["link_eef", "link7"]}


@pytest.mark.parametrize("name, speed, ratio, method", [
    ("ur5", 0.3, 500.0, "sjt"),     # yielded 16x its acceleration, 32x its jerk limit
    ("ur5", np.inf, None, "dls"),   # the damper alone: 13x its acceleration limit
    ("kinova", 1.0, 500.0, "dls"),  # 4.3x / 8.5x
    ("kinova", 0.3, None, "sjt"),   # never left its start: a joint at its range's end
    ("panda", 0.1, 500.0, "dls"),   # never left its start
    ("panda", 0.1, None, "sjt"),    # never left its start (a start without jerk limits)
    ("panda", 0.3, 2000.0, "dls"),  # never left its start
    ("panda", 0.1, 500.0, "sjt"),   # rested 22 mm above: each joint clipped alone
    ("panda", 0.1, 2000.0, "sjt"),  # rested 51 mm above, the hand moved sideways
    ("xarm7", 0.1, 500.0, "sjt"),   # rested 14 mm above
])
def test_an_arm_sent_through_a_users_floor_rests_on_it_within_every_limit(name, speed, ratio,
                                                                          method):
    """Two floors 5 cm under the hand (the hand's and a wrist link's), a target 30 cm below
    the hand, acceleration limits (10 rad/s^2) and jerk limits (``ratio`` times them): every
    step keeps both limits (finite differences of the returned stream) without a conflict,
    no frame goes below its floor, and the arm rests on the floor, at the constrained minimum
    of its error (0.25 m: the target's height below the floor)."""
    robot = sjt.Robot.from_example(name)
    n = robot.nv
    q = robot.q0.copy()
    start = robot.fk(q).translation
    floors = Floors(robot, FRAMES[name], start[2] - 0.05, speed)
    smooth = {} if ratio is None else {"jerk_limits": np.full(n, 10.0 * ratio)}
    cls = {"sjt": sjt.SJTSolver, "dls": sjt.DLSSolver}[method]
    solver = cls(robot, task=sjt.PositionTask(), limits=[floors], dt=DT,
                 acceleration_limits=np.full(n, 10.0), **smooth)
    target = start + [0.05, 0.02, -0.3]
    ids = [robot.frame_id(f) for f in FRAMES[name]]

    def height(q):  # (of the lower frame above the floor, at q)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q)
        return min(data.oMf[i].translation[2] for i in ids) - floors.z_min

    qs = [q]
    for _ in range(4000):
        q = solver.step(q, target)
        qs.append(q)
        assert not solver.last.limit_conflicts
        assert height(q) >= -1e-6
    v = np.array([pin.difference(robot.model, x, y)
                  for x, y in zip(qs[:-1], qs[1:], strict=True)]) / DT
    a = np.diff(np.vstack([np.zeros(n), v]), axis=0) / DT
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    if ratio is not None:
        jerk = np.diff(np.vstack([np.zeros(n), a]), axis=0) / DT
        assert np.abs(jerk).max() <= 10.0 * ratio * (1 + 1e-9)
    assert np.abs(v[-500:]).max() < 1e-6  # at rest over the last half second
    assert height(q) < 1e-3  # on the floor, not held above it
    assert solver.error_norm == pytest.approx(0.25, abs=1e-3)
