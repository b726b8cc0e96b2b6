"""The compiled pieces of a step with collision dampers, against their numpy references: the
damper rows (kernels.damper_rows), the witness rows, the broad phase that CollisionLimit skips
while nothing can have come within influence and its bookkeeping; rows no velocity can meet
leave the step within the speed limits."""


import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels as K
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits.base import Motion
from sjt_pin.limits.collision import CollisionLimit
from sjt_pin.solvers import make_solver


def damper_rows_reference(J: np.ndarray, support: np.ndarray, pairs: np.ndarray, rate: float
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``kernels.damper_rows`` in numpy: coal's normal ``n`` points from geometry a to b, so
    ``n^T (v_a - v_b) = -d_dot``; the WORLD Jacobian of joint j (its supports' columns) moves
    a point p fixed to it at ``v_O + w x p``, so ``n.v(p) = n.v_O + (p x n).w``; a row whose
    norm is at most ``kernels.ROUNDING_LEVER`` (m per unit of q_dot) is rounding and set to 0,
    and a row inside its margin with a lever below ``kernels.PUSH_LEVER`` only keeps its pair
    from closing."""
    pairs = np.atleast_2d(pairs)
    n = pairs[:, 4:7]
    ends = []
    for side, joints in ((pairs[:, 7:10], pairs[:, 2]), (pairs[:, 10:13], pairs[:, 3])):
        u = np.hstack([n, np.cross(side, n)])
        ends.append((u @ J) * support[joints.astype(int)])
    A = ends[0] - ends[1]
    lever = np.linalg.norm(A, axis=1)
    A[lever <= K.ROUNDING_LEVER] = 0.0  # (rounding, not a lever)
    b = rate * (pairs[:, 0] - pairs[:, 1])
    b[(b < 0.0) & (lever < K.PUSH_LEVER)] = 0.0  # (no lever to push with)
    return A, b


def test_compiled_kernels_name_the_argument_that_does_not_fit():
    with pytest.raises(ValueError, match="names joint 9"):
        pairs = np.zeros((1, 13))
        pairs[0, 2] = 9
        K.damper_rows(np.zeros((6, 3)), np.zeros((4, 3)), pairs, 1.0, np.zeros((1, 3)),
                      np.zeros(1))
    with pytest.raises(ValueError, match="near\\[0\\] = 5 is no pair"):
        K.near_pairs(np.zeros(2), K.Skip(np.zeros(2), np.full(2, -np.inf), np.full(2, np.inf),
                                         np.zeros((3, 2)), np.ones(3), [5], np.zeros(3),
                                         np.zeros(2)),
                     np.full(3, 0.05))
    with pytest.raises(ValueError, match="do not fit"):
        K.collision_rows(K.CollisionTables(
            geometry=None, geometry_data=None, model=None, update=pin.updateGeometryPlacements,
            floor=np.zeros(3), margins=np.zeros(2), joints=np.zeros((3, 2), dtype=np.int64),
            rows=np.zeros((3, 13)), memory=np.zeros((3, 6)), state=np.zeros((3, 2)),
            owners=np.zeros(3), support=np.zeros((2, 2)), mimic=None, keep=0.02, apart=1e-4,
            witnesses=True), [0], None, 1.0, np.full(3, 0.05), 1.0, None, pin.computeDistance)
    with pytest.raises(ValueError, match="do not fit"):
        K.braking_reach(np.zeros((3, 2)), np.zeros(2), np.ones(2), None, 1e-3, 0.5, 0.05, 0.01,
                        np.zeros(2))
    with pytest.raises(ValueError, match="rows\\[0\\] names joint 7; poses has 2"):
        rows = np.zeros((4, 13))
        rows[0, 3] = 7
        K.witness_rows(None, np.zeros((2, 16)), rows, [0], np.zeros((3, 6)), np.zeros((1, 2)),
                       1.0, 0.02, 1e-4, np.zeros(3))


def test_the_compiled_damper_rows_are_the_numpy_ones(panda):
    """At random Panda configurations with a ball near the hand and self-collision: the rows
    the limit returns are the numpy formula's on the same pairs, closest points and normals."""
    rng = np.random.default_rng(14)
    model = panda.model
    for _ in range(10):
        q = panda.random_configuration(rng)
        data = model.createData()
        pin.computeJointJacobians(model, data, q)
        hand = pin.updateFramePlacement(model, data, model.getFrameId(panda.ee_frame))
        ball = (coal.Sphere(0.03), pin.SE3(np.eye(3), hand.translation + [0.0, 0.0, 0.06]))
        limit = CollisionLimit(panda, [ball], self_collision=True, margin=0.0, influence=0.1)
        limit.margins[:] = 0.0  # the start rule keeps the pairs (none checked at this q)
        limit._checked = True
        kin = Kinematics(model)
        kin.update(q)
        rows = limit.rows(kin, Motion(q, np.zeros(panda.nv), np.zeros(panda.nv), 1e-3))
        assert rows is not None
        A, b = rows
        pairs = []
        pin.updateGeometryPlacements(model, kin.data, limit.geometry, limit.geometry_data)
        for k in limit.active:
            res = pin.computeDistance(limit.geometry, limit.geometry_data, k)
            a, g = limit.pairs[k]
            pairs.append([res.min_distance, limit.margins[k], limit._joint[a], limit._joint[g],
                          *res.normal, *res.getNearestPoint1(), *res.getNearestPoint2()])
        A_ref, b_ref = damper_rows_reference(kin.data.J, limit._support, np.array(pairs),
                                             limit.gain / 1e-3)
        if limit._mimic is not None:
            A_ref = A_ref @ limit._mimic
        np.testing.assert_allclose(A, A_ref, atol=1e-12)
        np.testing.assert_allclose(b, b_ref, atol=1e-9)


@pytest.fixture(scope="module")
def solo12() -> sjt.Robot:
    return sjt.Robot.from_example("solo12", ee_frame="FR_FOOT")


def _walk_scene(robot, rng):
    """A walk's start, a ball and a drift per step: on Panda and UR5 a random start and a ball
    10 cm beside the hand, no drift; on the revolute-prismatic arm (and its variant with a
    continuous wrist) the slide at 1.4 m and the first joint swinging 3 mrad a step from 0.9
    rad (plus the walk's noise) through a ball."""
    if robot.name in ("revolute_prismatic", "continuous_wrist"):
        q = pin.neutral(robot.model)
        q[:2] = 0.9, 1.4
        ball = (coal.Sphere(0.1), pin.SE3(np.eye(3), np.array([0.0, 1.4, 0.0])))
        return q, ball, np.array([0.003, 0.0, 0.0])
    q = robot.random_configuration(rng)
    if robot.name == "solo12":  # its free-flying base 1.5 m above the box of its position
        q[2] += 1.5  # limits (+-1 m), which the levers do not depend on
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    hand = pin.updateFramePlacement(robot.model, data, robot.model.getFrameId(robot.ee_frame))
    ball = (coal.Sphere(0.05), pin.SE3(np.eye(3), hand.translation + [0.1, 0.0, 0.0]))
    return q, ball, np.zeros(robot.nv)


def _walk_step(robot, q, drift, jump, rng):
    """The walk's next configuration: ``q`` moved by ``drift`` plus noise of up to ``jump`` on
    each velocity coordinate, its bounded coordinates clipped into their range."""
    model = robot.model
    q = pin.integrate(model, q, drift + rng.uniform(-jump, jump, robot.nv))
    bounded = np.zeros(robot.nq, dtype=bool)
    for joint in model.joints[1:]:
        if joint.nq == joint.nv:
            bounded[joint.idx_q:joint.idx_q + joint.nq] = True
    return np.where(bounded, np.clip(q, model.lowerPositionLimit, model.upperPositionLimit), q)


@pytest.mark.parametrize("name", ["panda", "ur5", "revolute_prismatic", "continuous_wrist",
                                  "solo12"])
def test_the_broad_phase_it_skips_never_misses_a_pair_within_influence(
        name, panda, ur5, revolute_prismatic, continuous_wrist, solo12):
    """Along random joint-space walks (steps of up to 3 mrad, every 50th up to 0.3 rad), the
    pairs the limit measures at each configuration hold every pair whose exact distance is
    below influence (brute force over every pair), although most steps reuse the last broad
    phase."""
    robot = {"panda": panda, "ur5": ur5, "revolute_prismatic": revolute_prismatic,
             "continuous_wrist": continuous_wrist, "solo12": solo12}[name]
    rng = np.random.default_rng(15)
    q, ball, drift = _walk_scene(robot, rng)
    data = robot.model.createData()
    limit = CollisionLimit(robot, [ball], self_collision=True, influence=0.08)
    calls = [0]
    full = limit._broad_phase

    def counted(data, influence):
        calls[0] += 1
        return full(data, influence)

    limit._broad_phase = counted
    steps = 300
    for step in range(steps):
        jump = 0.3 if step % 50 == 0 else 0.003  # mostly small steps, now and then a leap
        q = _walk_step(robot, q, drift, jump, rng)
        pin.computeJointJacobians(robot.model, data, q)
        near = set(limit._near(data, q, limit._influence).tolist())
        pin.updateGeometryPlacements(robot.model, data, limit.geometry, limit.geometry_data)
        for k in range(len(limit.pairs)):
            d = pin.computeDistance(limit.geometry, limit.geometry_data, k).min_distance
            if d < limit.influence:
                assert k in near, (limit.pair_names[k], d)
    assert calls[0] < steps / 2  # the skip did skip


@pytest.mark.parametrize("name", ["panda", "ur5", "revolute_prismatic", "continuous_wrist",
                                  "solo12"])
def test_rows_hold_every_pair_within_influence_though_most_are_not_queried(
        name, panda, ur5, revolute_prismatic, continuous_wrist, solo12):
    """Along random joint-space walks (steps of up to 3 mrad, every 50th up to 0.3 rad), the
    rows are those of exactly the pairs whose exact distance is below influence (brute force
    over every pair), although a pair last measured far enough beyond influence is not
    queried again until its bound reaches that gap."""
    robot = {"panda": panda, "ur5": ur5, "revolute_prismatic": revolute_prismatic,
             "continuous_wrist": continuous_wrist, "solo12": solo12}[name]
    rng = np.random.default_rng(16)
    q, ball, drift = _walk_scene(robot, rng)
    data = robot.model.createData()
    limit = CollisionLimit(robot, [ball], self_collision=True, influence=0.08)
    limit._checked = True  # every pair stays, the ball wherever the walk takes the arm
    queries, candidates, within = [0], 0, 0
    compute = pin.computeDistance

    def counted(*args):
        queries[0] += 1
        return compute(*args)

    kin = Kinematics(robot.model)
    motion = Motion(q, np.zeros(robot.nv), np.zeros(robot.nv), 1e-3)
    probe = limit.geometry.copy()
    probe_data = limit.geometry_data.copy()
    for step in range(300):
        jump = 0.3 if step % 50 == 0 else 0.003
        q = _walk_step(robot, q, drift, jump, rng)
        kin.update(q)
        pin.computeDistance = counted
        try:
            limit.rows(kin, motion)
        finally:
            pin.computeDistance = compute
        candidates += limit._near(kin.data, q, limit._influence).size
        pin.updateGeometryPlacements(robot.model, data, probe, probe_data, q)
        close = {k for k in range(len(limit.pairs))
                 if compute(probe, probe_data, k).min_distance < limit.influence}
        assert set(limit.active) == close, step
        within += len(close)
    if name in ("revolute_prismatic", "continuous_wrist"):  # its one pair near the ball:
        assert within > 20  # every candidate is within influence (and queried)
    else:
        assert within > 100  # pairs were within influence
        assert queries[0] < 0.6 * candidates  # and most candidates were not queried


@pytest.mark.parametrize("name", ["panda", "ur5", "revolute_prismatic"])
def test_the_compiled_refresh_lists_what_the_numpy_broad_phase_lists(
        name, panda, ur5, revolute_prismatic, monkeypatch):
    """Along random walks (every 50th step a leap, so the broad phase runs again and again), a
    limit whose broad phase hands its candidates and aged floors to kernels.refresh_pairs gives
    the same rows, pairs within influence and pairs queried as one that does it in numpy
    (_near, then _aged)."""
    robot = {"panda": panda, "ur5": ur5, "revolute_prismatic": revolute_prismatic}[name]
    rng = np.random.default_rng(17)
    q, ball, drift = _walk_scene(robot, rng)
    compiled = CollisionLimit(robot, [ball], self_collision=True, influence=0.08)
    numpy_path = CollisionLimit(robot, [ball], self_collision=True, influence=0.08)
    for limit in (compiled, numpy_path):
        limit._checked = True  # every pair stays, the ball wherever the walk takes the arm
    kin = Kinematics(robot.model)
    motion = Motion(q, np.zeros(robot.nv), np.zeros(robot.nv), 1e-3)
    import sjt_pin.limits.collision_broad_phase as broad_phase
    refresh = broad_phase.refresh_pairs
    refreshed, rows_seen = [0], 0

    def counted(*args):
        refreshed[0] += 1
        return refresh(*args)

    for step in range(300):
        q = _walk_step(robot, q, drift, 0.3 if step % 50 == 0 else 0.003, rng)
        kin.update(q)
        monkeypatch.setattr(broad_phase, "refresh_pairs", counted)
        a = compiled.rows(kin, motion)
        monkeypatch.setattr(broad_phase, "refresh_pairs", lambda *args: None)
        b = numpy_path.rows(kin, motion)
        assert (a is None) == (b is None), step
        assert compiled.active == numpy_path.active and compiled.within == numpy_path.within
        np.testing.assert_array_equal(compiled._floor, numpy_path._floor)
        if a is not None:
            rows_seen += 1
            np.testing.assert_array_equal(a[0], b[0])
            np.testing.assert_array_equal(a[1], b[1])
    assert refreshed[0] >= 6 and rows_seen >= 10  # the refresh ran, and pairs came near


def test_near_pairs_answers_the_same_with_its_prefilter():
    """near_pairs with the prefilter (a ninth item of skip: the lever test ordered by each
    pair's slack over its lever's norm, the pairs far beyond reach not summed) answers exactly
    what the whole test answers, on random levers, gaps (some infinite, some below influence)
    and moves, a tenth of them scaled onto a pair's boundary to the last bits; and the same
    floors after. A prefilter made for other influences is not used."""
    rng = np.random.default_rng(19)
    decided = {None: 0, "list": 0}
    for _ in range(300):
        n, npairs = int(rng.integers(1, 9)), int(rng.integers(1, 40))
        ref = rng.normal(size=n)
        lever = rng.uniform(0.0, 1.5, (npairs, n)) * (rng.random((npairs, n)) < 0.8)
        gap = rng.uniform(-0.01, 0.4, npairs)
        gap[rng.random(npairs) < 0.2] = np.inf
        influence = np.full(npairs, 0.05)
        near = sorted(rng.choice(npairs, int(rng.integers(0, npairs + 1)), replace=False)
                      .tolist())
        prefilter = np.full(1 + 3 * npairs, -1.0)
        floor, floor_q = rng.uniform(-0.1, 0.3, npairs), ref.copy()
        for _ in range(8):
            move = rng.normal(size=n) * rng.uniform(0.0, 0.05)
            k = int(rng.integers(npairs))
            acc = lever[k] @ np.abs(move)
            if rng.random() < 0.1 and acc > 0 and np.isfinite(gap[k]) and gap[k] > 0.05:
                move *= (gap[k] - 0.05) / acc  # pair k's bound on its gap, up to rounding
            q = ref + move
            answers = []
            for extra in ((), (prefilter,)):
                f, fq = floor.copy(), floor_q.copy()
                skip = K.Skip(ref, ref - 1.0, ref + 1.0, lever, gap, near, f, fq, *extra)
                answers.append((K.near_pairs(q, skip, influence), f, fq))
            assert answers[0][0] == answers[1][0]
            np.testing.assert_array_equal(answers[0][1], answers[1][1])
            np.testing.assert_array_equal(answers[0][2], answers[1][2])
            decided[None if answers[0][0] is None else "list"] += 1
        assert prefilter[0] == 1.0  # built once, on the first call
    assert min(decided.values()) > 200  # both answers came often
    ref, prefilter = np.zeros(2), np.full(10, -1.0)
    skip = (ref, ref - 1.0, ref + 1.0, np.ones((3, 2)), np.full(3, 0.3), [], np.zeros(3),
            np.zeros(2), prefilter)
    assert K.near_pairs(ref, K.Skip(*skip), np.full(3, 0.05)) == [] and prefilter[0] == 1.0
    assert K.near_pairs(ref, K.Skip(*skip), np.full(3, 1.0)) is None  # other influences
    with pytest.raises(ValueError, match="do not fit"):
        K.near_pairs(ref, K.Skip(*skip[:8], np.zeros(9)), np.full(3, 0.05))


def test_refresh_pairs_is_the_numpy_bookkeeping():
    """kernels.refresh_pairs against its formula on random floors, gaps and levers: the
    candidates (gap below influence plus the skin, their gaps then inf), the floors kept or
    forgotten, aged and compared with influence; None, with nothing changed, outside the box."""
    rng = np.random.default_rng(18)
    for trial in range(200):
        n, npairs = int(rng.integers(1, 8)), int(rng.integers(1, 30))
        q, start = rng.normal(size=n), rng.normal(size=n)
        lever = rng.uniform(0.0, 1.0, (npairs, n))
        gap = rng.uniform(-0.05, 0.3, npairs)
        influence = np.full(npairs, 0.05)
        floor = rng.uniform(-0.1, 0.5, npairs)
        kept = sorted(rng.choice(npairs, int(rng.integers(0, npairs + 1)), replace=False)
                      .tolist()) if trial % 4 else None
        aged = trial % 3 != 0
        floor_q = start.copy() if aged else None
        near = np.flatnonzero(gap < influence + 0.02)
        expect_floor = np.full(npairs, -np.inf)
        if kept is not None:
            expect_floor[kept] = floor[kept]
        if aged:
            expect_floor[near] -= lever[near] @ np.abs(q - start)
        listed = near[expect_floor[near] <= influence[near]] if aged else near
        expect_gap = gap.copy()
        expect_gap[near] = np.inf
        out = K.refresh_pairs(q, q - 1.0, q + 1.0, gap, influence, 0.02, floor, kept, floor_q,
                              lever)
        assert out == (near.tolist(), listed.tolist())
        np.testing.assert_allclose(floor, expect_floor, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(gap, expect_gap)
        if aged:
            np.testing.assert_array_equal(floor_q, q)
    before = floor.copy()
    assert K.refresh_pairs(q, q + 1.0, q + 2.0, gap, influence, 0.02, floor, None, None,
                           lever) is None
    np.testing.assert_array_equal(floor, before)
    with pytest.raises(ValueError, match="kept\\[0\\] = 99 is no pair"):
        K.refresh_pairs(q, q - 1.0, q + 1.0, gap, influence, 0.02, floor, [99], None, lever)
    with pytest.raises(ValueError, match="do not fit"):
        K.refresh_pairs(q, q - 1.0, q + 1.0, gap[:-1], influence, 0.02, floor, None, None,
                        lever)


def _witness_reference(poses, rows, found, memory, state, tick, keep, apart):
    """kernels.witness_rows in numpy (limits/collision.py, "Witnesses")."""
    W = memory.shape[0] // state.shape[0]
    out, owners = [r.copy() for r in rows[:len(found)]], []
    for i, k in enumerate(found):
        row, k = rows[i], int(k)
        if state[k, 0] < 0:  # a pair that never remembers (unique closest points)
            continue
        H = [poses[int(row[2])].reshape(4, 4), poses[int(row[3])].reshape(4, 4)]
        now = np.concatenate([H[s][:3, :3].T @ (row[7 + 3 * s:10 + 3 * s] - H[s][:3, 3])
                              for s in (0, 1)])
        filled = int(state[k, 0]) if state[k, 1] == tick - 1 else 0
        if row[0] - row[1] >= keep:
            state[k] = 0, tick
            continue
        kept = []
        for m in memory[W * k:W * k + filled]:
            pa, pb = H[0][:3, :3] @ m[:3] + H[0][:3, 3], H[1][:3, :3] @ m[3:] + H[1][:3, 3]
            sep = row[4:7] @ (pb - pa)
            if np.abs(m - now).max() > apart and sep - row[0] < keep:
                extra = row.copy()
                extra[0], extra[7:10], extra[10:] = sep, pa, pb
                out.append(extra)
                owners.append(k)
                kept.append(m.copy())
        kept = kept[max(len(kept) - (W - 1), 0):] + [now]
        memory[W * k:W * k + len(kept)] = kept
        state[k] = len(kept), tick
    return np.array(out), owners


@pytest.mark.parametrize("name", ["panda", "ur5", "revolute_prismatic", "continuous_wrist"])
def test_a_row_left_out_could_not_bind_at_the_speed_limits(
        name, panda, ur5, revolute_prismatic, continuous_wrist):
    """Along random walks near a ball (with self-collision), a pair within influence whose row
    is left out for a solver with speed limits v has a row (the one the limit gives without
    speed limits, at the same configuration) that no velocity within them breaks:
    sum_j |A_kj| v_j <= b_k; the pairs within influence are the same with and without."""
    robot = {"panda": panda, "ur5": ur5, "revolute_prismatic": revolute_prismatic,
             "continuous_wrist": continuous_wrist}[name]
    rng = np.random.default_rng(17)
    q, ball, drift = _walk_scene(robot, rng)
    limit = CollisionLimit(robot, [ball], self_collision=True, influence=0.08)
    limit._checked = True  # every pair stays, the ball wherever the walk takes the arm
    speeds = np.where(np.isfinite(robot.velocity_limits), robot.velocity_limits, 2.0)
    kin = Kinematics(robot.model)
    bounded = Motion(q, np.zeros(robot.nv), np.zeros(robot.nv), 1e-3, velocity_limits=speeds)
    free = Motion(q, np.zeros(robot.nv), np.zeros(robot.nv), 1e-3)
    left_out = kept = 0
    for step in range(300):
        q = _walk_step(robot, q, drift, 0.3 if step % 50 == 0 else 0.003, rng)
        kin.update(q)
        limit.rows(kin, bounded)
        active, within = list(limit.active), list(limit.within)
        rows = limit.rows(kin, free)
        assert limit.within == within and set(active) <= set(within)
        if rows is None:
            continue
        A, b = rows
        assert limit.active == within  # (without speed limits every pair has its row)
        for i, k in enumerate(within):
            if k in active:
                kept += 1
            else:
                left_out += 1
                assert np.abs(A[i]) @ speeds <= b[i] * (1 + 1e-12), limit.pair_names[k]
    assert left_out > 0  # rows were left out
    if name in ("panda", "ur5"):
        assert kept > 0  # and others kept


def test_the_compiled_witness_rows_are_the_numpy_ones():
    """Random poses, rows and memories, some stale (a pair the previous call missed), some
    witnesses too close to this step's points or too far from contact, one pair that never
    remembers: the same rows, owners, memory and state, over several calls."""
    rng = np.random.default_rng(3)
    njoints, npairs, W = 5, 6, 3
    memory = rng.normal(size=(npairs * W, 6)) * 0.05
    state = np.column_stack([rng.integers(0, W + 1, npairs), np.full(npairs, 4.0)])
    state[1, 1] = 2.0  # stale
    state[4, 0] = -1.0  # never remembers
    ref_memory, ref_state = memory.copy(), state.copy()
    extra = 0
    for tick in (5.0, 6.0, 7.0):
        poses = np.zeros((njoints, 4, 4))
        for j in range(njoints):
            poses[j] = pin.SE3(pin.exp3(rng.normal(size=3) * 0.1), rng.normal(size=3)).homogeneous
        found = rng.permutation(npairs)[:4].astype(float)
        rows = np.zeros((npairs * (1 + W), 13))
        for i, k in enumerate(found):
            n = rng.normal(size=3)
            rows[i, :4] = rng.uniform(0.0, 0.04), 0.01, *rng.integers(0, njoints, 2)
            rows[i, 4:7] = n / np.linalg.norm(n)
            rows[i, 7:13] = rng.normal(size=6) * 0.05
            if k == found[0]:  # this step's points where one remembered pair is
                joints = rows[i, 2:4].astype(int)
                m = memory[W * int(k)]
                rows[i, 7:10] = poses[joints[0]][:3, :3] @ m[:3] + poses[joints[0]][:3, 3]
                rows[i, 10:13] = poses[joints[1]][:3, :3] @ m[3:] + poses[joints[1]][:3, 3]
        flat = poses.reshape(njoints, 16)
        want, want_owners = _witness_reference(flat, rows, found, ref_memory, ref_state, tick,
                                               0.02, 1e-4)
        owners = np.zeros(npairs * W)
        total = K.witness_rows(None, flat, rows, found.astype(int).tolist(), memory, state,
                               tick, 0.02, 1e-4, owners)
        assert total == len(want)
        np.testing.assert_allclose(rows[:total], want, atol=1e-12)
        assert owners[:total - len(found)].astype(int).tolist() == want_owners
        extra += total - len(found)
        np.testing.assert_allclose(state, ref_state)
        for k in range(npairs):  # the remembered points (those counted)
            count = int(state[k, 0])
            np.testing.assert_allclose(memory[W * k:W * k + count],
                                       ref_memory[W * k:W * k + count], atol=1e-12)
    assert extra > 0  # some remembered points became rows
    assert state[4, 0] == -1.0  # (found on some call)


@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_rows_no_velocity_can_meet_leave_the_step_within_the_speed_limits(method, panda):
    """The limit first evaluated on another Kinematics (at Panda's q0, where it takes its start)
    and then stepped from a configuration whose link 6 is inside the base: that pair's row asks
    for a separation no joint speed allows, the projection's QP has no answer, and its dual
    once diverged into a step of several radians (Romeo: 2.6e5). Every step stays within the
    URDF's speed limits."""
    q = np.array([1.111, -1.614, 2.819, -2.779, -2.223, 1.902, -0.285, 0.021])
    limit = CollisionLimit(panda, self_collision=True, margin=0.01)
    other = Kinematics(panda.model)
    other.update(panda.q0)
    limit.rows(other, Motion(panda.q0, np.zeros(panda.nv), np.zeros(panda.nv), 1e-3))
    solver = make_solver(method, panda, dt=1e-3, limits=[limit])
    target = panda.fk(q)
    broken = 0
    for _ in range(20):
        q_next = solver.step(q, target)
        step = pin.difference(panda.model, q, q_next)
        assert np.all(np.isfinite(step))
        assert np.all(np.abs(step) <= panda.velocity_limits * 1e-3 * (1 + 1e-9))
        rows = limit.rows(solver.stack.kinematics, solver._motion)
        broken += rows is not None and bool(np.any(rows[0] @ (step / 1e-3) > rows[1] + 1e-6))
        q = q_next
    assert broken  # the rows could not all hold: the bounds won


def test_the_crowded_bench_scene_is_seeded_and_clear_of_the_robot(panda):
    """bench collision's crowd: the asked number of obstacles, each more than its clearance
    from the robot at the start (the limit's own distances), the same for the same seed."""
    from sjt_pin.bench.collision import crowd
    from sjt_pin.limits import CollisionLimit

    obstacles = crowd(panda, panda.q0, count=4, clearance=0.06, seed=3)
    assert len(obstacles) == 4
    limit = CollisionLimit(panda, obstacles, margin=0.0)
    assert min(d.distance for d in limit.distances(panda.q0)) > 0.06
    again = crowd(panda, panda.q0, count=4, clearance=0.06, seed=3)
    assert all(np.array_equal(a[1].homogeneous, b[1].homogeneous)
               for a, b in zip(obstacles, again, strict=True))
