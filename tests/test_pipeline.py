"""The step pipeline equals the reference formulas of ``tests/reference/mappings.py`` on random
chains, for every method and task combination; the package's import surface; solver settings
after construction."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sjt_pin.robots.planar3 import serial_chain, to_xml

import sjt_pin as sjt
from sjt_pin.methods.dls import DLS_DAMPING
from sjt_pin.methods.transpose import FF_DAMPING, FLOOR, POSE_LM_WEIGHT
from sjt_pin.tasks.pose import characteristic_length

from .reference import mappings

URDFS = Path(__file__).parent / "fixtures" / "urdf"  # (whatever the working directory)

DT = 1e-3


def random_chain(seed: int, joints: int) -> sjt.Robot:
    rng = np.random.default_rng(seed)
    xml = to_xml(serial_chain(list(rng.uniform(0.05, 0.6, joints)),
                              axes=rng.normal(size=(joints, 3)), gripper=0.1))
    return sjt.Robot.from_urdf(xml, ee_frame="ee", load_visuals=False)


def reference_rows(robot, q, task, target, velocity):
    """J, e, ff of one task from Pinocchio directly (the conventions of the tasks' docs)."""
    frame = task.frame or robot.ee_frame
    oMf = robot.fk(q, frame)
    local = robot.jacobian(q, frame)
    if isinstance(task, sjt.PoseTask):
        ff = oMf.actInv(pin.SE3(np.eye(3), target.translation).act(pin.Motion(velocity)))
        return local, pin.log6(oMf.actInv(target)).vector, ff.vector
    if isinstance(task, sjt.OrientationTask):
        e = pin.log3(oMf.rotation.T @ target.rotation)
        return local[3:], e, oMf.rotation.T @ velocity[3:]
    rows = ["xyz".index(a) for a in task.axes]
    aligned = robot.jacobian(q, frame, reference=pin.LOCAL_WORLD_ALIGNED)
    return aligned[rows], (target.translation - oMf.translation)[rows], velocity[rows]


def row_lengths(robot, task):
    """The rows' length weights: L on the angular rows of pose and orientation tasks."""
    length = characteristic_length(robot, robot.frame_id(task.frame or robot.ee_frame))
    if isinstance(task, sjt.PoseTask):
        return np.array([1.0, 1.0, 1.0, length, length, length]), length
    if isinstance(task, sjt.OrientationTask):
        return np.full(3, length), length
    return np.ones(task.dim), length


def reference_step(method, options, J, e, ff, sw, k, mask, target_rows, floor, lm=1.0,
                   length=1.0):
    """dt q_dot of the method from the numpy formulas of ``mappings``; ``floor`` is SJT's
    floor l under the column norms (m), ``lm`` the weight of the Levenberg-Marquardt term
    (SJT's, JP's and DLS's), ``length`` the tasks' characteristic length L (m)."""
    Jw = sw[:, None] * J * mask
    ew, ffw = sw * e, sw * ff
    # JP and DLS: Levenberg-Marquardt damping lm |e_w| L (L: the tasks' length)
    error = lm * np.linalg.norm(ew[:target_rows]) * length
    if method == "jp":
        return DT * mappings.jp_matrix(Jw, mappings.JP_RCOND, error) @ (ffw + k * ew)
    if method == "dls":
        return DT * mappings.dls_matrix(Jw, DLS_DAMPING, error) @ (ffw + k * ew)
    alpha = mappings.scaling_factors(Jw, mappings.COLUMN_TOL, floor)
    if method == "sjt" and options.get("feedback", "damped") == "damped":
        # Levenberg-Marquardt: mu^2 + lm |e_w| sqrt(max alpha)
        damping = FF_DAMPING**2 + lm * np.sqrt(ew[:target_rows] @ ew[:target_rows] * alpha.max())
        return DT * mappings.damped_sjt_matrix(Jw, damping, length=floor) @ (ffw + k * ew)
    S = alpha if method == "sjt" else mask
    feedforward = (S * (Jw.T @ ffw) if options.get("feedforward") == "transpose"
                   else mappings.damped_sjt_matrix(Jw, FF_DAMPING**2, length=floor) @ ffw)
    return DT * (S * (Jw.T @ (k * ew)) + feedforward)


COMBINATIONS = {
    "pose": lambda: [sjt.PoseTask()],
    "position xz": lambda: [sjt.PositionTask(axes="xz", weight=[2.0, 0.5])],
    "orientation": lambda: [sjt.OrientationTask()],
    "pose + posture": lambda: [sjt.PoseTask(weight=[1, 1, 1, 0.5, 0.5, 0.5]),
                               sjt.PostureTask(weight=0.03)],
    "two frames": lambda: [sjt.PositionTask(), sjt.OrientationTask(frame="link1")],
}
METHODS = [("sjt", {}), ("sjt", {"feedback": "transpose"}),
           ("sjt", {"feedback": "transpose", "feedforward": "transpose"}), ("jt", {}),
           ("jp", {}), ("dls", {})]


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(2, 8),
       combination=st.sampled_from(sorted(COMBINATIONS)),
       method=st.sampled_from(range(len(METHODS))), feedforward=st.booleans())
def test_one_step_is_the_reference_formula(seed, joints, combination, method, feedforward):
    name, options = METHODS[method]
    robot = random_chain(seed, joints)
    rng = np.random.default_rng(seed + 1)
    tasks = COMBINATIONS[combination]()
    posture = tasks.pop() if isinstance(tasks[-1], sjt.PostureTask) else None
    if len(tasks) == 2 and robot.nv < 2:
        return
    k = rng.uniform(1.0, 50.0)
    solver = sjt.make_solver(name, robot, gain=k, dt=DT, task=tasks if len(tasks) > 1 else
                             tasks[0], posture=posture, position_limits=False,
                             velocity_limits=False, check_stability=False, **options)
    q = robot.random_configuration(rng)
    frames = [t.frame or robot.ee_frame for t in tasks]
    targets = {f: robot.fk(q, f) * pin.exp6(pin.Motion(rng.normal(scale=0.05, size=6)))
               for f in frames}
    velocities = {f: rng.normal(scale=0.2, size=6) for f in frames}
    single = len(tasks) == 1
    solver.step(q, targets[frames[0]] if single else targets,
                (velocities[frames[0]] if single else velocities) if feedforward else None)
    blocks = [reference_rows(robot, q, t, targets[f], velocities[f] if feedforward
                             else np.zeros(6)) for t, f in zip(tasks, frames, strict=True)]
    weights = [row_lengths(robot, t) for t in tasks]
    sw = [(np.ones(t.dim) if t.sqrt_weight is None else t.sqrt_weight) * w
          for t, (w, _) in zip(tasks, weights, strict=True)]
    length = max(length for _, length in weights)
    floor = FLOOR * length
    # half the Levenberg-Marquardt term when every target row turns with the frame
    rotational = all(isinstance(t, (sjt.PoseTask, sjt.OrientationTask)) for t in tasks)
    lm = POSE_LM_WEIGHT if rotational else 1.0
    target_rows = sum(t.dim for t in tasks)
    mask = solver.stack.chain
    if posture is not None:
        blocks.append((np.eye(robot.nv), pin.difference(robot.model, q, robot.q0),
                       np.zeros(robot.nv)))
        sw.append(np.full(robot.nv, np.sqrt(0.03)))
    J, e, ff = (np.concatenate(part) for part in zip(*blocks, strict=True))
    rank_scale = np.concatenate([np.full(w.size, 1.0 / w.max()) for w in sw[:len(tasks)]])
    sw = np.concatenate(sw)
    expected = reference_step(name, options, J[:target_rows], e[:target_rows],
                              ff[:target_rows], sw[:target_rows], k, mask, target_rows, floor,
                              lm, length)
    if posture is not None:
        # the posture's level: its velocity k w (q0 - q) in the null space of the tasks' rows,
        # in place of the tasks' own self-motion (Siciliano and Slotine's recursion)
        Jw = sw[:target_rows, None] * J[:target_rows] * mask
        null = np.eye(robot.nv) - np.linalg.pinv(Jw, rcond=1e-12) @ Jw
        wanted = DT * k * 0.03 * e[target_rows:]
        # (fading where the tasks' rows lose rank: a smoothstep of the least over the largest
        # eigenvalue of their Gram matrix, each task's rows over its largest weight, from 1e-6
        # to 1e-4; a row no joint moves counts as independent)
        rows = rank_scale[:, None] * Jw
        gram = rows @ rows.T
        top = np.diag(gram).max()
        gram[np.diag_indices_from(gram)] = np.where(np.diag(gram) > 1e-18 * top, np.diag(gram),
                                                    top)
        gram = np.linalg.eigvalsh(gram)
        x = np.clip((max(gram[0], 0.0) / gram[-1] - 1e-6) / (1e-4 - 1e-6), 0.0, 1.0)
        expected = expected + x * x * (3.0 - 2.0 * x) * null @ (wanted - expected)
    np.testing.assert_allclose(solver.displacement, expected, rtol=1e-7,
                               atol=1e-9 * max(1.0, np.abs(expected).max()))
    np.testing.assert_allclose(solver.last.error, e[:target_rows], atol=1e-12)


def test_import_leaves_the_heavy_optional_modules_out():
    code = ("import sys, sjt_pin; heavy = {'matplotlib', 'tqdm', 'meshcat', 'pink', 'dask', "
            "'distributed'}; "
            "print(sorted(m for m in heavy if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


def test_dt_and_gain_set_after_construction_act_on_the_next_step(ur5):
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q) * pin.SE3(np.eye(3), np.array([0.01, 0.0, 0.0]))
    a = sjt.SJTSolver(ur5, gain=5.0, dt=1e-3, feedback="transpose")
    b = sjt.SJTSolver(ur5, gain=5.0, dt=1e-2, feedback="transpose")
    a.dt = 1e-2
    a.step(q, target)
    b.step(q, target)
    np.testing.assert_allclose(a.displacement, b.displacement)
    a.gain = "auto"
    a.step(q, target)
    assert a.last.gain == pytest.approx(1.0 / (1e-2 * a.last.loop_bound))
    for bad in (0.0, -1e-3, np.nan):
        with pytest.raises(ValueError, match="dt must be a positive number in s"):
            a.dt = bad
    with pytest.raises(TypeError, match="dt must be a number"):
        a.dt = "fast"
    with pytest.raises(TypeError, match="gain must be a number"):
        a.gain = None
    assert a.dt == 1e-2  # a refused setting leaves the solver as it was


def test_robots_with_one_moving_joint_and_none():
    one = sjt.Robot.from_urdf(URDFS / "one_joint.urdf", load_visuals=False)
    target = one.fk(np.array([0.3]))
    for name in ("sjt", "jt", "jp", "dls"):
        for task in (sjt.PoseTask(), sjt.PositionTask(), sjt.OrientationTask()):
            solver = sjt.make_solver(name, one, task=task, dt=1e-2)
            q = one.q0
            for _ in range(500):
                q = solver.step(q, target)
            assert solver.error_norm < 1e-6 and solver.last.dq.shape == (1,)
            assert solver.solve(target, one.q0).success
    zero = sjt.Robot.from_urdf(URDFS / "fixed_only.urdf", load_visuals=False)
    with pytest.raises(ValueError, match="has no moving joint"):
        sjt.SJTSolver(zero)


# Pinocchio's bindings give a (6, 1) or (3, 1) matrix as a vector: the centre of mass's
# Jacobian of a robot with one velocity coordinate broke CoMTask ("could not broadcast (3,)
# into (3, 1)"), its frame Jacobian move_to (a matmul of (6,) by (1,)) and its joint Jacobian
# reachability() (IndexError).
def test_the_centre_of_mass_a_joint_move_and_the_reach_of_a_robot_with_one_joint():
    """A 1 kg mass 0.25 m out on a revolute joint: CoMTask's Jacobian is the finite
    difference of the centre of mass, the task brings it onto a point of its circle, move_to
    takes the hand to a pose of its own, and
    reachability() maps the arm's workspace (none of its grid's poses lies on the one circle of
    poses the arm reaches, every one is solved)."""
    urdf = (URDFS / "one_joint.urdf").read_text().replace(
        '<link name="arm"/>', '<link name="arm"><inertial><origin xyz="0.25 0 0"/>'
        '<mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" '
        'iyz="0"/></inertial></link>')
    one = sjt.Robot.from_urdf(urdf, load_visuals=False)
    kinematics = sjt.Kinematics(one.model)
    task = sjt.CoMTask().bind(one)
    at = np.array([0.4])
    kinematics.update(at)
    J = task.compute(kinematics, np.zeros(3), None)[0].copy()
    centre = [pin.centerOfMass(one.model, one.model.createData(), at + h) for h in (1e-6, -1e-6)]
    np.testing.assert_allclose(J[:, 0], (centre[0] - centre[1]) / 2e-6, atol=1e-8)
    goal = 0.25 * np.array([np.cos(1.2), np.sin(1.2), 0.0])
    solver = sjt.SJTSolver(one, task=sjt.CoMTask(), dt=1e-2)
    q = one.q0
    for _ in range(500):
        q = solver.step(q, goal)
    assert q[0] == pytest.approx(1.2, abs=1e-6)
    solver = sjt.SJTSolver(one)
    move, q = solver.move_to(one.q0, one.fk(np.array([-0.7]))), one.q0
    while not move.done:
        q = move.step(q)
    assert q[0] == pytest.approx(-0.7, abs=1e-9)
    reach = sjt.reachability(one, step=0.1, orientations=1, processes=1, progress=False,
                             budget=50)
    assert reach.done == len(reach.positions) and np.isfinite(reach.error).all()
    assert not reach.reached.any()

