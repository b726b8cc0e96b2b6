"""Whole-body tasks: the centre of mass, contacts, the support polygon, and strict priorities.

Real robots from example-robot-data: Solo-12 (a quadruped, free-flyer base, point feet) moves
its body over its four held feet; TALOS (a 30-joint humanoid) reaches with both hands while its
soles hold and its centre of mass stays over them.
"""

import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.kinematics import Kinematics
from sjt_pin.limits.support import convex_hull

DT = 1e-3
FEET = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
SOLES = ["left_sole_link", "right_sole_link"]
HANDS = ["gripper_left_base_link", "gripper_right_base_link"]
#: Solo-12's URDF gives 1,000 rad/s; a real Solo's joints and a body moved by hand are slower
SOLO_SPEEDS = np.r_[np.full(6, 2.0), np.full(12, 10.0)]


@pytest.fixture(scope="module")
def solo():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (no end effector known: the tasks name their frames)
        return sjt.Robot.from_example("solo12")


@pytest.fixture(scope="module")
def talos():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sjt.Robot.from_example("talos")


def smooth(t: float) -> float:
    """Minimum-jerk 0 -> 1 over t in [0, 1]."""
    t = min(max(t, 0.0), 1.0)
    return t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)


def com(robot, q):
    kinematics = Kinematics(robot.model)
    kinematics.update(q)
    return kinematics.center_of_mass()[0].copy()


def test_com_jacobian_is_the_derivative_of_pinocchios_centre_of_mass(solo, rng):
    """J_c by central differences along random tangent directions, free flyer included."""
    task = sjt.CoMTask().bind(solo)
    kinematics = Kinematics(solo.model)
    for _ in range(5):
        q = pin.randomConfiguration(solo.model, -np.ones(solo.nq), np.ones(solo.nq))
        q[3:7] /= np.linalg.norm(q[3:7])
        kinematics.update(q)
        J, e, _ = task.compute(kinematics, np.zeros(3), None)
        J = J.copy()
        np.testing.assert_allclose(-e, pin.centerOfMass(solo.model, solo.model.createData(), q),
                                   atol=1e-12)
        v, h = rng.normal(size=solo.nv), 1e-6
        plus = com(solo, pin.integrate(solo.model, q, h * v))
        minus = com(solo, pin.integrate(solo.model, q, -h * v))
        np.testing.assert_allclose(J @ v, (plus - minus) / (2 * h), atol=1e-7)
    xz = sjt.CoMTask(axes="zx").bind(solo)
    J2, e2, _ = xz.compute(kinematics, np.array([1.0, 2.0, 3.0]), None)
    c, Jc = kinematics.center_of_mass()
    np.testing.assert_allclose(J2, Jc[[2, 0]])
    np.testing.assert_allclose(e2, np.array([3.0, 1.0]) - c[[2, 0]])


def test_frameless_tasks_sit_in_a_mapping_under_any_key(solo):
    tasks = {f: sjt.ContactTask(f, point=True) for f in FEET}
    tasks["body"] = sjt.CoMTask(priority=1)
    tasks["rest"] = sjt.PostureTask()
    solver = sjt.SJTSolver(solo, task=tasks, dt=DT)
    assert solver.stack.frames == ["body"]  # contacts and posture take no target
    q = solver.step(solo.q0, {"body": com(solo, solo.q0) + [0.01, 0.0, 0.0]})
    assert np.all(np.isfinite(q))
    with pytest.raises(ValueError, match=r"exactly the frames \['body'\]"):
        solver.step(solo.q0, {"com": np.zeros(3)})
    alone = sjt.SJTSolver(solo, task=[sjt.CoMTask()], dt=DT)
    assert alone.stack.frames == ["com"]


@pytest.mark.parametrize("Solver", [sjt.SJTSolver, sjt.DLSSolver, sjt.JPSolver])
def test_quadruped_moves_its_body_over_held_feet_and_rests_at_the_support_edge(solo, Solver):
    q = solo.q0.copy()
    feet = {f: solo.fk(q, f).translation.copy() for f in FEET}
    support = sjt.SupportLimit(FEET, margin=0.02)
    solver = Solver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                    + [sjt.CoMTask(priority=1)], dt=DT, limits=[support],
                    velocity_limits=SOLO_SPEEDS)
    c0 = com(solo, q)
    move = np.array([0.05, 0.04, -0.04])
    slip, closest = 0.0, np.inf
    for i in range(1500):  # 1 s of a smooth move, then 0.5 s held
        q = solver.step(q, c0 + smooth(i * DT) * move)
        slip = max(slip, max(np.linalg.norm(solo.fk(q, f).translation - p)
                             for f, p in feet.items()))
        closest = min(closest, support.distance)
    assert np.linalg.norm(com(solo, q) - c0 - move) < 1e-9
    assert slip < 5e-6
    assert closest > 0.02
    # a target far outside the feet: the body stops at the margin, feet held, and rests (a
    # jump at the speed limits: each step's second-order slip, taken back at the next, is
    # larger)
    far, slip = c0 + move + [0.3, 0.0, 0.0], 0.0
    for _ in range(3000):
        q = solver.step(q, far)
        slip = max(slip, max(np.linalg.norm(solo.fk(q, f).translation - p)
                             for f, p in feet.items()))
        closest = min(closest, support.distance)
    assert slip < 5e-5
    assert closest > 0.02 - 1e-4
    assert support.distance < 0.021  # it went as far as the margin lets it
    assert np.abs(solver.last.dq).max() < 1e-6


@pytest.mark.parametrize("point", [True, False])
def test_a_contacts_drift_is_the_second_order_term_of_its_motion(solo, point, rng):
    """ContactTask.drift: over a step h of velocity v a frame moves by J v h - drift(h) h (as
    its rows count it) up to third order: the residual falls 8 times when h halves."""
    model = solo.model
    task = sjt.ContactTask("FL_FOOT", point=point).bind(solo)
    kinematics = Kinematics(model)
    for _ in range(3):
        q = pin.randomConfiguration(model, -np.ones(solo.nq), np.ones(solo.nq))
        v = rng.normal(size=solo.nv)
        kinematics.update(q)
        M0 = kinematics.placement(task.frame_id)
        J = (kinematics.world_aligned_jacobian(task.frame_id)[:3] if point
             else kinematics.jacobian(task.frame_id))
        kinematics.velocity_products(v)
        residuals = []
        for h in (4e-3, 2e-3, 1e-3):
            drift = task.drift(kinematics, h)
            data = model.createData()
            pin.framesForwardKinematics(model, data, pin.integrate(model, q, h * v))
            M = data.oMf[task.frame_id]
            moved = M.translation - M0.translation if point else pin.log6(M0.actInv(M)).vector
            residuals.append(np.linalg.norm(moved - (J @ v * h - drift * h)))
        assert residuals[0] / residuals[1] > 6.0 and residuals[1] / residuals[2] > 6.0


@pytest.mark.parametrize("Solver", [sjt.SJTSolver, sjt.DLSSolver, sjt.JPSolver])
@pytest.mark.parametrize("jerk", [None, 2000.0])
def test_held_feet_hold_under_acceleration_and_jerk_limits(solo, Solver, jerk):
    """A jump of the centre of mass's target under acceleration (and jerk) limits: each joint's
    smoothness box taken alone let the held feet slide by centimetres; the feet now hold to
    1e-6 m at every step, no acceleration passes its limit, and the body rests on the target
    (then, sent far outside the feet, at the margin: acceleration limits alone)."""
    q = solo.q0.copy()
    feet = {f: solo.fk(q, f).translation.copy() for f in FEET}
    support = sjt.SupportLimit(FEET, margin=0.02)
    solver = Solver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                    + [sjt.CoMTask(priority=1)], dt=DT, limits=[support],
                    velocity_limits=SOLO_SPEEDS, acceleration_limits=20.0, jerk_limits=jerk)
    c0 = com(solo, q)
    goals = [(c0 + [0.05, 0.04, -0.04], 3000)]
    if jerk is None:
        goals.append((c0 + [0.35, 0.04, -0.04], 6000))
    dq, slip, closest = np.zeros(solo.nv), 0.0, np.inf
    for goal, steps in goals:
        for _ in range(steps):
            q = solver.step(q, goal)
            slip = max(slip, max(np.linalg.norm(solo.fk(q, f).translation - p)
                                 for f, p in feet.items()))
            closest = min(closest, support.distance)
            assert np.abs(solver.last.dq - dq).max() <= 20.0 * DT * (1 + 1e-9)
            assert not solver.last.limit_conflicts
            dq = solver.last.dq.copy()
        assert np.abs(dq).max() < 1e-6  # at rest
    # (without jerk limits the step asks back the drift of the last velocity)
    assert slip < (5e-7 if jerk is None else 5e-6)
    if jerk is None:  # it went as far as the margin lets it (DLS 0.6 mm into the margin)
        assert 0.02 - 1e-3 < closest and support.distance < 0.021
    else:
        assert np.linalg.norm(com(solo, q) - goals[0][0]) < 1e-9
        assert closest > 0.02


@pytest.mark.parametrize("limits", [{}, {"acceleration_limits": 10.0}])
def test_humanoid_reaches_with_both_hands_over_its_held_soles(talos, limits):
    q = talos.q0.copy()
    soles = {f: talos.fk(q, f) for f in SOLES}
    hands = {h: talos.fk(q, h).translation.copy() for h in HANDS}
    moves = {HANDS[0]: np.array([0.1, 0.05, 0.05]), HANDS[1]: np.array([0.08, -0.05, -0.05])}
    tasks = {f: sjt.ContactTask(f) for f in SOLES}
    tasks.update({h: sjt.PositionTask(h, priority=1) for h in HANDS})
    tasks["com"] = sjt.CoMTask(axes="xy", priority=1)
    support = sjt.SupportLimit(SOLES, sole=(0.1, 0.05), margin=0.02)
    solver = sjt.SJTSolver(talos, task=tasks, dt=DT, limits=[support],
                           posture=sjt.PostureTask(), **limits)
    c0 = com(talos, q)
    slip, closest, dq = 0.0, np.inf, np.zeros(talos.nv)
    for i in range(2500):  # 1.5 s of a smooth reach, then 1 s held
        s = smooth(i * DT / 1.5)
        target = {h: hands[h] + s * moves[h] for h in HANDS}
        target["com"] = c0
        q = solver.step(q, target)
        slip = max(slip, max(float(np.linalg.norm(pin.log6(talos.fk(q, f).actInv(M)).vector))
                             for f, M in soles.items()))
        closest = min(closest, support.distance)
        lo, hi = talos.model.lowerPositionLimit[7:], talos.model.upperPositionLimit[7:]
        assert np.all(q[7:] >= lo - 1e-9) and np.all(q[7:] <= hi + 1e-9)
        if limits:  # (each joint's box taken alone let the soles slide 0.65)
            assert np.abs(solver.last.dq - dq).max() <= 10.0 * DT * (1 + 1e-9)
            dq = solver.last.dq.copy()
    for h in HANDS:
        assert np.linalg.norm(talos.fk(q, h).translation - hands[h] - moves[h]) < 1e-4
    assert np.linalg.norm((com(talos, q) - c0)[:2]) < 1e-4
    assert slip < 1e-6
    assert closest > 0.02


def test_support_polygon_and_its_rows(solo):
    support = sjt.SupportLimit(FEET, margin=0.0, gain=1.0)
    kinematics = Kinematics(solo.model)
    kinematics.update(solo.q0)
    motion = sjt.limits.Motion(solo.q0, np.zeros(solo.nv), np.zeros(solo.nv), DT)
    A, b = support.rows(kinematics, motion)
    feet = np.array([solo.fk(solo.q0, f).translation[:2] for f in FEET])
    np.testing.assert_allclose(np.sort(support.polygon, axis=0), np.sort(feet, axis=0))
    # gain 1, margin 0: b dt is each edge's distance, A the rate of its decrease
    c, Jc = kinematics.center_of_mass()
    polygon = support.polygon
    for k in range(len(polygon)):
        p, r = polygon[k], polygon[(k + 1) % len(polygon)]
        edge = (r - p) / np.linalg.norm(r - p)
        inward = np.array([-edge[1], edge[0]])
        assert b[k] * DT == pytest.approx(inward @ (c[:2] - p), abs=1e-12)
        np.testing.assert_allclose(A[k], -inward @ Jc[:2], atol=1e-12)
    hull = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.5, 0]]))
    (ax, ay), (bx, by) = hull[1] - hull[0], hull[2] - hull[1]
    assert len(hull) == 4 and ax * by - ay * bx > 0  # counter-clockwise


def test_whole_body_bad_input(solo):
    with pytest.raises(TypeError, match="contacts must be one or more frame names"):
        sjt.SupportLimit([])
    with pytest.raises(ValueError, match="margin must be a finite distance"):
        sjt.SupportLimit(FEET, margin=-0.01)
    with pytest.raises(ValueError, match="sole must be"):
        sjt.SupportLimit(FEET, sole=(0.1, -0.1))
    with pytest.raises(ValueError, match="gain must be in"):
        sjt.SupportLimit(FEET, gain=0.0)
    with pytest.raises(TypeError, match="a contact needs its frame"):
        sjt.ContactTask(None)
    with pytest.raises(ValueError, match="axes must be a non-empty subset"):
        sjt.CoMTask(axes="xw")
    two = sjt.SupportLimit(FEET[:2])  # two point feet: a segment
    solver = sjt.SJTSolver(solo, task=[sjt.CoMTask()], dt=DT, limits=[two])
    with pytest.raises(ValueError, match="span no area"):
        solver.step(solo.q0, com(solo, solo.q0))
    missing = sjt.SJTSolver(solo, task=[sjt.CoMTask()], dt=DT,
                            limits=[sjt.SupportLimit(["FL_FOOT", "no_such_foot", "HL_FOOT"])])
    with pytest.raises(sjt.FrameNotFound, match="no_such_foot"):
        missing.step(solo.q0, com(solo, solo.q0))
    with pytest.raises(sjt.FrameNotFound, match=r"PositionTask\(axes='xy'\)"):
        sjt.SJTSolver(solo, task=sjt.PositionTask("xy"))
    # links without <inertial>: the centre of mass is 0 / 0 (a step said "target is too far
    # for a finite task error")
    massless = sjt.Robot.from_urdf(Path(__file__).parent / "fixtures" / "urdf" / "one_joint.urdf",
                                   load_visuals=False)
    with pytest.raises(ValueError, match="CoMTask needs .* one_joint have no mass"):
        sjt.SJTSolver(massless, task=sjt.CoMTask())
    solver = sjt.SJTSolver(massless, limits=[sjt.SupportLimit(["tip"])])
    for _ in range(2):  # (said again at the next step)
        with pytest.raises(ValueError, match="SupportLimit needs .* have no mass"):
            solver.step(massless.q0, massless.fk(massless.q0))
    # a mass on the fixed root link alone moves with no joint: the centre of mass of the
    # moving links is still 0 / 0
    rooted = sjt.Robot.from_urdf((Path(__file__).parent / "fixtures" / "urdf" /
                                  "one_joint.urdf").read_text().replace(
        '<link name="base"/>', '<link name="base"><inertial><mass value="2"/><inertia '
        'ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial></link>'),
        load_visuals=False)
    with pytest.raises(ValueError, match="CoMTask needs"):
        sjt.SJTSolver(rooted, task=sjt.CoMTask())


def test_a_start_outside_the_margin_is_said_and_moved_in(solo):
    q = solo.q0.copy()
    support = sjt.SupportLimit(FEET, margin=0.2)  # wider than the feet: the start is outside
    solver = sjt.DLSSolver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                           + [sjt.CoMTask(axes="z", priority=1)], dt=DT, limits=[support],
                           velocity_limits=SOLO_SPEEDS)
    with pytest.warns(UserWarning, match="centre of mass starts .* less than the margin"):
        q = solver.step(q, com(solo, q))
    assert np.all(np.isfinite(q))


@pytest.mark.parametrize("Solver", [sjt.SJTSolver, sjt.DLSSolver, sjt.JPSolver, sjt.JTSolver])
@pytest.mark.parametrize("seed", range(6))
def test_a_lower_level_costs_the_top_level_nothing(Solver, seed):
    """Strict priorities on random redundant chains: the top level's task motion J0 q_dot is
    the same with and without the levels below it (where no limit binds)."""
    from .test_pipeline import random_chain  # (yourdfpy: .ci/oldest.sh leaves this test out)

    robot = random_chain(seed, 9)
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, robot.nq)
    target = robot.fk(q).translation + rng.normal(scale=0.02, size=3)
    free = dict(dt=DT, position_limits=False, velocity_limits=False)
    top = Solver(robot, task=sjt.PositionTask(), **free)
    below = Solver(robot, task=[sjt.PositionTask(), sjt.OrientationTask(priority=1)],
                   posture=sjt.PostureTask(q_ref=rng.uniform(-1, 1, robot.nq), weight=0.1),
                   **free)
    top.step(q, target)
    # one target for both tasks on the end effector: its translation the position task's
    turned = pin.SE3(robot.fk(q).rotation @ pin.exp3(rng.normal(scale=0.2, size=3)), target)
    below.step(q, turned)
    J0 = robot.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:3]
    scale = np.linalg.norm(J0 @ top.last.dq)
    np.testing.assert_allclose(J0 @ below.last.dq, J0 @ top.last.dq, atol=1e-9 * scale)
    assert np.linalg.norm(below.last.dq - top.last.dq) > 1e-6 * np.linalg.norm(top.last.dq)


@pytest.mark.parametrize("Solver", [sjt.SJTSolver, sjt.DLSSolver, sjt.JPSolver, sjt.JTSolver])
@pytest.mark.parametrize("second", ["panda_hand", "panda_link5"])
def test_levels_below_rows_that_repeat_or_fill_the_joints(Solver, second):
    """Level 0's rows dependent on each other (a pose and a position task on one frame: 9 rows,
    rank 6 on 7 joints) or more than the joints (two poses: 12 rows, rank 7): the projector of
    the levels below spans them once, level 0's task motion is the same with and without the
    levels below, and where level 0 takes every joint the levels below change nothing. (A
    lower level's tasks once changed level 0's step through the method's parameters: the
    least-squares damping's length and weight were set from every level's tasks.)"""
    panda = sjt.Robot.from_example("panda")
    rng = np.random.default_rng(7)
    q = panda.q0 + rng.normal(scale=0.2, size=panda.nq)
    hand = panda.fk(q, "panda_hand") * pin.exp6(pin.Motion(rng.normal(scale=0.02, size=6)))
    top_tasks = [sjt.PoseTask("panda_hand"),
                 sjt.PositionTask("panda_hand") if second == "panda_hand" else sjt.PoseTask(second)]
    targets = {"panda_hand": hand}
    if second != "panda_hand":
        targets[second] = panda.fk(q, second) * pin.exp6(pin.Motion(rng.normal(scale=0.02, size=6)))
    free = dict(dt=DT, position_limits=False, velocity_limits=False)
    top = Solver(panda, task=top_tasks, **free)
    below = Solver(panda, task=[*top_tasks, sjt.PositionTask("panda_link4", priority=1)],
                   posture=sjt.PostureTask(q_ref=panda.q0 + 0.3, weight=0.1), **free)
    top.step(q, targets)
    lower_target = panda.fk(q, "panda_link4").translation + [0.02, -0.01, 0.01]
    below.step(q, targets | {"panda_link4": lower_target})
    assert np.all(np.isfinite(below.last.dq))
    J0 = np.vstack([panda.jacobian(q, f) for f in dict.fromkeys(["panda_hand", second])])
    scale = np.linalg.norm(J0 @ top.last.dq)
    np.testing.assert_allclose(J0 @ below.last.dq, J0 @ top.last.dq, atol=1e-9 * scale)
    arm = np.abs(J0).sum(axis=0) > 0  # (the fingers are the posture's alone)
    moved = np.linalg.norm((below.last.dq - top.last.dq)[arm]) / np.linalg.norm(top.last.dq)
    if second == "panda_hand":  # one joint left to the levels below, and they use it
        assert moved > 1e-6
    else:  # none left
        assert moved < 1e-9


def test_solve_brings_the_centre_of_mass_to_its_target_with_the_feet_held(solo):
    """solve()'s success counts the contacts' rows too, not only the rows that take targets
    (it counted the first rows, the contacts': success at the start, the body not moved)."""
    solver = sjt.DLSSolver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                           + [sjt.CoMTask(priority=1)])
    goal = com(solo, solo.q0) + [0.03, -0.02, -0.03]
    result = solver.solve(goal, solo.q0)
    assert result.success and result.iterations > 1
    assert np.linalg.norm(com(solo, result.q) - goal) < 1e-6
    for f in FEET:
        np.testing.assert_allclose(solo.fk(result.q, f).translation,
                                   solo.fk(solo.q0, f).translation, atol=1e-6)


def test_a_posture_below_does_not_stop_the_hands_after_a_fast_reach(talos):
    """A 0.1 s reach (joints at their speed limits), then held: the posture at the lowest level
    must not veto level 1's motion (one step share for all lower levels stopped the hands
    5.8 cm short, at rest, no limit active)."""
    q = talos.q0.copy()
    start = {h: talos.fk(q, h).translation.copy() for h in HANDS}
    reach = {HANDS[0]: np.array([0.1, 0.05, 0.05]), HANDS[1]: np.array([0.08, -0.05, -0.05])}
    tasks = {f: sjt.ContactTask(f) for f in SOLES}
    tasks.update({h: sjt.PositionTask(h, priority=1) for h in HANDS})
    tasks["com"] = sjt.CoMTask(axes="xy", priority=1)
    solver = sjt.SJTSolver(talos, task=tasks, dt=DT, posture=sjt.PostureTask())
    c0 = com(talos, q)
    for i in range(1100):
        s = smooth(i / 100)
        target = {h: start[h] + s * reach[h] for h in HANDS}
        target["com"] = c0
        q = solver.step(q, target)
    for h in HANDS:
        assert np.linalg.norm(talos.fk(q, h).translation - start[h] - reach[h]) < 1e-6


@pytest.mark.parametrize("method", [sjt.SJTSolver, sjt.DLSSolver])
def test_g1_reaches_with_its_knees_at_their_limits_and_rests(method):
    """Unitree G1 (a robot the other tests do not use): the reach drives both knees onto their
    limits; the other joints must take over level 1's task motion, with the posture below them,
    and the robot must come to rest (the nearest velocity in joint space, and then one share of
    the step for all lower levels, rested 2.7e-4 m short)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g1 = sjt.Robot.from_example("g1")
    soles = ["left_ankle_roll_link", "right_ankle_roll_link"]
    hands = ["left_rubber_hand", "right_rubber_hand"]
    reach = {hands[0]: np.array([0.08, 0.03, 0.04]), hands[1]: np.array([0.06, -0.03, -0.06])}
    tasks = {f: sjt.ContactTask(f) for f in soles}
    tasks.update({h: sjt.PositionTask(h, priority=1) for h in hands})
    tasks["com"] = sjt.CoMTask(axes="xy", priority=1)
    support = sjt.SupportLimit(soles, sole=(0.08, 0.04), margin=0.02)
    solver = method(g1, task=tasks, dt=DT, limits=[support], posture=sjt.PostureTask())
    q = g1.q0.copy()
    start = {h: g1.fk(q, h).translation.copy() for h in hands}
    c0 = com(g1, q)
    knees = []
    for i in range(3000):
        s = smooth(i / 1500)
        target = {h: start[h] + s * reach[h] for h in hands}
        target["com"] = c0
        q = solver.step(q, target)
        knees += [j for kind, j in solver.last.active_limits if "knee" in j]
    assert knees  # the knees did reach their limits
    for h in hands:
        assert np.linalg.norm(g1.fk(q, h).translation - start[h] - reach[h]) < 1e-6
    assert np.abs(solver.last.dq).max() < 1e-6
    assert support.distance > 0.02


def test_a_slipping_contact_is_the_level_error_a_step_reports(solo):
    """A contact takes no target, but its slip is its level's error in StepInfo."""
    held = {f: solo.fk(solo.q0, f) for f in FEET}
    moved = {f: pin.SE3(M.rotation, M.translation + [0.0, 0.0, 0.05]) for f, M in held.items()}
    solver = sjt.DLSSolver(solo, task=[sjt.ContactTask(f, pose=moved[f], point=True)
                                       for f in FEET] + [sjt.CoMTask(priority=1)],
                           posture=sjt.PostureTask(), dt=DT)
    solver.step(solo.q0, com(solo, solo.q0))
    assert solver.last.levels[0].error_norm == pytest.approx(0.05 * 2, rel=1e-9)  # 4 feet
    assert solver.last.levels[1].error_norm == pytest.approx(0.0, abs=1e-12)
    # the step's error is the targets' (the centre of mass's), its norm that error's
    assert solver.last.error_norm == pytest.approx(np.linalg.norm(solver.last.error), abs=1e-15)


def test_copies_of_a_solver_with_contacts_continue_bitwise(solo):
    """A copy carries the contacts' held poses (the rebuilt solver took them anew where its
    first step was: 0.61 rad apart after the copy)."""
    import copy
    import pickle

    solver = sjt.DLSSolver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                           + [sjt.CoMTask(priority=1)], dt=DT, velocity_limits=SOLO_SPEEDS)
    goal = com(solo, solo.q0) + [0.04, 0.0, -0.03]
    q = solo.q0.copy()
    for _ in range(300):
        q = solver.step(q, goal)
    copies = [copy.deepcopy(solver), pickle.loads(pickle.dumps(solver))]
    q_copies = [q.copy(), q.copy()]
    for _ in range(50):
        q = solver.step(q, goal)
        q_copies = [c.step(qc, goal) for c, qc in zip(copies, q_copies, strict=True)]
    for qc in q_copies:
        np.testing.assert_array_equal(qc, q)


def test_each_solve_holds_the_contacts_where_it_starts(solo):
    """solve() holds a contact where that solve starts (it held the first solve's feet)."""
    solver = sjt.DLSSolver(solo, task=[sjt.ContactTask(f, point=True) for f in FEET]
                           + [sjt.CoMTask(priority=1)])
    first = solver.solve(com(solo, solo.q0) + [0.02, 0.0, -0.02], solo.q0)
    q1 = solo.q0.copy()
    q1[0] += 0.3  # the robot moved 30 cm
    second = solver.solve(com(solo, q1) + [0.02, 0.0, -0.02], q1)
    assert first.success and second.success
    for f in FEET:
        np.testing.assert_allclose(solo.fk(second.q, f).translation, solo.fk(q1, f).translation,
                                   atol=1e-6)
