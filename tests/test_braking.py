"""The braking of a joint toward a position limit: the jerk-limited stopping distance is the
distance a simulated braking covers, continuous and increasing in the velocity; the braking
speed is the largest velocity from which that stop still fits in the room left
(``sjt_pin/kernels/src/braking.hpp``)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sjt_pin.kernels import approach_top, largest_stoppable
from sjt_pin.kernels import stopping_distance as one_stop

#: the root search's relative tolerance on its bracket (braking.hpp: 1e-12 of the bracket)
BRAKING_TOL = 1e-12


def stopping_distance(w, a0, A, J):
    """The compiled stopping distance, elementwise."""
    return np.array([one_stop(*args) for args in zip(w, a0, A, J, strict=True)])


def simulated_stop(w, a0, A, J, h=1e-6):
    """The distance a braking covers, integrated in steps of h: the acceleration ramps at the
    jerk limit toward -A (down to 0 first when positive), holds, and ramps back to 0 when the
    velocity left is what that ramp loses; it ends where the velocity reaches 0 (or, from a
    velocity away from the room, where the acceleration toward it has ramped down before the
    velocity turned)."""
    x, v, a = 0.0, w, a0
    while v > 0.0 or a > 0.0:
        release = a < 0.0 and a * a / (2.0 * J) >= v  # ramping to 0 now loses all of v
        a = a + J * h if release else max(a - J * h, -A) if a > -A else a
        v += a * h
        x += v * h
    return x


@settings(max_examples=60, deadline=None)
@given(w=st.floats(-1.0, 2.0), a0=st.floats(-1.0, 1.0), A=st.floats(2.0, 30.0),
       J=st.floats(500.0, 20000.0))
def test_the_stopping_distance_is_the_simulated_braking(w, a0, A, J):
    """From a deceleration within the limit or an acceleration (a0 times A), the formula is
    the distance the jerk-limited braking covers (to the integration's step), also from a
    velocity away from the room (w < 0) that an acceleration toward it turns."""
    a0 = a0 * A
    exact = float(stopping_distance(np.array([w]), np.array([a0]), np.array([A]), np.array([J]))[0])
    assert abs(exact - simulated_stop(w, a0, A, J)) <= 1e-5 * (1.0 + exact) + 3e-6 * w


@settings(max_examples=60, deadline=None)
@given(v=st.floats(-2.0, 2.0), A=st.floats(1.0, 30.0), J=st.floats(100.0, 20000.0),
       dt=st.sampled_from([1e-3, 4e-3]))
def test_the_overshoot_grows_with_the_velocity(v, A, J, dt):
    """``x dt + stopping_distance(x, (x - v) / dt)`` over every velocity one step can reach
    (x > 0): increasing, without jumps (what lets the braking speed be found as a root)."""
    x = np.linspace(max(v - 2.0 * A * dt, 1e-12), v + 2.0 * A * dt, 4001)
    x = x[x > 0.0]
    if x.size < 3:
        return
    f = x * dt + stopping_distance(x, (x - v) / dt, np.full(x.size, A), np.full(x.size, J))
    d = np.diff(f)
    assert np.all(d >= -1e-12 * (1.0 + np.abs(f[1:])))
    # no jump: a step across one is far larger than both its neighbours (across a kink of a
    # continuous function it lies between them)
    neighbours = np.maximum(d[:-2], d[2:])
    assert np.all(d[1:-1] <= 2.0 * neighbours + 1e-12 * (1.0 + np.abs(f[2:-1])))


@settings(max_examples=100, deadline=None)
@given(v=st.floats(-2.0, 2.0), A=st.floats(1.0, 30.0), J=st.floats(100.0, 20000.0),
       room=st.floats(0.0, 0.2), dt=st.sampled_from([1e-3, 4e-3]))
def test_the_braking_speed_is_the_largest_that_still_stops(v, A, J, room, dt):
    """Where it bounds, the braking speed x still stops within the room, and a velocity a
    little faster (the search's tolerance) does not: the largest that fits."""
    low, high = v - 2.0 * A * dt, v + 2.0 * A * dt
    x = largest_stoppable(low, high, v, room, dt, A, J)
    assert low <= x <= high

    def overshoot(y):  # (a velocity away from the room stops in it unless accelerated toward it)
        a0 = (y - v) / dt
        d = stopping_distance(np.array([y]), np.array([a0]), np.array([A]),
                              np.array([J]))[0] if y > 0.0 or a0 > 0.0 else 0.0
        return y * dt + d - room

    if x == low:  # nothing one step reaches can stop in time
        assert overshoot(low) > 0.0
        return
    assert overshoot(x) <= 1e-15
    if x < high:
        assert overshoot(x + 1e-9 * (high - low) + 1e-15) > 0.0


@settings(max_examples=100, deadline=None)
@given(v=st.floats(-2.0, 2.0), gap=st.floats(0.0, 1.0), J=st.floats(100.0, 20000.0),
       dt=st.sampled_from([1e-3, 4e-3]))
def test_the_approach_top_ramps_down_before_passing_its_point(v, gap, J, dt):
    """The fastest x >= v whose acceleration can still ramp to 0 at the jerk limit before the
    velocity passes u = v + gap: on the boundary x + ((x - v)/dt)^2 / (2 J) = u."""
    u = v + gap
    x = approach_top(v, u, dt, J)
    assert v - 1e-12 <= x <= u + 1e-12
    a = (x - v) / dt
    assert x + a * a / (2.0 * J) == pytest.approx(u, rel=1e-9, abs=1e-12)
    assert approach_top(v, u, dt, float("inf")) == u
