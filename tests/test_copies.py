"""Copies of a solver — pickle, deepcopy, another process — step exactly as the original."""

import copy
import pickle

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sjt_pin as sjt
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits.base import Motion
from sjt_pin.limits.collision import CollisionError

from .helpers import full_range_pair
from .test_random_urdfs import random_semantic_robot


def run(solver, q, targets):
    out = []
    for target in targets:
        q = solver.step(q, target)
        out.append(q)
    return np.array(out)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
@pytest.mark.parametrize("name, options", [
    ("sjt", {}), ("sjt", {"task": sjt.PositionTask()}), ("dls", {}),
    ("sjt", {"acceleration_limits": 10.0, "jerk_limits": 2000.0}),
])
def test_a_copy_steps_as_the_original(ur5, rng, how, name, options):
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    position = "task" in options
    targets = [ur5.fk(q) * pin.exp6(pin.Motion(rng.normal(scale=0.05, size=6)))
               for _ in range(60)]
    if position:
        targets = [t.translation for t in targets]
    original = sjt.make_solver(name, ur5, **options)
    q = run(original, q, targets[:20])[-1]  # mid-run: state to carry
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    assert type(twin) is type(original) and twin.last is None
    np.testing.assert_array_equal(run(twin, q, targets[20:]), run(original, q, targets[20:]))
    assert twin.error_norm == original.error_norm  # its own buffers, bound to its own arrays


def at_the_saddle(until):
    """UR5 at q = 0 asked to roll its tool about the lost axis (a saddle, where the transpose
    feedback needs its escape), stepped until ``until(solver.escape)``: (solver, q, target)."""
    from sjt_pin.bench.accuracy import saddle_problems

    _, robot, q, target = saddle_problems()[0]
    solver = sjt.SJTSolver(robot, dt=2e-3, feedback="transpose")
    for _ in range(5000):
        q = solver.step(q, target)
        if until(solver.escape):
            break
    return solver, q, target


def run_both(solver, twin, q, target, steps=300):
    a, b = q, q
    for _ in range(steps):
        a, b = solver.step(a, target), twin.step(b, target)
    return a, b


def test_a_copy_made_mid_escape_escapes_alike():
    """A copy made during the escape escapes alike."""
    solver, q, target = at_the_saddle(lambda escape: escape.active)
    assert solver.escape.active
    np.testing.assert_array_equal(*run_both(solver, copy.deepcopy(solver), q, target))


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_made_during_a_curvature_test_finishes_it_alike(how):
    """A copy made while the escape's curvature test is spread over the steps (a few row
    evaluations in) replays what the original had evaluated, and finds and escapes alike,
    bitwise."""
    solver, q, target = at_the_saddle(lambda escape: escape.testing)
    for _ in range(5):  # its first evaluation, its setup, the first finite differences
        q = solver.step(q, target)
    assert solver.escape.testing and not solver.escape.active
    assert solver.escape._pending[2] == 5  # noqa: SLF001 (pauses taken: a few evaluations in)
    twin = pickle.loads(pickle.dumps(solver)) if how == "pickle" else copy.deepcopy(solver)
    a, b = run_both(solver, twin, q, target)
    assert solver.escape.escapes == twin.escape.escapes == 1
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_carries_the_curvature_the_last_step_measured(panda, how):
    """Panda's JT sent 1.5 m below, its joint 2 at its range: each projected step is trusted
    only as far as the curvature the last step measured allows (the stage's sufficient
    decrease); a copy made while it settles carries that measurement and steps alike."""
    q = panda.q0.copy()
    target = panda.fk(q).translation + np.array([0.0, 0.0, -1.5])
    solver = sjt.JTSolver(panda, task=sjt.PositionTask())
    for _ in range(600):
        q = solver.step(q, target)
    ready, bent = solver._controller.curvature_memory
    assert ready and bent.shape == (3,) and np.abs(bent).max() > 0.0
    twin = pickle.loads(pickle.dumps(solver)) if how == "pickle" else copy.deepcopy(solver)
    a, b = q, q
    for _ in range(300):
        a, b = solver.step(a, target), twin.step(b, target)
    np.testing.assert_array_equal(a, b)


def test_a_second_thread_stepping_a_busy_solver_is_told(ur5):
    """While one thread's step runs (held inside a limit of the constraint stage), another
    thread's step of the same solver raises ConcurrentStepError instead of sharing its
    buffers; the first step completes as if alone, and the solver steps on afterwards."""
    import threading

    from sjt_pin.limits import Limit

    entered, release = threading.Event(), threading.Event()

    class Held(Limit):
        name = "held"
        hold = True

        def bounds(self, kinematics, motion):
            if self.hold:
                entered.set()
                release.wait(10)
            n = kinematics.model.nv
            return np.full(n, -np.inf), np.full(n, np.inf)

    limit = Held()
    solver = sjt.SJTSolver(ur5, dt=1e-3, limits=[limit])
    alone = sjt.SJTSolver(ur5, dt=1e-3)
    q0 = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q0) * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.05]))
    out = {}
    first = threading.Thread(target=lambda: out.setdefault("q", solver.step(q0, target)))
    first.start()
    assert entered.wait(10)
    with pytest.raises(sjt.ConcurrentStepError, match="another thread"):
        solver.step(q0, target)
    release.set()
    first.join(10)
    np.testing.assert_array_equal(out["q"], alone.step(q0, target))
    limit.hold = False
    np.testing.assert_array_equal(solver.step(out["q"], target), alone.step(out["q"], target))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(1, 12),
       cut=st.integers(0, 60), how=st.sampled_from(["pickle", "deepcopy"]),
       method=st.sampled_from(["sjt", "jt", "dls", "jp"]))
def test_copies_step_as_the_original_on_random_robots(seed, joints, cut, how, method):
    """On random trees (mimic, planar and locked joints), a solver copied after ``cut`` steps
    of a random target sequence — reachable and unreachable targets, so escapes and limits
    happen — makes the same next steps as the original, bitwise."""
    robot = random_semantic_robot(seed, joints)
    if robot is None:
        return
    rng = np.random.default_rng(seed)
    targets = []
    for _ in range(4):  # each held for 30 steps; the last one far out of reach
        targets += [robot.fk(robot.random_configuration(rng))] * 30
    targets[-30:] = [pin.SE3(np.eye(3), np.array([50.0, 0.0, 0.0]))] * 30
    solver = sjt.make_solver(method, robot, dt=1e-2)
    q = robot.q0.copy()
    for target in targets[:cut]:
        q = solver.step(q, target)
    twin = pickle.loads(pickle.dumps(solver)) if how == "pickle" else copy.deepcopy(solver)
    qa, qb = q.copy(), q.copy()
    for target in targets[cut:]:
        qa, qb = solver.step(qa, target), twin.step(qb, target)
        np.testing.assert_array_equal(qa, qb)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_at_a_rest_takes_the_rows_the_original_takes(how):
    """Panda held by its ranges short of a far pose target (a random full-range reach) takes
    the pose error's exact rows from that rest on: a copy made after it carries that, and goes
    on as the original does, bitwise; a solver made anew at the same q and motion would not."""
    panda = sjt.Robot.from_example("panda")
    q, goal = full_range_pair(panda, 3, 61)
    target = panda.fk(goal)
    original = sjt.make_solver("sjt", panda)
    q = run(original, q, [target] * 1150)[-1]  # (at rest with them from about 1,100 steps)
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    ahead = run(original, q, [target] * 200)
    np.testing.assert_array_equal(run(twin, q, [target] * 200), ahead)
    fresh = sjt.make_solver("sjt", panda)
    assert not np.array_equal(run(fresh, q, [target] * 200), ahead)  # (the case under test)


def _ur5_above_a_table(ur5):
    """(SJT solver, q0, target): UR5 under jerk limits, a table 13 cm under its hand, its
    target 30 cm below the hand (behind the table)."""
    hand = ur5.fk(ur5.q0).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, -0.13]))
    limit = sjt.CollisionLimit(ur5, [table])
    solver = sjt.SJTSolver(ur5, task=sjt.PositionTask(), limits=[limit],
                           acceleration_limits=10.0, jerk_limits=2000.0)
    return solver, ur5.q0.copy(), hand + [0.05, 0.02, -0.3]


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_carries_where_the_last_start_from_rest_began(ur5, how):
    """UR5 above a table under jerk limits, its target below it, comes to rest on the table's
    margin by 4 s, where its starts from rest (and the damping they raised) have gained what
    they could: a copy made there carries that memory and stays at rest as the original does
    (a fresh solver there starts again: a joint moves 2e-3 rad), bitwise."""
    original, q, target = _ur5_above_a_table(ur5)
    q = run(original, q, [target] * 5000)[-1]
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    ahead = run(original, q, [target] * 1000)
    np.testing.assert_array_equal(run(twin, q, [target] * 1000), ahead)
    assert np.abs(ahead - q).max() < 1e-9  # (at rest)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_carries_the_damping_a_failed_line_raised(ur5, how):
    """The same UR5 2 s in: its line along the table has failed once and raised the damping
    of its bounded displacement (fourfold); a copy made there goes on with that damping, and
    its next 1.5 s are the original's, bitwise."""
    original, q, target = _ur5_above_a_table(ur5)
    q = run(original, q, [target] * 2000)[-1]
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    ahead = run(original, q, [target] * 1500)
    np.testing.assert_array_equal(run(twin, q, [target] * 1500), ahead)
    assert np.abs(ahead[-1] - q).max() > 1e-3  # (it still moved)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_answers_from_the_last_rows_where_the_original_does(ur5, how):
    """A step at the configuration and motion of the last one (an arm at a bitwise rest)
    answers from the last rows without a query. A copy carries them: it answers alike, with
    its own arrays of the same limits, and its witnesses' clock stays the original's (a
    query advanced it a tick ahead); with other limits it queries."""
    q = ur5.q0.copy()
    hand = ur5.fk(q).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, -0.07]))
    limit = sjt.CollisionLimit(ur5, [table])
    kinematics = Kinematics(ur5.model)
    kinematics.update(q)

    def motion(acceleration):
        return Motion(q=q, dq=np.full(ur5.nv, 0.1), ddq=np.zeros(ur5.nv), dt=1e-3,
                      velocity_limits=np.full(ur5.nv, 3.0),
                      acceleration_limits=np.full(ur5.nv, acceleration),
                      jerk_limits=np.full(ur5.nv, 2000.0))

    same = motion(10.0)
    rows = limit.rows(kinematics, same)
    assert rows is not None
    tick = limit._tick
    _assert_same(limit.rows(kinematics, same), rows)
    assert limit._tick == tick  # (answered from the last rows)
    twin = pickle.loads(pickle.dumps(limit)) if how == "pickle" else copy.deepcopy(limit)
    carried = twin.rows(kinematics, motion(10.0))
    _assert_same(carried, rows)
    assert not any(x.flags.writeable for x in carried)  # (read-only, as the original's)
    assert twin._tick == tick
    _assert_same(twin._memories(), limit._memories())
    other = pickle.loads(pickle.dumps(limit)) if how == "pickle" else copy.deepcopy(limit)
    other.rows(kinematics, motion(12.0))
    assert other._tick == tick + 1.0  # (other limits: queried)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
@pytest.mark.parametrize("cut", [100, 300, 800, 1500])
def test_a_copy_made_on_the_way_down_to_a_table_steps_as_the_original(ur5, how, cut):
    """UR5 descending onto a table under jerk limits: a copy made on the way (the pairs'
    witnesses, the broad phase's floors and each pair's GJK warm start in play) steps as
    the original, bitwise. Before copies carried those, the copies' distances differed in
    the last bits from the first step, and the arms parted by up to 0.25 rad along the
    table's margin."""
    q = ur5.q0.copy()
    hand = ur5.fk(q).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, -0.13]))
    original = sjt.SJTSolver(ur5, task=sjt.PositionTask(), limits=[sjt.CollisionLimit(
        ur5, [table])], acceleration_limits=10.0, jerk_limits=2000.0)
    target = hand + [0.05, 0.02, -0.3]
    q = run(original, q, [target] * cut)[-1]
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    np.testing.assert_array_equal(run(twin, q, [target] * 600),
                                  run(original, q, [target] * 600))
    # and the memories behind the steps (the broad phase's floors among them: a copy without
    # them queries more pairs and steps the same here)
    _assert_same(twin.options.limits[0]._memories(), original.options.limits[0]._memories())


def _assert_same(a, b):
    """``a`` and ``b`` equal, bitwise, through dicts, lists and tuples of arrays and numbers."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            _assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b)
    else:
        assert a == b, (a, b)


@pytest.mark.parametrize("shape, options", [
    (coal.Box(0.3, 0.3, 0.02), {"acceleration_limits": 10.0, "jerk_limits": 2000.0}),
    (coal.Cylinder(0.15, 0.02), {}),
])
def test_a_copy_in_another_process_steps_as_the_original(ur5, tmp_path, shape, options):
    """A solver with a CollisionLimit pickled on the way down to a table and loaded in a fresh
    process steps there as the original does here, bitwise. Before coal's process-wide state
    was settled ahead of the limit's queries (``settle_coal``), its first distances differed
    in the last bits (box, cylinder) and the runs parted by up to 0.05 rad."""
    import subprocess
    import sys

    q = ur5.q0.copy()
    hand = ur5.fk(q).translation
    table = (shape, pin.SE3(np.eye(3), hand + [0.0, 0.0, -0.13]))
    original = sjt.SJTSolver(ur5, task=sjt.PositionTask(), limits=[sjt.CollisionLimit(
        ur5, [table])], **options)
    target = hand + [0.05, 0.02, -0.3]
    q = run(original, q, [target] * 300)[-1]
    (tmp_path / "solver.pkl").write_bytes(pickle.dumps((original, q, target)))
    script = ("import pickle, sys, numpy as np\n"
              "solver, q, target = pickle.loads(open(sys.argv[1], 'rb').read())\n"
              "out = []\n"
              "for _ in range(300):\n"
              "    q = solver.step(q, target); out.append(q)\n"
              "np.save(sys.argv[2], np.array(out))\n")
    subprocess.run([sys.executable, "-c", script, str(tmp_path / "solver.pkl"),
                    str(tmp_path / "there.npy")], check=True, timeout=300)
    np.testing.assert_array_equal(np.load(tmp_path / "there.npy"),
                                  run(original, q, [target] * 300))


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_keeps_the_margins_its_start_chose(how):
    """Panda with self-collision starts with its fifth link 24-29 mm from a finger, inside the
    30 mm margin (those pairs keep their start distance as margin): a copy made after the
    first steps keeps those margins, not its own first configuration's, and steps as the
    original, bitwise."""
    panda = sjt.Robot.from_example("panda")
    q = np.array([0.901, 0.359, 1.91, -2.02, -2.662, 0.093, 0.498, 0.034])
    limit = sjt.CollisionLimit(panda, [], self_collision=True, margin=0.03)
    original = sjt.SJTSolver(panda, limits=[limit], acceleration_limits=20.0)
    target = panda.fk(panda.q0)
    q = run(original, q, [target] * 300)[-1]
    assert 0.0 < limit.margins.min() < 0.03
    fresh = sjt.CollisionLimit(panda, [], self_collision=True, margin=0.03)
    fresh.check(q)
    assert not np.array_equal(fresh.margins, limit.margins)  # (the case under test)
    twin = pickle.loads(pickle.dumps(original)) if how == "pickle" else copy.deepcopy(original)
    np.testing.assert_array_equal(twin.options.limits[0].margins, limit.margins)
    np.testing.assert_array_equal(run(twin, q, [target] * 500), run(original, q, [target] * 500))


@pytest.mark.filterwarnings("ignore:CollisionLimit")  # (links that overlap at the start)
@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), cut=st.integers(1, 400),
       how=st.sampled_from(["pickle", "deepcopy"]),
       method=st.sampled_from(["sjt", "jt", "dls", "jp"]))
def test_copies_with_collision_step_as_the_original_on_random_trees(seed, cut, how, method):
    """On random trees (floating, planar, prismatic and mimic joints; spheres and boxes on
    their links) with self-collision, a box moving through them and acceleration and jerk
    limits, a solver copied after ``cut`` steps makes the same next steps as the original,
    bitwise."""
    from .test_collision_trees import random_tree_with_geometry

    drawn = random_tree_with_geometry(seed)
    if drawn is None:
        return
    robot, rng = drawn
    q = robot.q0.copy()
    centre = robot.fk(q).translation + rng.normal(size=3) * 0.1
    velocity = np.concatenate([rng.normal(size=3) * 0.2, np.zeros(3)])
    try:
        limit = sjt.CollisionLimit(robot, [(coal.Box(0.06, 0.06, 0.06),
                                            pin.SE3(np.eye(3), centre))], self_collision=True)
        limit.check(q)
    except (ValueError, CollisionError):  # (no pair to check; the ball on a link)
        return
    solver = sjt.make_solver(method, robot, dt=1e-3, limits=[limit],
                             acceleration_limits=np.full(robot.nv, 8.0),
                             jerk_limits=np.full(robot.nv, 4000.0))
    targets = [robot.fk(robot.random_configuration(rng)) for _ in range(3)]

    def step(solver, q, k):
        solver.options.limits[0].move(0, pin.SE3(np.eye(3), centre + velocity[:3] * k * 1e-3),
                                      velocity=velocity)
        return solver.step(q, targets[k // 200 % 3])

    for k in range(cut):
        q = step(solver, q, k)
    twin = pickle.loads(pickle.dumps(solver)) if how == "pickle" else copy.deepcopy(solver)
    qa, qb = q.copy(), q.copy()
    for k in range(cut, cut + 300):
        qa, qb = step(solver, qa, k), step(twin, qb, k)
        np.testing.assert_array_equal(qa, qb)
