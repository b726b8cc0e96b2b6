"""Random URDF chains and trees: no exception but the documented ones, finite outputs, SJT's
bounds (eq. 19, 25) and convergence to reachable targets."""

import re

import numpy as np
import pinocchio as pin
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sjt_pin as sjt
from sjt_pin.bench.random_robots import random_urdf  # the bench's random robots, shared

from .reference import mappings


def goal_near(robot, q, rng):
    """A configuration near ``q`` within the limits (so its pose is reachable)."""
    goal = pin.integrate(robot.model, q, rng.normal(scale=0.1, size=robot.nv))
    return np.clip(goal, robot.lower_limits, robot.upper_limits)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(1, 20))
def test_random_trees(seed, joints):
    xml, leaf = random_urdf(seed, joints)
    robot = sjt.Robot.from_urdf(xml, ee_frame=leaf, load_visuals=False)
    rng = np.random.default_rng(seed)
    if robot.nv == 0:  # only fixed joints: the documented error, not a crash
        try:
            sjt.SJTSolver(robot)
        except ValueError as error:
            assert "no moving joint" in str(error)
            return
        raise AssertionError("a robot without moving joints must be refused")
    q = robot.random_configuration(rng)
    target = robot.fk(goal_near(robot, q, rng))
    for name in ("sjt", "jt", "jp", "dls"):
        for task in (sjt.PoseTask(), sjt.PositionTask()):
            solver = sjt.make_solver(name, robot, task=task)
            goal = target.translation if isinstance(task, sjt.PositionTask) else target
            q_next = solver.step(q, goal, np.full(6, 0.1))
            info = solver.last
            assert np.all(np.isfinite(q_next)) and np.all(np.isfinite(info.dq))
            assert np.all(q_next >= robot.lower_limits) and np.all(q_next <= robot.upper_limits)
            if name != "sjt":
                continue
            alpha = info.alpha
            assert np.all(alpha >= 0.0)
            floor = solver.method.length
            if isinstance(task, sjt.PoseTask):  # eq. 19 with the length L: J_i^T W J_i >= L^2
                # for revolute joints, 1 for prismatic ones
                length = solver.stack.task.length
                assert np.all(alpha <= max(1.0, 1.0 / length**2) + 1e-12)
            else:  # the floor caps what nothing else bounds
                assert np.all(alpha <= 1.0 / floor**2 * (1 + 1e-9))
            J = (robot.jacobian(q) if isinstance(task, sjt.PoseTask) else
                 robot.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:3]) * solver.stack.chain
            J = solver.stack.sqrt_weight[:, None] * J
            lam = mappings.max_loop_eigenvalue(J, mappings.sjt_matrix(J, length=floor))
            assert lam <= np.count_nonzero(alpha) + 1e-9  # eq. 25: at most n_active
    # a reachable target is reached (a pose target may need every joint: position suffices)
    solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), dt=1e-2)
    q = solver.step(q, target.translation)
    start = solver.error_norm
    for _ in range(3000):
        q = solver.step(q, target.translation)
        if solver.error_norm < 1e-6:
            break
    assert solver.error_norm < max(1e-6, 1e-3 * start), (solver.error_norm, start)


# -- mimic joints, planar joints with any axis, locked joints, shared names, seeds outside ----
MIMIC_TYPES = ["revolute", "revolute", "prismatic", "continuous", "fixed", "planar"]


def random_urdf_semantics(seed: int, joints: int) -> tuple[str, str]:
    """A random tree with what Pinocchio's parser alone gets wrong: mimic joints (chains too),
    planar joints with any axis, locked joints (lower == upper), a joint sharing its child
    link's name; returns the XML and the name of its deepest link."""
    rng = np.random.default_rng(seed)
    links, depth, body, movable = ["base"], {"base": 0}, [], []
    for k in range(joints):
        parent = links[-1] if rng.random() < 0.7 else links[rng.integers(len(links))]
        kind = MIMIC_TYPES[rng.integers(len(MIMIC_TYPES))]
        xyz = rng.normal(size=3) * 10 ** rng.uniform(-2, 0)
        rpy = rng.uniform(-np.pi, np.pi, 3)
        axis = rng.normal(size=3) * 10 ** rng.uniform(-3, 1)  # any length, any direction
        child = f"l{k}"
        name = child if rng.random() < 0.2 else f"j{k}"  # a joint named as its child link
        extra = ""
        if kind in ("revolute", "prismatic"):
            lo, hi = -rng.uniform(0.2, 2), rng.uniform(0.2, 2)
            if rng.random() < 0.15:  # locked
                lo = hi = rng.uniform(-1, 1)
            extra = f'<limit lower="{lo:.6f}" upper="{hi:.6f}" effort="10" velocity="2"/>'
        if kind in ("revolute", "prismatic", "continuous") and rng.random() < 0.35:
            family = [m for m, t in movable if t != "planar"
                      and (t == "continuous") == (kind == "continuous")]
            if family:
                followed = family[rng.integers(len(family))]
                k_mult = rng.choice([-1, 1]) * rng.uniform(0.3, 2)
                extra += (f'<mimic joint="{followed}" multiplier="{k_mult:.6f}" '
                          f'offset="{rng.uniform(-0.2, 0.2):.6f}"/>')
        if kind != "fixed":
            movable.append((name, kind))
        body.append(
            f'<link name="{child}"/><joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{" ".join(f"{v:.9g}" for v in xyz)}" '
            f'rpy="{" ".join(f"{v:.9g}" for v in rpy)}"/>'
            f'<axis xyz="{" ".join(f"{v:.9g}" for v in axis)}"/>{extra}</joint>')
        links.append(child)
        depth[child] = depth[parent] + 1
    # the task frame: a link of its own below the deepest one (looking a shared name up is
    # the frame selection's business, tests/test_robot.py)
    leaf = max(links, key=depth.__getitem__)
    body.append(f'<link name="tip"/><joint name="to_tip" type="fixed"><parent link="{leaf}"/>'
                '<child link="tip"/><origin xyz="0.05 0 0"/></joint>')
    xml = '<robot name="random"><link name="base"/>' + "".join(body) + "</robot>"
    return xml, "tip"


def as_free(robot: sjt.Robot, free: sjt.Robot, q: np.ndarray) -> np.ndarray:
    """``q`` of ``robot`` (mimic joints) on ``free`` (the same URDF without <mimic>)."""
    values = robot.joint_values(q)
    out = pin.neutral(free.model)
    for j in range(1, free.model.njoints):
        joint, name = free.model.joints[j], free.model.names[j]
        i = joint.idx_q
        if joint.nv == 1 and joint.nq == 1:
            out[i] = values[name]
        elif joint.nv == 1 and joint.nq == 2:
            out[i:i + 2] = np.cos(values[name]), np.sin(values[name])
        else:  # planar, floating: the same coordinates
            own = robot.model.joints[robot.model.getJointId(name)]
            out[i:i + joint.nq] = q[own.idx_q:own.idx_q + own.nq]
    return out


def relation_error(robot: sjt.Robot, free: sjt.Robot, q: np.ndarray) -> float:
    """Largest difference between the frames of ``robot`` at ``q`` and of ``free`` with every
    mimic joint set by its relation: 0 when every relation holds."""
    d1, d2 = robot.model.createData(), free.model.createData()
    pin.framesForwardKinematics(robot.model, d1, q)
    pin.framesForwardKinematics(free.model, d2, as_free(robot, free, q))
    return max((float(np.max(np.abs(a.homogeneous - b.homogeneous)))
                for a, b in zip(d1.oMf, d2.oMf, strict=True)), default=0.0)


def distance_outside(robot: sjt.Robot, q: np.ndarray) -> np.ndarray:
    return np.maximum(robot.lower_limits - q, 0.0) + np.maximum(q - robot.upper_limits, 0.0)


def random_semantic_robot(seed: int, joints: int) -> sjt.Robot | None:
    """The robot of :func:`random_urdf_semantics`, or ``None`` where that URDF is the
    documented refusal (mimic limits with no common range) or has no moving joint."""
    xml, leaf = random_urdf_semantics(seed, joints)
    try:
        robot = sjt.Robot.from_urdf(xml, ee_frame=leaf, load_visuals=False)
    except sjt.URDFError:
        return None
    return robot if robot.nv > 0 else None


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), joints=st.integers(1, 16))
def test_random_trees_with_mimic_planar_and_locked_joints_from_seeds_outside(seed, joints):
    xml, leaf = random_urdf_semantics(seed, joints)
    try:
        robot = sjt.Robot.from_urdf(xml, ee_frame=leaf, load_visuals=False)
    except sjt.URDFError as error:  # mimic limits that leave no common range: the documented
        assert "no value of" in str(error)  # refusal
        return
    free = sjt.Robot.from_urdf(re.sub(r"<mimic [^>]*/>", "", xml), ee_frame=leaf,
                               load_visuals=False)
    assert robot.nv == free.nv - len(robot.mimic_joints)
    if robot.nv == 0:
        return
    rng = np.random.default_rng(seed)
    limited = np.isfinite(robot.lower_limits)
    q = robot.random_configuration(rng)
    target = robot.fk(goal_near(robot, q, rng))
    # a seed outside the limits: some limited joints pushed out of their range
    seed_q = q.copy()
    push = rng.uniform(0.05, 1.0, robot.nq) * rng.choice([-1, 1], robot.nq)
    out = limited & (rng.random(robot.nq) < 0.5)
    seed_q[out] = np.where(push[out] > 0, robot.upper_limits[out], robot.lower_limits[out]) \
        + push[out]
    assert relation_error(robot, free, q) < 1e-9
    for task in (sjt.PoseTask(), sjt.PositionTask()):
        goal = target.translation if isinstance(task, sjt.PositionTask) else target
        solver = sjt.SJTSolver(robot, task=task, dt=1e-2)
        x, outside = seed_q, distance_outside(robot, seed_q)
        for k in range(60):
            x_next = solver.step(x, goal)
            assert np.all(np.isfinite(x_next))
            assert relation_error(robot, free, x_next) < 1e-9
            assert np.all(np.abs(solver.last.dq) <= robot.velocity_limits * (1 + 1e-9))
            now = distance_outside(robot, x_next)
            assert np.all(now <= outside + 1e-12)  # never further out; once in, in
            if k == 0:  # the step says which joints it started outside their range
                assert bool(solver.last.outside_limits) == bool(np.any(outside > 0))
            x, outside = x_next, now
        result = solver.solve(goal, seed_q, timeout=None, budget=300)
        assert np.all(result.q >= robot.lower_limits) and np.all(result.q <= robot.upper_limits)
        assert relation_error(robot, free, result.q) < 1e-9
        assert bool(result.clipped) == bool(np.any(out))
