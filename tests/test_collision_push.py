"""A pair inside its margin is pushed out only by a row whose lever can take it there
(``kernels.damper_rows``: ``PUSH_LEVER``), and a row's rounding is not a lever
(``ROUNDING_LEVER``): arms started inside a table's margin with a link its joints only turn
about a point near the table."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
from sjt_pin.bench import collision as bench
from sjt_pin.limits import CollisionLimit

DT, MARGIN, GAIN = 1e-3, 0.01, 0.5


def _rows(J, support, pairs):
    A, b = np.empty((len(pairs), J.shape[1])), np.empty(len(pairs))
    kernels.damper_rows(J, support, np.asarray(pairs, dtype=float), GAIN / DT, A, b)
    return A, b


def _turning_link(reach: float, distance: float) -> np.ndarray:
    """A pair row: a link turned by joint 1 (about y through the origin), its closest point
    ``reach`` (m) along x from the axis, ``distance`` (m) above a table below it."""
    return np.array([distance, MARGIN, 1, 0, 0.0, 0.0, -1.0, reach, 0.0, 0.0, reach, 0.0,
                     -distance])


def test_a_push_its_lever_cannot_make_only_stops_the_pair_closing():
    """Inside the margin a row pushes its pair out (b < 0: the damper's gain (d - margin) /
    dt) where its lever |A_i| is at least PUSH_LEVER, 1 cm per unit of joint motion; below,
    a centimetre's push takes more than a radian, over which the row's linearisation does not
    hold, and the row only keeps the pair from closing (b = 0). Outside the margin the lever
    does not matter."""
    assert kernels.PUSH_LEVER == 0.01
    J = np.zeros((6, 2))
    J[4, 0] = 1.0  # joint 0 of the columns (model joint 1) turns about y
    support = np.array([[0.0, 0.0], [1.0, 0.0]])  # (model joint 0: the world)
    inside, outside = MARGIN - 0.002, MARGIN + 0.002
    pairs = [_turning_link(0.3, inside), _turning_link(0.0015, inside),
             _turning_link(0.0015, outside)]
    A, b = _rows(J, support, pairs)
    np.testing.assert_allclose(np.abs(A[:, 0]), [0.3, 0.0015, 0.0015], rtol=1e-12)
    assert b[0] == pytest.approx(-GAIN * 0.002 / DT)  # pushed out
    assert b[1] == 0.0  # (Z1's upper arm: 1.5 mm/rad) held
    assert b[2] == pytest.approx(GAIN * 0.002 / DT)


def test_a_row_of_rounding_is_zero_and_holds_nothing():
    """A row whose norm is at most ROUNDING_LEVER (m per unit of q_dot) is rounding: a joint
    that turns a pair's closest point about the pair's normal gives 0, not 1e-15. Inside the
    margin that rounding, held from closing, bound Kinova's base turn (which turns its first
    link about its own axis, 2 mm inside a table's margin) to one direction."""
    assert kernels.ROUNDING_LEVER == 1e-12
    J = np.zeros((6, 2))
    J[5, 0] = 1.0  # joint 0 turns about z through the origin
    J[2, 1] = 1.0  # joint 1 lifts along z
    support = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])  # (the world, joint 1, joint 2)
    normal = [2e-14, 0.0, -1.0]  # n from a down to the table, z but for rounding
    turned = [MARGIN - 0.002, MARGIN, 1, 0, *normal, 0.0, 0.05, 0.1, 0.0, 0.05, 0.098]
    lifted = [MARGIN - 0.002, MARGIN, 2, 0, *normal, 0.0, 0.05, 0.1, 0.0, 0.05, 0.098]
    assert np.cross(turned[7:10], normal)[2] == pytest.approx(-1e-15)  # (the rounding)
    A, b = _rows(J, support, [turned, lifted])
    assert np.all(A[0] == 0.0) and b[0] == 0.0  # (0 <= 0 whatever the turn)
    assert A[1, 1] == -1.0 and A[1, 0] == pytest.approx(1e-15)  # (a lever: kept whole)
    assert b[1] == pytest.approx(-GAIN * 0.002 / DT)  # pushed out


def _table_scene(name: str, z: float):
    """A 2 cm table 30 cm square under the hand at q0, its top 8 mm from the robot's hull
    (``z``: the table's centre below the hand, m)."""
    robot = sjt.Robot.from_example(name)
    q0 = robot.q0.copy()
    hand = robot.fk(q0).translation
    table = (coal.Box(0.3, 0.3, 0.02), pin.SE3(np.eye(3), hand + [0.0, 0.0, z]))
    return robot, q0, hand, table


def _run(robot, q0, goal, solver, seconds):
    q, qs, conflicts = q0.copy(), [q0.copy()], 0
    with pytest.warns(UserWarning, match="margin"):
        for _ in range(int(round(seconds / DT))):
            q = solver.step(q, goal)
            qs.append(q)
            conflicts += bool(solver.last.limit_conflicts)
    return np.array(qs), conflicts


def _distances(robot, table, limit, qs):
    """Per configuration (every 5th), each pair's distance on the URDF's meshes (coal)."""
    checker = bench.Checker(robot, [table], limit.pair_names)
    out = []
    for q in qs[::5]:
        pin.updateGeometryPlacements(checker.model, checker.data, checker.mesh,
                                     checker.mesh_data, q)
        out.append([pin.computeDistance(checker.mesh, checker.mesh_data, k).min_distance
                    for k in range(len(checker.names))])
    return np.array(out), checker.names


@pytest.mark.slow
def test_a_table_through_the_shoulders_margin_keeps_every_limit_and_the_other_links_out():
    """Z1 with a table at its shoulder, 2 mm inside the margin of its upper arm (``link02``),
    which its shoulder only turns about a point near the table: the row's lever is 1.5 mm/rad.
    Its push out drove the shoulder at half its acceleration limit for good while the distance
    never grew; the rows then held by yawing, the acceleration limits yielded 48-233x, the arm
    swung at up to 4.6 rad/s and the forearm went 30-39 mm into the table. Now the upper arm
    keeps its distance, no step is in conflict with a limit, every other link keeps the
    margin, and the arm slows to a stop."""
    robot, q0, hand, table = _table_scene("z1", -0.19808)
    limit = CollisionLimit(robot, [table], margin=MARGIN)
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), limits=[limit], dt=DT,
                           acceleration_limits=10.0, jerk_limits=1_000.0)
    qs, conflicts = _run(robot, q0, hand + [0.05, 0.02, -0.3], solver, 8.0)
    distances, names = _distances(robot, table, limit, qs)
    upper = np.array(["link02" in a for a, _ in names])
    assert distances[0, upper].min() == pytest.approx(MARGIN - 0.002, abs=2e-4)  # (the case)
    assert distances[:, upper].min() >= MARGIN - 0.002 - 1e-4
    assert distances[:, ~upper].min() >= MARGIN - 1e-3
    assert conflicts == 0
    v, a, j = bench.rates(robot.model, qs, DT)
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    assert np.abs(j).max() <= 1_000.0 * (1 + 1e-9)
    assert np.abs(v[-1000:]).max() < 1e-2  # (it swung at 1-4.6 rad/s)


@pytest.mark.slow
def test_a_table_through_the_shoulders_margin_beside_speed_limits_alone():
    """The same Z1 scene with speed limits alone: the push asked the shoulder for its speed
    limit, and the arm still moved at 3.14 rad/s after 4 s. Now it comes to rest, the upper
    arm at its distance and every other link out of the margin."""
    robot, q0, hand, table = _table_scene("z1", -0.19808)
    limit = CollisionLimit(robot, [table], margin=MARGIN)
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), limits=[limit], dt=DT)
    qs, _ = _run(robot, q0, hand + [0.2, 0.1, -0.15], solver, 4.0)
    distances, names = _distances(robot, table, limit, qs)
    upper = np.array(["link02" in a for a, _ in names])
    assert distances[:, upper].min() >= MARGIN - 0.002 - 1e-4
    assert distances[:, ~upper].min() >= MARGIN - 1e-3
    v, _, _ = bench.rates(robot.model, qs, DT)
    assert np.abs(v[-1000:]).max() < 1e-6  # (at rest over the last second)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_a_link_on_its_base_turns_inside_the_margin_to_reach_the_target(method):
    """Kinova with a table 2 mm inside the margin of its first link, which only the base's turn
    moves, about the link's own axis: the row's entry for that turn was 3e-15 (rounding), and
    with the push out of the margin it bound the turn to one direction. The target beside it
    (reached exactly without the table's row) was missed by 0.065-0.077; now the base turns
    and the hand gets there, the first link keeping its distance, within every limit."""
    robot, q0, hand, table = _table_scene("kinova", -0.038373)
    limit = CollisionLimit(robot, [table], margin=MARGIN)
    solver = sjt.make_solver(method, robot, task=sjt.PositionTask(), limits=[limit], dt=DT,
                             acceleration_limits=10.0, jerk_limits=1_000.0)
    goal = hand + [-0.1, 0.25, -0.1]
    qs, conflicts = _run(robot, q0, goal, solver, 5.0)
    assert np.linalg.norm(robot.fk(qs[-1]).translation - goal) < 1e-6
    distances, _ = _distances(robot, table, limit, qs)
    assert distances.min() >= MARGIN - 0.002 - 1e-4
    assert conflicts == 0
    _, a, j = bench.rates(robot.model, qs, DT)
    assert np.abs(a).max() <= 10.0 * (1 + 1e-9)
    assert np.abs(j).max() <= 1_000.0 * (1 + 1e-9)
