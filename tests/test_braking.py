"""The braking of a joint toward a position limit: the jerk-limited stopping distance is the
distance a simulated braking covers, continuous and increasing in the velocity; the braking
speed is the largest velocity from which that stop still fits in the room left."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sjt_pin.limits.position import BRAKING_TOL, braking_speed, stopping_distance


def simulated_stop(w, a0, A, J, h=1e-6):
    """The distance a braking covers, integrated in steps of h: the acceleration ramps at the
    jerk limit toward -A (down to 0 first when positive), holds, and ramps back to 0 when the
    velocity left is what that ramp loses; it ends where the velocity reaches 0."""
    x, v, a = 0.0, w, a0
    while v > 0.0:
        release = a < 0.0 and a * a / (2.0 * J) >= v  # ramping to 0 now loses all of v
        a = a + J * h if release else max(a - J * h, -A) if a > -A else a
        v += a * h
        x += v * h
    return x


@settings(max_examples=60, deadline=None)
@given(w=st.floats(0.01, 2.0), a0=st.floats(-1.0, 1.0), A=st.floats(2.0, 30.0),
       J=st.floats(500.0, 20000.0))
def test_the_stopping_distance_is_the_simulated_braking(w, a0, A, J):
    """From a deceleration within the limit or an acceleration (a0 times A), the formula is
    the distance the jerk-limited braking covers (to the integration's step)."""
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
    args = (np.array([room]), np.array([v]), np.zeros(1), dt, np.array([A]), np.array([J]))
    x = float(braking_speed(*args)[0])
    if not np.isfinite(x):
        return
    low, high = v - 2.0 * A * dt, v + 2.0 * A * dt

    def overshoot(y):
        d = stopping_distance(np.array([y]), np.array([(y - v) / dt]), np.array([A]),
                              np.array([J]))[0] if y > 0.0 else 0.0
        return y * dt + d - room

    if x == low:  # nothing one step reaches can stop in time
        assert overshoot(low) > 0.0
        return
    assert overshoot(x) <= 0.0
    assert overshoot(x + 2.0 * BRAKING_TOL * (high - low) + 1e-15) > 0.0
