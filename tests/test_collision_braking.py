"""CollisionLimit beside acceleration and jerk limits: damper rows an arm with those limits can
keep (``kernels.stoppable_rows``), and a blocked arm that comes to rest."""

from __future__ import annotations

import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
from sjt_pin.bench import collision_blocked as blocked
from sjt_pin.limits import CollisionLimit
from sjt_pin.limits.collision import BRAKING_SHARE, EASING_SLACK

from .test_collision_rest import DT, MARGIN, _blocked_scene, _closest, _rest

GAIN = 0.5


def _speed(h, a, tau):
    """The signed closing speed held for tau then braked at a that covers |h|."""
    v = np.sqrt((a * tau) ** 2 + 2.0 * a * np.abs(h)) - a * tau
    return np.where(h >= 0.0, v, -v)


def _row_jerk(A, ddq, acc, jerks):
    """Each row's jerk (m/s^3): the summed ``|A_ij| jerks_j``, or where slower the chord of its
    deceleration as each joint ramps its own to its limit, ``sum_j |A_ij| min(acc_j, c_j +
    jerks_j t)`` (``c_j = -sign(A_ij) ddq_j``), from ``-A_i ddq`` at 0 to ``sum_j |A_ij|
    acc_j`` when the last joint gets there."""
    summed = np.abs(A) @ jerks
    braking = -np.sign(A) * ddq
    full = np.where((A != 0.0) & (braking < acc), (acc - braking) / jerks, 0.0).max(axis=1)
    rise = np.abs(A) @ acc + A @ ddq
    chord = np.divide(rise, full, out=np.full_like(rise, np.inf), where=full > 0.0)
    return np.where((full > 0.0) & (rise > 0.0), np.minimum(summed, chord), summed)


def test_a_row_ramps_its_braking_no_faster_than_its_joints_can():
    """The row's jerk is at most the chord of the deceleration its joints reach, each at its
    own jerk limit: where some brake at their limit already, or speed the row up, it is below
    the summed jerks; it is never above the deceleration any joint-by-joint ramp gives."""
    rng = np.random.default_rng(11)
    acc, jerks = rng.uniform(5.0, 20.0, 6), rng.uniform(500.0, 8000.0, 6)
    A = rng.normal(size=(300, 6)) * rng.uniform(0.01, 0.5, (300, 1))
    ddq = rng.uniform(-1.0, 1.0, 6) * acc
    ddq[:2] = -np.sign(A[0, :2]) * acc[:2]  # (two joints of row 0 brake it at their limit)
    j = _row_jerk(A, ddq, acc, jerks)
    assert j[0] < np.abs(A[0]) @ jerks
    t = np.linspace(0.0, 0.05, 501)[:, None, None]
    reached = (np.abs(A) * np.minimum(acc, -np.sign(A) * ddq + jerks * t)).sum(axis=2)
    a = np.abs(A) @ acc
    ramp = np.minimum(a, -(A @ ddq) + j * t[:, :, 0])
    assert np.all(ramp <= reached + 1e-9)


def _row_box(A, ddq, acc, jerks, dt):
    """Each row's least and largest acceleration (m/s^2) within the joints' acceleration and
    jerk boxes this period (an empty box, after the limits yielded, counts as its nearer
    end)."""
    low, high = np.maximum(-acc, ddq - jerks * dt), np.minimum(acc, ddq + jerks * dt)
    low, high = np.minimum(low, high), np.maximum(low, high)
    return (np.where(A > 0, A * low, A * high).sum(axis=1),
            np.where(A > 0, A * high, A * low).sum(axis=1))


@pytest.mark.parametrize("jerk", [False, True])
def test_stoppable_rows_brake_within_the_excess_and_ease_in(jerk):
    """Random rows: each bound is the damper's, cut to a closing speed that, held for one
    period (and the jerk's ramp) and braked at BRAKING_SHARE of the row's acceleration, stops
    within the excess h = b / rate; never below what the previous velocity and acceleration can
    reach in one period at that share unless the pair would then come closer than
    margin - slack; inside the margin, never below what they can reach in one period, and
    where the row's lever is below PUSH_LEVER the pair only stops closing. The
    row's jerk is its joints' (:func:`_row_jerk`), and the ramp the held speed waits for at
    most the time its slowest joint takes from one acceleration limit to the other."""
    rng = np.random.default_rng(7 + jerk)
    n, k, dt = 7, 200, 1e-3
    rate = GAIN / dt
    A = rng.normal(size=(k, n)) * rng.uniform(0.01, 0.5, (k, 1))
    h = rng.uniform(-0.004, 0.05, k)
    damper = rate * h
    dq, ddq = rng.normal(size=n) * 1.5, rng.normal(size=n) * 8.0
    A[np.flatnonzero(h < 0.0)[::2]] *= 0.005  # (levers too short to push their pairs out)
    acc = rng.uniform(5.0, 20.0, n)
    jerks = rng.uniform(2000.0, 8000.0, n) if jerk else None
    if jerk:  # (some joints at their acceleration limit, one of them beyond it: yielded)
        ddq[:3] = acc[:3] * np.array([1.0, -1.0, 1.0])
        ddq[3] = -1.2 * acc[3]
    b = damper.copy()
    kernels.stoppable_rows(A, b, dq, ddq, acc, jerks, rate, dt, BRAKING_SHARE, EASING_SLACK)
    a_row = np.abs(A) @ acc
    j_row = _row_jerk(A, ddq, acc, jerks) if jerk else np.full(k, np.inf)
    rise = np.where(A != 0.0, acc / jerks, 0.0).max(axis=1) if jerk else np.zeros(k)
    tau = dt + np.minimum(a_row / j_row, 2.0 * rise)
    brake = _speed(h, BRAKING_SHARE * a_row, tau)
    s = A @ dq
    share_a, share_j = BRAKING_SHARE * a_row, BRAKING_SHARE * j_row
    if jerk:  # a bound above s lets the row speed up toward its margin: only while the
        # fastest speed it can reach this step (within the joints' boxes) stops within h
        least, most = _row_box(A, ddq, acc, jerks, dt)
        for i in np.flatnonzero((h >= 0.0) & (brake > s)):
            top = min(brake[i], s[i] + dt * most[i])
            if top > s[i]:
                x = kernels.largest_stoppable(s[i], top, s[i], h[i], dt, share_a[i],
                                              share_j[i])
                brake[i] = x if x < top else brake[i]
    r = np.maximum(-share_a, A @ ddq - share_j * dt) if jerk else -share_a
    if jerk:  # nor faster than the joints' boxes let it (the chord keeps within them where
        # some joints already brake at their limit, the summed jerks did not; one beyond its
        # limit, yielded, leaves an empty box)
        assert np.sum(j_row < np.abs(A) @ jerks) >= 20
        summed = np.sum(least > A @ ddq - BRAKING_SHARE * (np.abs(A) @ jerks) * dt)
        assert summed >= 5 and np.sum(least > A @ ddq - share_j * dt) < summed / 4
        r = np.maximum(r, least)
    drop, held = s + r * dt, _speed(h + EASING_SLACK, a_row, tau)
    floor = np.minimum(drop, held)
    if jerk:  # the margin's guard braking at the whole limits from the acceleration the drop
        # leaves, jerk-limited (not held for the whole ramp first)
        floor = np.array([kernels.largest_stoppable(min(drop[i], held[i]), drop[i], s[i],
                                                    h[i] + EASING_SLACK, dt, a_row[i],
                                                    j_row[i]) for i in range(k)])
        assert np.sum(floor > np.minimum(drop, held) + 1e-9) >= 5  # (where the ramp counts)
    cut = np.where(h >= 0.0, np.minimum(damper, brake), np.maximum(damper, brake))
    expected = np.maximum(cut, floor)
    inside = h < 0.0  # (a pair inside its margin separates as the share lets it)
    expected[inside] = np.maximum(expected[inside], (s + r * dt)[inside])
    assert inside.sum() > 5
    # (where its lever can push it: else it stops closing as the share lets it)
    held = inside & (np.linalg.norm(A, axis=1) < kernels.PUSH_LEVER)
    expected[held] = np.maximum(s + r * dt, 0.0)[held]
    assert held.sum() >= 3 and (inside & ~held).sum() >= 3
    np.testing.assert_allclose(b, expected, rtol=1e-12, atol=1e-15)
    # the cut bound stops within h: v tau + v^2 / (2 a) <= h where it holds
    kept = (b <= cut) & (h >= 0.0)
    assert kept.sum() > 20
    v = b[kept]
    a = BRAKING_SHARE * a_row[kept]
    assert np.all(v * tau[kept] + v * np.abs(v) / (2.0 * a) <= h[kept] + 1e-12)
    if jerk:  # and from the acceleration that reaching it takes, at the share's jerk too
        for i in np.flatnonzero(kept):
            x = min(b[i], s[i] + dt * most[i])  # (the fastest it can reach)
            stop = kernels.stopping_distance(x, (x - s[i]) / dt, share_a[i], share_j[i])
            assert x * dt + stop <= h[i] * (1 + 1e-9) + 1e-12, i
    # and a row eased in still brakes, at the row's whole limits, short of margin - slack
    # (under a jerk limit from the acceleration its speed leaves, else held for a period),
    # or is at the hardest braking the guard allows where no speed stops there
    eased = (b > cut + 1e-12) & (h >= 0.0)
    assert eased.any()
    for i in np.flatnonzero(eased):
        v = b[i]
        if jerk:
            stop = v * dt + kernels.stopping_distance(v, (v - s[i]) / dt, a_row[i], j_row[i])
        else:
            stop = v * tau[i] + v * abs(v) / (2.0 * a_row[i])
        assert stop <= (h[i] + EASING_SLACK) * (1 + 1e-9) + 1e-12 or v == pytest.approx(
            min(drop[i], held[i]), rel=1e-12), i


def test_a_row_accelerating_toward_its_margin_under_a_jerk_limit_can_still_stop():
    """Under a jerk limit a row's acceleration toward its margin takes time to ramp out; the
    bound counts it: from the closing speed it allows, reached with the acceleration that takes,
    the pair stops within its excess at the share of the limits. (Panda's fingers sliding on a
    plate's hull, 0.1 mm from the margin at 5 mm/s and speeding up at 6 m/s^2, were allowed
    21 mm/s by the bound that ignored it, and reached the margin at that speed: the rows then
    asked 1.08x Franka's acceleration limit.)"""
    rng = np.random.default_rng(3)
    dt, n, rate = 1e-3, 7, GAIN / 1e-3
    acc = rng.uniform(7.5, 20.0, n)
    jerks = 500.0 * acc
    checked = tight = 0
    for _ in range(300):
        row = rng.normal(size=(1, n)) * 0.1
        s, sd = rng.uniform(-0.02, 0.03), rng.uniform(-3.0, 9.0)
        h = rng.uniform(1e-5, 2e-3)
        # a previous velocity and acceleration with these closing speed and acceleration
        dq = row[0] * s / (row[0] @ row[0])
        ddq = row[0] * sd / (row[0] @ row[0])
        b = np.array([rate * h])
        kernels.stoppable_rows(row, b, dq, ddq, acc, jerks, rate, dt, BRAKING_SHARE, 0.0)
        a = BRAKING_SHARE * np.abs(row[0]) @ acc
        j = BRAKING_SHARE * _row_jerk(row, ddq, acc, jerks)[0]
        # the fastest closing speed this step can reach, within the joints' boxes
        most = _row_box(row, ddq, acc, jerks, dt)[1][0]
        x = min(b[0], s + dt * most)
        floor = s + dt * max(-a, sd - j * dt)  # (the least the share's jerk lets it drop to)
        if x <= s or b[0] <= floor + 1e-12:  # no acceleration toward the margin, or a pair
            continue  # too late for the share's braking (the ease-in's floor)
        checked += 1
        stop = kernels.stopping_distance(x, (x - s) / dt, a, j)
        assert x * dt + stop <= h * (1 + 1e-9), (s, sd, h, x)
        # and the closed-form bound that assumes no acceleration would not have stopped
        ramp = min(a / j, 2.0 * np.max(acc / jerks))
        v = min(float(_speed(np.array(h), a, dt + ramp)), s + dt * most)
        tight += v > x + 1e-9 and v * dt + kernels.stopping_distance(v, (v - s) / dt, a, j) > h
    assert checked > 100 and tight > 10


def test_a_row_asks_no_faster_drop_than_its_joints_boxes_give():
    """A row whose closing speed must drop while two of the joints that drop it already brake
    at their acceleration limit and two speed up: its bound asks the share of what the others'
    jerk limits let them give (the row's jerk is the chord of their ramps), and no less. (The
    share of the row's summed acceleration and jerk was more: the limits yielded to a row
    11 mm from its margin. All that the boxes give left nothing for the pair's other rows:
    under a ring's hull, Panda's finger row and its witnesses each asked 96 % of it, and the
    acceleration limit yielded 1.2 %.)"""
    dt, rate = 1e-3, GAIN / 1e-3
    acc, jerks = np.full(4, 15.0), np.full(4, 7500.0)
    row = np.array([[0.3, 0.3, 0.3, 0.05]])
    dq = np.full(4, 0.5)  # closing at 0.475 m/s
    ddq = np.array([-15.0, -15.0, 15.0, 15.0])  # two brake at their limit, two speed up
    s, sd = row[0] @ dq, row[0] @ ddq
    least = _row_box(row, ddq, acc, jerks, dt)[0][0]  # (m/s^2: the most the boxes give)
    a, j = np.abs(row[0]) @ acc, _row_jerk(row, ddq, acc, jerks)[0]
    # (the summed jerks' share would have asked more than the boxes give)
    assert sd - BRAKING_SHARE * (np.abs(row[0]) @ jerks) * dt < least - 0.5
    share = max(-BRAKING_SHARE * a, sd - BRAKING_SHARE * j * dt)
    asked = s + dt * max(share, least)
    assert asked > s + dt * least + 1e-3  # (the chord: less than all the boxes give)
    held = 0
    for h in (2e-3, 5e-3, 1e-2, 2e-2, 5e-2):
        b = np.array([rate * h])
        kernels.stoppable_rows(row, b, dq, ddq, acc, jerks, rate, dt, BRAKING_SHARE,
                               EASING_SLACK)
        ramp = min(a / j, 2.0 * np.max(acc / jerks))  # (the held speed's ramp)
        cut = min(rate * h, float(_speed(np.array(h), BRAKING_SHARE * a, dt + ramp)))
        # the pair would come closer than margin - slack braking at all its joints can (from
        # the acceleration the drop leaves, jerk-limited): the margin wins, the row asks more
        # than the boxes give (the limits yield, and say so)
        late = float(_speed(np.array(h + EASING_SLACK), a, dt + ramp))
        guard = kernels.largest_stoppable(min(asked, late), asked, s, h + EASING_SLACK, dt, a, j)
        assert b[0] == pytest.approx(max(cut, guard), rel=1e-12)
        held += bool(cut < asked and b[0] == pytest.approx(asked, rel=1e-12))
    assert held >= 1


def test_stoppable_rows_refuses_what_does_not_fit():
    A, b = np.ones((2, 3)), np.ones(2)
    with pytest.raises(ValueError, match="do not fit"):
        kernels.stoppable_rows(A, b, np.zeros(2), np.zeros(3), np.ones(3), None, 1.0, 1e-3,
                               0.5, 0.0)
    with pytest.raises(ValueError, match="share"):
        kernels.stoppable_rows(A, b, np.zeros(3), np.zeros(3), np.ones(3), None, 1.0, 1e-3,
                               1.5, 0.0)


def test_a_solver_with_acceleration_limits_slows_the_rows():
    """The rows a limit returns to a solver with acceleration limits are the damper's cut to
    stoppable closing speeds (the same limit, the same configuration); without them, the
    rows of the pairs whose damper bound no step within the speed limits can break are left
    out."""
    panda = sjt.Robot.from_example("panda")
    q0, end, target, obstacle = _blocked_scene(panda, np.random.default_rng(0))
    limit = CollisionLimit(panda, [obstacle], self_collision=True, margin=MARGIN)
    plain = sjt.make_solver("sjt", panda, dt=DT, limits=[limit])
    smooth = sjt.make_solver("sjt", panda, dt=DT, limits=[limit],
                             acceleration_limits=np.full(panda.nv, 15.0))
    q = q0.copy()
    for k in range(3000):  # into the obstacle's influence
        pose, velocity = target(k * DT)
        q = plain.step(q, pose, velocity)
        if limit.active:
            break
    assert limit.active
    rows = []
    for solver in (plain, smooth):
        solver.stack.kinematics.update(q)
        motion = solver._motion  # noqa: SLF001 (the state the solver hands its limits)
        motion.q = q
        A, b = limit.rows(solver.stack.kinematics, motion)
        count = len(limit.active)  # (the witness rows follow)
        rows.append((dict(zip(limit.active, A[:count], strict=True)),
                     dict(zip(limit.active, b[:count], strict=True))))
        within = limit.within
    assert set(rows[1][0]) == set(within)  # with acceleration limits, every pair within
    assert set(rows[0][0]) <= set(within)  # influence has a row; without, those that can bind
    for k in rows[0][0]:
        np.testing.assert_allclose(rows[0][0][k], rows[1][0][k], rtol=0.0, atol=1e-12)  # (coal's
        # GJK starts from its last answer: the same points to rounding)
        assert rows[1][1][k] <= rows[0][1][k] + 1e-12
    assert any(rows[1][1][k] < 0.5 * rows[0][1][k] for k in rows[0][0])


def _blocked_run(seed, method, acceleration, jerk=None):
    """Panda's blocked scene ``seed`` for 8 s with ``acceleration`` (and ``jerk``) as every
    joint's limit: the robot, the obstacle, its limit, the configurations (8001, nq) and, per
    step, whether ``limit_conflicts`` was reported and the error norm."""
    panda = sjt.Robot.from_example("panda")
    q0, end, target, obstacle = _blocked_scene(panda, np.random.default_rng(seed))
    limit = CollisionLimit(panda, [obstacle], self_collision=True, margin=MARGIN)
    smooth = {} if jerk is None else {"jerk_limits": np.full(panda.nv, jerk)}
    solver = sjt.make_solver(method, panda, dt=DT, limits=[limit],
                             acceleration_limits=np.full(panda.nv, acceleration), **smooth)
    q, qs, reported, errors = q0.copy(), [q0.copy()], [], []
    for k in range(8000):
        pose, velocity = target(k * DT)
        q = solver.step(q, pose, velocity)
        qs.append(q)
        reported.append(bool(solver.last.limit_conflicts))
        errors.append(solver.last.error_norm)
    return panda, obstacle, limit, np.array(qs), reported, errors


def _accelerations(qs, n):
    v = np.diff(qs, axis=0) / DT  # (Panda's coordinates are its tangent space)
    return np.diff(np.vstack([np.zeros((1, n)), v]), axis=0) / DT


@pytest.mark.slow
# Panda's blocked scenes with 15 rad/s^2 and 7,500 rad/s^3. An arm whose target lies behind an
# obstacle slides along it while that lowers the error (the stage never stops an arm some motion
# within its limits would bring closer), and settles where none does. Each joint approaches the
# feasible velocity, not the method's beyond the rows (approaching that one crept at 3-7 cm/s for
# seconds). Before the feedback's displacement was kept within the rows' room (Limit.room), the
# jerk-limited arm still slid at 1.3e-2 to 1.6e-2 rad/s RMS over the 8th second (SJT) and
# 1.4e-3 to 1.5e-3 (DLS), the error falling by 1e-5 a step.
@pytest.mark.parametrize("seed", [0, 9])
@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_blocked_targets_with_acceleration_limits_come_to_rest(seed, method):
    accel = 15.0
    panda, obstacle, limit, qs, reported, errors = _blocked_run(seed, method, accel, 7500.0)
    assert np.mean(errors[-1000:]) <= np.mean(errors[-4000:-3000]) + 1e-9
    assert _closest(panda, [obstacle], limit, qs) >= MARGIN - 1e-3
    over = np.max(np.abs(_accelerations(qs, panda.nv)) / accel, axis=1) > 1.001
    for k in np.flatnonzero(over & ~np.concatenate([[False], over[:-1]])):
        assert reported[k], f"step {k} broke the acceleration limit unreported"
    assert _rest(qs) < 1e-3


@pytest.mark.slow
# Panda's blocked scenes with 15 rad/s^2 and no jerk limit, where the arm swung on behind the
# obstacle (DLS on seed 11 at 0.29 rad/s RMS over the 8th second, the error flat to 1e-4, seed 2
# at 1.1e-2 rad/s) before a projected step that lowers the error by less than the stage's rest
# rate gave way to rest where rest is feasible.
@pytest.mark.parametrize("seed", [2, 11])
@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_blocked_targets_with_acceleration_limits_alone_come_to_rest(seed, method):
    accel = 15.0
    panda, obstacle, limit, qs, reported, _ = _blocked_run(seed, method, accel)
    assert _closest(panda, [obstacle], limit, qs) >= MARGIN - 1e-3
    over = np.max(np.abs(_accelerations(qs, panda.nv)) / accel, axis=1) > 1.001
    assert all(reported[k] for k in np.flatnonzero(over)), "an acceleration limit broken unreported"
    assert _rest(qs) < 1e-3


@pytest.mark.slow
# Arms no other acceleration-limited collision test uses, at targets behind an obstacle with
# 15 rad/s^2 (and 7,500 rad/s^3). Before the feedback's displacement was kept within the
# collision rows' room, 16 of 18 such runs on KUKA iiwa, xArm6 and UR3 (pybullet's URDFs and
# example-robot-data's; seeds 0-2, SJT and DLS) still slid along the obstacle after 8 s, their
# error falling by some 1e-6 a step; now every one rests by the 4th second.
@pytest.mark.parametrize("jerk", [None, 7500.0])
@pytest.mark.parametrize("name", ["ur3_gripper", "xarm7", "ur10"])
def test_blocked_targets_on_other_arms_rest_within_5_s(name, jerk):
    """(The bench's run, :func:`~sjt_pin.bench.collision_blocked.blocked_run`: 8 s, every joint
    below 1e-6 rad/s from its rest time to the end, the margin checked on the meshes.)"""
    robot = sjt.Robot.from_example(name)
    assert blocked.ACCELERATION == 15.0 and blocked.MARGIN == MARGIN
    for seed in (0, 1):
        for method in ("sjt", "dls"):
            row = blocked.blocked_run(robot, seed, method, jerk)
            assert row.min_distance >= MARGIN - 1e-3, (seed, method)
            assert row.rest_at <= 5.0, (seed, method)  # (nan: still moving at 8 s)


@pytest.mark.parametrize("jerk", [False, True])
def test_braking_reach_covers_the_distance_any_row_needs_to_stop(jerk):
    """Random pairs, levers and velocities: every row a pair can have (|A_ij| <= lever_kj) at
    every velocity one period can reach (|q_dot_j| <= |dq_j| + a_j dt) stops its closing speed
    within braking_reach's influence - margin, held for a period (and the jerk's ramp) and
    braked at BRAKING_SHARE of the row's acceleration (what stoppable_rows asks; the ramp at
    most twice the slowest joint's acceleration over jerk limit)."""
    rng = np.random.default_rng(21 + jerk)
    npairs, n, dt, influence, margin = 40, 7, 1e-3, 0.05, 0.01
    lever = rng.uniform(0.0, 1.2, (npairs, n)) * (rng.uniform(size=(npairs, n)) < 0.7)
    dq = rng.normal(size=n) * 1.5
    acc = rng.uniform(5.0, 20.0, n)
    jerks = rng.uniform(2000.0, 8000.0, n) if jerk else None
    out = np.zeros(npairs)
    kernels.braking_reach(lever, dq, acc, jerks, dt, BRAKING_SHARE, influence, margin, out)
    assert np.all(out >= influence)
    for k in range(npairs):
        for _ in range(200):
            A = lever[k] * rng.uniform(-1.0, 1.0, n)
            v = (np.abs(dq) + acc * dt) * rng.choice([-1.0, 1.0], n) * rng.uniform(0, 1, n) ** 0.2
            a = BRAKING_SHARE * np.abs(A) @ acc
            if a <= 0:
                continue
            tau = dt + (2.0 * np.max(np.where(A != 0.0, acc / jerks, 0.0)) if jerk else 0.0)
            s = abs(A @ v)
            assert s * tau + s * s / (2.0 * a) <= out[k] - margin + 1e-12
    still = np.zeros(npairs)
    kernels.braking_reach(np.zeros((npairs, n)), dq, acc, jerks, dt, BRAKING_SHARE, influence,
                          margin, still)
    assert np.all(still == influence)  # a pair no joint moves keeps the limit's influence


# Panda's hand sent at its full speed past a ball in its way, beside 10 rad/s^2 and
# 5,000 rad/s^3 with the default influence (50 mm): a row appearing at 50 mm could not stop a
# link closing at 1-2 m/s, and the acceleration limit yielded up to 3.4x (DLS), the pair
# coming within the easing slack of its margin. Each pair's influence now grows to the
# distance its joints' speeds need to brake (kernels.braking_reach).
@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_a_fast_arm_brakes_for_an_obstacle_within_its_acceleration_limits(method):
    import coal
    import pinocchio as pin

    panda = sjt.Robot.from_example("panda")
    n = panda.nv
    accel, jerk = np.full(n, 10.0), np.full(n, 5000.0)
    q = panda.q0.copy()
    start = panda.fk(q)
    goal = pin.SE3(start.rotation, start.translation + np.array([0.0, 0.7, 0.0]))
    ball = (coal.Sphere(0.05), pin.SE3(np.eye(3), start.translation + np.array([0.0, 0.25, 0.0])))
    limit = CollisionLimit(panda, [ball], self_collision=True, margin=MARGIN)
    solver = sjt.make_solver(method, panda, dt=DT, limits=[limit], acceleration_limits=accel,
                             jerk_limits=jerk)
    qs, conflicts = [q], 0
    for _ in range(2000):
        q = solver.step(q, goal)
        qs.append(q)
        conflicts += bool(solver.last.limit_conflicts)
    qs = np.array(qs)
    v = np.diff(qs, axis=0) / DT
    a = np.diff(np.vstack([np.zeros((1, n)), v]), axis=0) / DT
    assert np.abs(v).max() > 0.9  # fast: about 1 rad/s, more than a 50 mm band could brake
    assert np.max(np.abs(a) / accel) <= 1.001
    assert np.max(np.abs(np.diff(a, axis=0)) / DT / jerk) <= 1.001
    assert conflicts == 0
    assert _closest(panda, [ball], limit, qs) >= MARGIN - 1e-4


def _unreported_and_above(robot, qs, reported, accelerations, jerks, dt):
    """The steps above an acceleration or jerk limit, and those of them not reported."""
    n = robot.nv
    v = np.diff(qs, axis=0) / dt  # (the arms' coordinates are their tangent space)
    a = np.diff(np.vstack([np.zeros((1, n)), v]), axis=0) / dt
    j = np.diff(np.vstack([np.zeros((1, n)), a]), axis=0) / dt
    above = (np.max(np.abs(a) / accelerations, axis=1) > 1.001) | (
        np.max(np.abs(j) / jerks, axis=1) > 1.001)
    return int(above.sum()), np.flatnonzero(above & ~np.asarray(reported))


@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_every_step_above_a_limit_says_so(method):
    """Every step whose acceleration or jerk exceeds its limit names joints in
    ``limit_conflicts``: xArm7's stream beside a ball (``sjt_pin.bench.collision_stream``,
    seeds 0-2; a few did not, when after a step the rows made break the acceleration limit the
    stage took the middle of its contradicting acceleration and jerk bounds for several steps),
    and a ball driven at Panda's hand at 2 m/s, faster than Franka's acceleration limits let
    the arm retreat but not its speed limits (``sjt_pin.bench.collision_moving``), where the
    margin wins and the limits yield."""
    from sjt_pin.bench import collision_moving as moving
    from sjt_pin.bench import collision_stream as stream

    robot = sjt.Robot.from_example("xarm7")
    n = robot.nv
    for seed in range(3):
        qs, reported, _, _ = stream._run(robot, method, True, seed)
        _, unreported = _unreported_and_above(robot, qs, reported, np.full(n, stream.ACCELERATION),
                                              np.full(n, stream.JERK), stream.DT)
        assert unreported.size == 0, unreported
    panda = sjt.Robot.from_example("panda")
    driven = moving.ball(panda, 2.0, DT)
    limit = CollisionLimit(panda, driven.obstacles, margin=MARGIN)
    accelerations, jerks = moving.franka_like(panda.nv)
    solver = sjt.make_solver(method, panda, dt=DT, limits=[limit],
                             acceleration_limits=accelerations, jerk_limits=jerks)
    q, qs, reported = panda.q0.copy(), [panda.q0.copy()], []
    for pose, velocity in driven.path[:int(moving.TRAVEL / 2.0 / DT) + 200]:  # (to its stop)
        limit.move(0, pose, velocity=velocity)
        q = solver.step(q, driven.hand)
        qs.append(q)
        reported.append(bool(solver.last.limit_conflicts))
    above, unreported = _unreported_and_above(panda, np.array(qs), reported, accelerations,
                                              jerks, DT)
    assert above > 0  # (the premise: the rows made the limits yield)
    assert unreported.size == 0, unreported
