"""On random robots (revolute, prismatic, continuous, trees) and configurations at and near
their limits: whenever the linearised task error can be decreased by a velocity within the
bounds, the step decreases it by at least a fixed fraction of that best decrease.

The definition, for one step from rest of a solver with its default limits (position and
speed), at a configuration ``q`` with a target:

- ``e`` is the solver's task error (``solver.last.error``), ``e_w = s * e`` its weighted rows
  (``s = solver.stack.sqrt_weight``: ``[1, 1, 1, L, L, L]`` for a pose task) and ``J_w`` the
  weighted rows of the method's linear model ``e_dot = -J q_dot`` (the LOCAL frame Jacobian
  for a pose task, the LOCAL_WORLD_ALIGNED linear rows for a position task), masked by the
  task's chain. The linearised error after a step ``v`` is ``e_w - J_w v dt``, and ``v``
  lowers it by ``d(v) = |e_w|^2 - |e_w - J_w v dt|^2``. For the position task the model's
  sign is checked against central differences of the error on the manifold. (For a far pose
  target the method's ``J`` is not ``-de/dq``'s ``Jlog6 J``: the stage reasons in the model,
  so the model is what is tested.)
- ``dq = pin.difference(model, q, q_next) / dt`` is the step's velocity.
- the bounds: each joint's speed limit (0 for a joint off the task's chain) intersected with
  ``(lower - q) / dt <= v <= (upper - q) / dt`` for a 1-DoF joint with finite position
  limits, built here from the URDF's limits (the step is checked to lie within them).
- ``R = |dq_free|``, the Euclidean norm of the same method's step from the same ``q`` with
  ``position_limits=False, velocity_limits=False``: the comparison is with motion of the
  method's own size, not with full speed.
- ``best``: the largest ``d(v)`` over the bounds and the ball ``|v| <= R`` (a convex QP,
  solved exactly by bounded least squares with the ball's multiplier found by bisection, and
  checked against SLSQP and random feasible points below), or the method's own unconstrained
  ``d(dq_free)`` where that is smaller: JT's steepest-descent step lowers the linearised error
  by less than a velocity of its size can, limits or not, and the stage is not asked to do
  better than its method.
- the property: ``d(dq) >= C * best`` whenever ``best`` is above rounding (``REL_TOL |e_w|^2``)
  and above what the library itself calls no progress (``sjt_pin.step_info.STALL_RATE``).

``C = 0.1``. The stage guarantees a quarter of its Cauchy point's decrease (the steepest
descent path within the same bounds and ball: ``docs/limits.md``); the Cauchy point itself
can fall short of ``best`` on an ill-conditioned Jacobian, so the test asks less.
"""

from __future__ import annotations

import re
import warnings
import zlib

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.random_robots import random_urdf
from sjt_pin.step_info import STALL_RATE

#: the fraction of the best decrease of the linearised error that a step must keep
C = 0.1
#: below ``REL_TOL |e_w|^2`` (rounding) or ``STALL_RATE dt |e_w|^2`` (the library's "no
#: progress" over the step) the best decrease counts as none
REL_TOL = 1e-9
METHODS = ("sjt", "jt", "jp", "dls", "default")
ARMS = ("ur5", "panda", "ur10", "xarm7")


# -- robots -------------------------------------------------------------------------------------
def with_finite_speeds(xml: str, speed: float = 3.0) -> str:
    """``xml`` with a speed limit (no position limits) on every continuous joint: the random
    generator leaves them without a ``<limit>``, so with an infinite speed limit."""
    return re.sub(r'(type="continuous">.*?)(</joint>)',
                  rf'\1<limit effort="10" velocity="{speed:g}"/>\2', xml)


_ROBOTS: dict[str, sjt.Robot] = {}


def robot_of(name: str) -> sjt.Robot:
    """``"ur5"`` etc.: example-robot-data; ``"random-<seed>"``: the bench's random tree of
    ``1 + seed % 10`` joints (continuous joints with no speed limit); ``"finite-<seed>"``: the
    same with every continuous joint limited to 3 rad/s."""
    if name not in _ROBOTS:
        if name in ARMS:
            robot = sjt.Robot.from_example(name)
        else:
            kind, seed = name.split("-")
            xml, leaf = random_urdf(int(seed), 1 + int(seed) % 10)
            if kind == "finite":
                xml = with_finite_speeds(xml)
            robot = sjt.Robot.from_urdf(xml, ee_frame=leaf, load_visuals=False)
        _ROBOTS[name] = robot
    return _ROBOTS[name]


def limited_joints(robot: sjt.Robot) -> list[tuple[int, float, float]]:
    """``(q index, lower, upper)`` of the 1-DoF joints with finite position limits."""
    model = robot.model
    out = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        lo, hi = robot.lower_limits[joint.idx_q], robot.upper_limits[joint.idx_q]
        if joint.nq == 1 and joint.nv == 1 and np.isfinite(lo) and np.isfinite(hi):
            out.append((joint.idx_q, float(lo), float(hi)))
    return out


def configuration(robot: sjt.Robot, rng: np.random.Generator, mode: str) -> np.ndarray:
    """Uniform within the range; ``"at"``: then some limited joints exactly at a limit;
    ``"near"``: some within 1e-3 inside a limit."""
    q = robot.random_configuration(rng)
    joints = limited_joints(robot)
    if mode == "uniform" or not joints:
        return q
    picks = rng.choice(len(joints), size=rng.integers(1, len(joints) + 1), replace=False)
    for k in picks:
        i, lo, hi = joints[k]
        inside = 0.0 if mode == "at" else rng.uniform(0.0, 1e-3)
        q[i] = lo + inside if rng.integers(2) == 0 else hi - inside
    return q


def cases(name: str, draws: int):
    """``(q, target pose, label)``: per draw, a configuration of each mode with a far target
    (the pose of a random configuration) and a near one (the pose 0.05 rad/m away, which may
    ask to go beyond a limit)."""
    robot = robot_of(name)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for draw in range(draws):
        for mode in ("uniform", "at", "near"):
            q = configuration(robot, rng, mode)
            far = robot.fk(robot.random_configuration(rng))
            near = robot.fk(pin.integrate(robot.model, q,
                                          rng.normal(scale=0.05, size=robot.nv)))
            yield q, far, f"{mode}/far/{draw}"
            yield q, near, f"{mode}/near/{draw}"


# -- the measure --------------------------------------------------------------------------------
def make(method: str, robot: sjt.Robot, task, **options) -> sjt.Solver:
    if method == "default":
        return sjt.SJTSolver(robot, task=task, **options)
    return sjt.make_solver(method, robot, task=task, **options)


def velocity_box(robot: sjt.Robot, solver, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The position and speed bounds of one step from rest (rad/s, m/s)."""
    speed = np.where(solver.stack.chain > 0, robot.velocity_limits, 0.0)
    lo, hi = -speed, speed.copy()
    model, dt = robot.model, solver.dt
    for j in range(1, model.njoints):
        joint = model.joints[j]
        a, b = robot.lower_limits[joint.idx_q], robot.upper_limits[joint.idx_q]
        if joint.nq == 1 and joint.nv == 1 and np.isfinite(a) and np.isfinite(b):
            lo[joint.idx_v] = max(lo[joint.idx_v], (a - q[joint.idx_q]) / dt)
            hi[joint.idx_v] = min(hi[joint.idx_v], (b - q[joint.idx_q]) / dt)
    return lo, hi


def model_decrease(M: np.ndarray, e: np.ndarray, v: np.ndarray) -> float:
    """How much ``v`` lowers the linearised error: ``|e|^2 - |e - M v|^2``."""
    r = e - M @ v
    return float(e @ e - r @ r)


def best_decrease(M: np.ndarray, e: np.ndarray, lo: np.ndarray, hi: np.ndarray, radius: float
                  ) -> tuple[float, np.ndarray]:
    """``max model_decrease(v)`` over ``lo <= v <= hi`` and ``|v| <= radius`` (a convex QP),
    and its maximiser: the least-squares problem ``min |e - M v|^2 + mu |v|^2`` within the box
    (scipy's exact BVLS), with ``mu >= 0`` the ball's multiplier found by bisection (``|v|``
    falls as ``mu`` grows)."""
    from scipy.optimize import lsq_linear

    n = M.shape[1]
    lo, hi = np.maximum(lo, -radius), np.minimum(hi, radius)  # (the ball bounds each joint)
    fixed = lo >= hi
    lo, hi = np.where(fixed, lo - 1e-300, lo), np.where(fixed, hi + 1e-300, hi)

    def solve(mu: float) -> np.ndarray:
        A = np.vstack([M, np.sqrt(mu) * np.eye(n)])
        v = lsq_linear(A, np.r_[e, np.zeros(n)], bounds=(lo, hi), method="bvls").x
        return np.clip(v, lo, hi)

    v = solve(0.0)
    if np.linalg.norm(v) > radius:
        a, b = 0.0, max(1.0, float(np.linalg.norm(M, 2)) ** 2)
        while np.linalg.norm(solve(b)) > radius:
            a, b = b, 4.0 * b
        for _ in range(60):
            mu = 0.5 * (a + b)
            a, b = (mu, b) if np.linalg.norm(solve(mu)) > radius else (a, mu)
        v = solve(b)
    return model_decrease(M, e, v), v


def task_rows(robot: sjt.Robot, q: np.ndarray, pose: bool) -> np.ndarray:
    if pose:
        return robot.jacobian(q)
    return robot.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:3]


def half_squared_error(robot: sjt.Robot, frame_id: int, sw: np.ndarray, goal, pose: bool):
    model, data = robot.model, robot.model.createData()

    def f(q):
        pin.framesForwardKinematics(model, data, q)
        oMf = data.oMf[frame_id]
        e = pin.log6(oMf.actInv(goal)).vector if pose else goal - oMf.translation
        return 0.5 * float((sw * e) @ (sw * e))

    return f


def central_rate(model, f, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """``-grad f`` on the manifold by central differences."""
    g = np.empty(model.nv)
    for i in range(model.nv):
        d = np.zeros(model.nv)
        d[i] = h
        g[i] = -(f(pin.integrate(model, q, d)) - f(pin.integrate(model, q, -d))) / (2 * h)
    return g


def measure(name: str, method: str, q: np.ndarray, target: pin.SE3, pose: bool) -> dict:
    """One step from rest at ``q``: its rate ``r(dq)``, the best rate within the bounds and
    the method's own step size, and what ``solver.last`` says."""
    robot = robot_of(name)
    goal = target if pose else target.translation.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (reach warnings of far position targets)
        solver = make(method, robot, sjt.PoseTask() if pose else sjt.PositionTask())
        q_next = solver.step(q, goal)
        free = make(method, robot, sjt.PoseTask() if pose else sjt.PositionTask(),
                    position_limits=False, velocity_limits=False)
        q_free = free.step(q, goal)
    model, dt = robot.model, solver.dt
    info = solver.last
    dq = pin.difference(model, q, q_next) / dt
    dq_free = pin.difference(model, q, q_free) / dt
    sw, chain = solver.stack.sqrt_weight, solver.stack.chain
    e = info.error
    f = half_squared_error(robot, solver.stack.task.frame_id, sw, goal, pose)
    assert np.isclose(f(q), 0.5 * float((sw * e) @ (sw * e)), rtol=1e-9, atol=1e-15)
    g = (sw[:, None] * task_rows(robot, q, pose) * chain).T @ (sw * e)
    if not pose:  # the model is the exact derivative: the sign convention, checked
        g_fd = central_rate(model, f, q)
        assert np.allclose(g, g_fd, rtol=1e-5, atol=1e-6 * (np.abs(g).max() + 1e-300))
    lo, hi = velocity_box(robot, solver, q)
    assert np.all(dq >= lo - 1e-9 * (1 + np.abs(lo))) and np.all(dq <= hi + 1e-9 * (1 + np.abs(hi)))
    radius = float(np.linalg.norm(dq_free))
    M = (sw[:, None] * task_rows(robot, q, pose) * chain) * dt
    ew = sw * e
    best, _ = best_decrease(M, ew, lo, hi, radius)
    # what the method's own step would do without limits, where that is less (JT's steepest
    # descent lowers the linearised error by less than a velocity of its size can)
    best = min(best, model_decrease(M, ew, dq_free))
    floor = max(REL_TOL * float(ew @ ew), STALL_RATE * dt * float(ew @ ew))
    return dict(decrease=model_decrease(M, ew, dq), best=best, floor=floor,
                task_scale=info.task_scale, stalled=info.stalled,
                active_limits=info.active_limits, clamped=tuple(int(i) for i in info.clamped))


def shortfalls(name: str, method: str, draws: int) -> tuple[list[str], list[float]]:
    """The cases of robot ``name`` where ``method``'s step keeps less than ``C`` of the best
    decrease, and every ratio measured."""
    bad, ratios = [], []
    for q, target, label in cases(name, draws):
        for pose in (True, False):
            m = measure(name, method, q, target, pose)
            if not m["best"] > m["floor"]:
                continue  # nothing within the bounds lowers the error
            ratio = m["decrease"] / m["best"]
            ratios.append(ratio)
            if ratio < C:
                bad.append(f"{label}/{'pose' if pose else 'position'}: ratio {ratio:.3g}, "
                           f"task_scale {m['task_scale']:.3g}, stalled {m['stalled']}, "
                           f"active {m['active_limits']}, q={np.array2string(q, separator=',')}")
    return bad, ratios


# -- the oracle ---------------------------------------------------------------------------------
def test_best_decrease_is_the_maximum():
    """The least-squares oracle agrees with SLSQP on random boxes (some bounds 0: a joint at a
    limit, some infinite: a continuous joint), models and radii, and no sampled point of the
    feasible set does better."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(0)
    for _ in range(40):
        n, m = int(rng.integers(1, 8)), int(rng.integers(1, 7))
        M, e = rng.normal(size=(m, n)), rng.normal(size=m)
        lo, hi = -rng.uniform(0, 3, n), rng.uniform(0, 3, n)
        lo[rng.random(n) < 0.2] = 0.0
        hi[rng.random(n) < 0.2] = np.inf
        radius = float(rng.uniform(0.1, 5))
        best, v = best_decrease(M, e, lo, hi, radius)
        assert np.all(v >= lo - 1e-12) and np.all(v <= hi + 1e-12)
        assert np.linalg.norm(v) <= radius * (1 + 1e-9)
        bounds = [(a, min(b, radius)) for a, b in zip(lo, hi, strict=True)]
        ball = {"type": "ineq", "fun": lambda x, r=radius: r**2 - x @ x,
                "jac": lambda x: -2 * x}
        res = minimize(lambda x, M=M, e=e: -model_decrease(M, e, x), np.zeros(n),
                       jac=lambda x, M=M, e=e: -2 * M.T @ (e - M @ x), method="SLSQP",
                       bounds=bounds,
                       constraints=[ball], options={"ftol": 1e-14, "maxiter": 500})
        assert -res.fun <= best + 1e-6 * (1 + abs(best))
        for _ in range(50):  # random feasible points
            x = np.clip(rng.normal(size=n) * radius, lo, np.minimum(hi, radius))
            x *= min(1.0, radius / max(np.linalg.norm(x), 1e-300))
            assert model_decrease(M, e, x) <= best + 1e-9 * (1 + abs(best))


# -- the property -------------------------------------------------------------------------------
#: random trees: seeds whose robots have every joint type between them (chains, branches,
#: prismatic, continuous); "random" keeps the generator's unbounded continuous joints
RANDOM_SEEDS = (0, 2, 3, 5, 14, 17, 24, 27, 31, 38)
FINITE_SEEDS = (41, 58, 60, 63, 76, 87, 98, 105)
FAST_ROBOTS = (ARMS + tuple(f"random-{s}" for s in RANDOM_SEEDS)
               + tuple(f"finite-{s}" for s in FINITE_SEEDS))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", FAST_ROBOTS)
def test_step_keeps_a_fraction_of_the_best_decrease(name, method):
    bad, ratios = shortfalls(name, method, draws=2)
    assert ratios, "no case where the error can decrease"
    assert not bad, f"{len(bad)} of {len(ratios)} cases below {C}:\n" + "\n".join(bad)


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("kind", ["random", "finite"])
def test_step_keeps_a_fraction_of_the_best_decrease_sweep(kind, method):
    """40 more random trees of each kind, 3 draws of each configuration mode each."""
    failures, count = [], 0
    for seed in range(1000, 1040):
        name = f"{kind}-{seed}"
        if robot_of(name).nv == 0:
            continue
        bad, ratios = shortfalls(name, method, draws=3)
        count += len(ratios)
        failures += [f"{name} {b}" for b in bad]
    assert not failures, (f"{len(failures)} of {count} cases below {C}:\n"
                          + "\n".join(failures[:20]))
