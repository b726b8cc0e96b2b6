"""Random URDF chains and trees: no exception but the documented ones, finite outputs, SJT's
bounds (eq. 19, 25) and convergence to reachable targets."""

import numpy as np
import pinocchio as pin
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sjt_pin as sjt
from sjt_pin import mappings

TYPES = ["revolute", "revolute", "prismatic", "continuous", "fixed"]


def random_urdf(seed: int, joints: int) -> tuple[str, str]:
    """A random tree: joints of every type, random axes, offsets from 1 mm to 10 m; returns
    the XML and the name of its deepest link."""
    rng = np.random.default_rng(seed)
    links, depth, body = ["base"], {"base": 0}, []
    for k in range(joints):
        # mostly a chain, sometimes a branch
        parent = links[-1] if rng.random() < 0.7 else links[rng.integers(len(links))]
        kind = TYPES[rng.integers(len(TYPES))]
        direction = rng.normal(size=3)
        xyz = direction / np.linalg.norm(direction) * 10 ** rng.uniform(-3, 1)
        rpy = rng.uniform(-np.pi, np.pi, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        limit = ""
        if kind in ("revolute", "prismatic"):
            limit = (f'<limit lower="{-rng.uniform(0.3, 3):.6f}" upper="{rng.uniform(0.3, 3):.6f}"'
                     ' effort="10" velocity="2"/>')
        child = f"l{k}"
        body.append(
            f'<link name="{child}"/><joint name="j{k}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{" ".join(f"{v:.9g}" for v in xyz)}" '
            f'rpy="{" ".join(f"{v:.9g}" for v in rpy)}"/>'
            f'<axis xyz="{" ".join(f"{v:.9g}" for v in axis)}"/>{limit}</joint>')
        links.append(child)
        depth[child] = depth[parent] + 1
    xml = '<robot name="random"><link name="base"/>' + "".join(body) + "</robot>"
    return xml, max(links, key=depth.__getitem__)


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
