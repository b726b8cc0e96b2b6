"""CollisionLimit at a blocked target: the arm comes to rest (RMS joint speed < 1e-3 rad/s over
the last second) with every checked pair at least margin - 1 mm apart, checked independently
with coal on the robot's meshes (the bench's checker, not the limit's numbers)."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench import collision as bench
from sjt_pin.bench.collision_blocked import blocked_scene as _blocked_scene
from sjt_pin.limits import CollisionLimit

pytestmark = pytest.mark.slow  # (seconds of simulated contact per scene; CI runs them)

DT = 1e-3
MARGIN = 0.01


def _run(robot, q0, target, limit, method, seconds=6.0):
    """The configurations of a run at DT (N+1, nq); ``method``: a name, or a solver."""
    solver = (sjt.make_solver(method, robot, dt=DT, limits=[limit]) if isinstance(method, str)
              else method)
    q, qs = q0.copy(), [q0.copy()]
    for k in range(int(round(seconds / DT))):
        pose, velocity = target(k * DT)
        q = solver.step(q, pose, velocity)
        qs.append(q)
    return np.array(qs)


def _rest(qs) -> float:
    """RMS joint speed over the last second (rad/s)."""
    speed = np.diff(qs[-int(round(1.0 / DT)) - 1:], axis=0) / DT
    return float(np.sqrt(np.mean(speed ** 2)))


def _closest(robot, obstacles, limit, qs) -> float:
    checker = bench.Checker(robot, obstacles, limit.pair_names)
    return min(checker.closest(q)[0] for q in qs[::10])


def _beside_the_base(panda):
    """The found case: Panda's hand sent in 1.5 s to a pose its own links block (the 6th pose
    of a seeded draw beside the start)."""
    q0 = panda.q0.copy()
    start = panda.fk(q0)
    rng = np.random.default_rng(0)
    for _ in range(6):
        t = rng.uniform([-0.25, -0.25, 0.05], [0.25, 0.25, 0.5])
        rot = pin.exp3(rng.normal(size=3) * 0.7) @ start.rotation
    return q0, bench.line_path(start, pin.SE3(rot, t), 1.5)


@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_a_target_its_own_links_block_comes_to_rest(panda, method):
    """Panda with self-collision at a target its links block: SJT slid along a face of one
    pair's hull, coal's closest points jumped to the face's other end and the next row turned
    the arm back, a 7-step cycle at 0.0146 rad/s forever (main before the witness rows)."""
    q0, target = _beside_the_base(panda)
    limit = CollisionLimit(panda, self_collision=True, margin=MARGIN)
    qs = _run(panda, q0, target, limit, method, seconds=8.0)  # at rest (0 rad/s) from 4 s
    assert _rest(qs) < 1e-3  # (it slides along its links to 0.019 of the target)
    assert _closest(panda, [], limit, qs) >= MARGIN - 1e-3


# seeds of _blocked_scene where both methods come to rest. Panda seed 14 chattered (SJT and DLS,
# main too): a 3-step cycle at 0.45 rad/s RMS with the hand still. The kernel's saturation (SNS)
# chose between scaling the whole blocked push into the box and holding joint 4 at its speed
# limit and solving again, a choice that flipped with q (task scales 0.019 and 0.074), and
# rows_step projected each of those very different steps onto the rows. The rows now correct
# SNS's first candidate, the method's step scaled as a whole into the box, continuous in the
# method's step (constraints.scaled_into): SJT 4.9e-6 rad/s at 6 s, DLS 5.9e-11 at 10 s. Seed 9,
# which slid on at 5e-3 rad/s at 12 s, now rests too (1e-13 and 0 rad/s). Before the second
# projection started from the task motion the first kept (constraints.rest_target), seeds 4, 7
# and 11 slid on too (SJT 3.8e-3 rad/s at 6 s, DLS 6e-4 steady to 10 s, SJT 3.8e-3 steady), the
# hand nearly still: the push the rows stop, projected again in the metric J^T J + rho I, came
# out as self-motion that kept the contacts. UR10 (a robot no other collision test uses): seed 2
# settles slowly (DLS 1.2e-2 rad/s at 6 s, 6e-5 at 12 s before the scaled start; now SJT 3.2e-3
# at 6 s, DLS 3.7e-4 at 10 s).
RESTING = [("panda", 0), ("panda", 1), ("panda", 2), ("panda", 3), ("panda", 4), ("panda", 5),
           ("panda", 6), ("panda", 7), ("panda", 8), ("panda", 9), ("panda", 10), ("panda", 11),
           ("panda", 14),
           ("ur5", 0), ("ur5", 1), ("ur5", 2), ("ur5", 3), ("ur5", 4), ("ur5", 5), ("ur5", 6),
           ("ur5", 7), ("ur10", 0), ("ur10", 1), ("ur10", 3)]
# arms no other collision test uses. Before the stage's projection took the Hessian of the
# method's own objective as its metric, five of UR3's ten (seeds 3, 5, 6, 7, 9) chattered
# against the obstacle at 1.6 rad/s RMS for good, and two of xArm7's (6: 1.2, 9: 4e-3 rad/s).
# Before a step that lowers the error by less than a resting arm's rate gave way to rest, Panda's
# seeds 1, 2, 7 and 11 and xArm7's seed 6 slid on at 3e-3 to 8e-2 rad/s with the hand still:
# the projection's answer lowered the linearised error by 3e-7 to 2e-5 of itself per second
# (it grew by 5e-4 per second on Panda's seed 7)
RESTING += [("ur3_gripper", seed) for seed in range(10)] + [("xarm7", seed) for seed in range(10)]


@pytest.fixture(scope="module")
def ur10() -> sjt.Robot:
    return sjt.Robot.from_example("ur10")


@pytest.fixture(scope="module")
def arms(panda, ur5, ur10) -> dict[str, sjt.Robot]:
    loaded = {"panda": panda, "ur5": ur5, "ur10": ur10}
    loaded.update((name, sjt.Robot.from_example(name)) for name in ("ur3_gripper", "xarm7"))
    return loaded


@pytest.mark.parametrize("name,seed", RESTING)
def test_random_blocked_targets_come_to_rest(name, seed, arms):
    """A target inside an obstacle, with self-collision: both methods come to rest, every
    pair at least margin - 1 mm apart (independently)."""
    robot = arms[name]
    q0, end, target, obstacle = _blocked_scene(robot, np.random.default_rng(seed))
    for method in ("sjt", "dls"):
        limit = CollisionLimit(robot, [obstacle], self_collision=True, margin=MARGIN)
        # DLS's error damping (w |e_w| L, large while the obstacle holds the arm short) slides
        # it more slowly to its rest along the obstacle: 10 s
        qs = _run(robot, q0, target, limit, method, 6.0 if method == "sjt" else 10.0)
        assert _closest(robot, [obstacle], limit, qs) >= MARGIN - 1e-3, method
        assert _rest(qs) < 1e-3, method


# seeds that settle more slowly: the speed limits cut the blocked push to about 2 % of the
# method's step (task_scale 0.023-0.025), so the arm slides along the contact at that share
# of its gain; each passes below 1e-3 rad/s between 8 and 18 s (measured on this code)
SLOW = [("ur5", 8), ("ur5", 13), ("ur10", 2)]


@pytest.mark.parametrize("name,seed", SLOW)
def test_slow_blocked_targets_come_to_rest_within_20_s(name, seed, ur5, ur10):
    robot = {"ur5": ur5, "ur10": ur10}[name]
    q0, end, target, obstacle = _blocked_scene(robot, np.random.default_rng(seed))
    for method in ("sjt", "dls"):
        limit = CollisionLimit(robot, [obstacle], self_collision=True, margin=MARGIN)
        qs = _run(robot, q0, target, limit, method, 20.0)
        assert _closest(robot, [obstacle], limit, qs) >= MARGIN - 1e-3, method
        assert _rest(qs) < 1e-3, method


def test_an_arm_at_rest_above_an_obstacle_starts_under_a_jerk_limit(arms):
    """UR10 at rest 48 mm above a 39 cm box, a target 21 cm below its hand (behind the box),
    DLS, acceleration limits 8-14 rad/s^2 and jerk limits 327 times those: the arm goes down
    onto the box and rests there, within every limit and margin.
    (Each joint clipped alone into the sliver of a box the jerk limit gives an arm at rest
    moved the hand sideways or back; settling braked that to rest, and the arm never moved:
    0.225 from the target.)"""
    robot = arms["ur10"]
    q0 = robot.q0.copy()
    hand = robot.fk(q0).translation
    box = (coal.Box(0.39, 0.39, 0.02), pin.SE3(np.eye(3), hand + [0.043, 0.016, -0.105]))
    limit = CollisionLimit(robot, [box], margin=MARGIN)
    acceleration = np.array([11.9, 10.4, 8.0, 13.6, 11.0, 9.3])
    jerk = 327.0 * acceleration
    solver = sjt.DLSSolver(robot, task=sjt.PositionTask(), limits=[limit], dt=DT,
                           acceleration_limits=acceleration, jerk_limits=jerk)
    target = hand + [-0.079, -0.021, -0.209]
    qs = _run(robot, q0, lambda t: (target, None), limit, solver, seconds=10.0)
    # (the error at rest depends on the last bits of the arithmetic: 0.134 in a fresh process,
    # 0.169 after the other tests here; the arm at rest where it started: 0.224)
    assert np.linalg.norm(robot.fk(qs[-1]).translation - target) < 0.2
    assert _rest(qs) < 1e-6
    assert _closest(robot, [box], limit, qs) >= MARGIN - 1e-3
    _, a, j = bench.rates(robot.model, qs, DT)
    assert np.all(np.abs(a) <= acceleration * (1 + 1e-9))
    assert np.all(np.abs(j) <= jerk * (1 + 1e-9))


@pytest.mark.parametrize("name, jerk, below", [
    ("ur5", 20_000.0, 0.23),  # each joint clipped alone: braked to rest at 0.237, 8.7 mm above
    ("xarm7", None, 0.21),    # a line not judged by the error measured: still sliding at 8 s
    # its fingers start 2.9 mm inside the margin: pushed out, it rested at 0.3076, judged
    # against the error before the push
    ("panda", 5_000.0, 0.304),
])
def test_an_arm_sent_through_a_table_slides_on_it_and_rests(name, jerk, below, arms):
    """An arm (SJT), a table 13 cm under its hand, a target 30 cm below the hand (behind the
    table), 10 rad/s^2 and a jerk limit or none: the joints move along one line toward the
    bounded displacement's velocity, the arm slides along the table and comes to rest, below
    ``below`` from the target (its start: 0.305), within every limit and the margin (Panda's
    fingers start inside it)."""
    robot = arms[name]
    q0 = robot.q0.copy()
    hand = robot.fk(q0).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, -0.13]))
    limit = CollisionLimit(robot, [table], margin=MARGIN)
    smooth = {} if jerk is None else {"jerk_limits": jerk}
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), limits=[limit], dt=DT,
                           acceleration_limits=10.0, **smooth)
    target = hand + [0.05, 0.02, -0.3]
    qs = _run(robot, q0, lambda t: (target, None), limit, solver, seconds=8.0)
    assert np.linalg.norm(robot.fk(qs[-1]).translation - target) < below
    assert np.abs(np.diff(qs[-501:], axis=0)).max() / DT < 1e-6  # at rest, the last 0.5 s
    start = _closest(robot, [table], limit, qs[:1])  # (out of the margin within 0.2 s)
    assert _closest(robot, [table], limit, qs) >= min(start, MARGIN - 1e-3)
    assert _closest(robot, [table], limit, qs[200:]) >= MARGIN - 1e-3
    _, a, j = bench.rates(robot.model, qs, DT)
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    if jerk is not None:
        assert np.abs(j).max() <= jerk * (1 + 1e-9)


@pytest.mark.parametrize("name, table_z, target, jerk, below, seconds", [
    # pushed out, the arm braked, and from that rest it never started again (0.304)
    ("ur5", -0.0610, [0.05, 0.02, -0.3], 5_000.0, 0.26, 8.0),
    # its line along the table failed (the error rose) and braked it to rest at 0.2305; with
    # the damping raised it slides on and rests at 0.1519 by 10 s
    ("ur10", -0.0644, [0.2, 0.1, -0.15], 1_000.0, 0.153, 11.0),
])
def test_an_arm_started_inside_a_tables_margin_goes_on_to_its_constrained_minimum(
        name, table_z, target, jerk, below, seconds, arms):
    """An arm (SJT) whose hand starts 2 mm inside a table's 10 mm margin, a target below the
    table, 10 rad/s^2 and a jerk limit: pushed out, it slides along the table and rests at the
    constrained minimum the same solver without acceleration limits finds from there (UR5
    0.2585, UR10 0.1519), within every limit and, from 0.2 s on, the margin."""
    robot = arms[name]
    q0 = robot.q0.copy()
    hand = robot.fk(q0).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, table_z]))
    limit = CollisionLimit(robot, [table], margin=MARGIN)
    assert _closest(robot, [table], limit, [q0]) < MARGIN - 1.9e-3  # (the case under test)
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), limits=[limit], dt=DT,
                           acceleration_limits=10.0, jerk_limits=jerk)
    goal = hand + target
    with pytest.warns(UserWarning, match="margin"):
        qs = _run(robot, q0, lambda t: (goal, None), limit, solver, seconds=seconds)
    assert np.linalg.norm(robot.fk(qs[-1]).translation - goal) < below
    assert np.abs(np.diff(qs[-501:], axis=0)).max() / DT < 1e-6  # at rest, the last 0.5 s
    assert _closest(robot, [table], limit, qs[200:]) >= MARGIN - 1e-3
    _, a, j = bench.rates(robot.model, qs, DT)
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    assert np.abs(j).max() <= jerk * (1 + 1e-9)
