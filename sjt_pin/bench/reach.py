"""``sjt-pin bench reach``: does the arm get where it is sent, and does it settle?

- **random** (:func:`random_reaches`): random starts and reachable targets (the forward
  kinematics of random configurations), both drawn over the full URDF ranges, 5 s of
  ``step()`` at 1 kHz with the URDF's position and speed limits, every method with its
  defaults; beside pink (its ``FrameTask`` with its configuration and velocity limits, when
  installed) on the same pairs, and beside ``move_to`` (``solve()``, then a timed joint move)
  on the targets ``solve()`` finds. A run reaches its target when the position error is below
  1 mm and the orientation error below 0.01 rad. Local methods stop at local minima against
  the joint limits, pink's QP among them: the table counts how often, the pairs one reaches
  and the other does not, and how far the misses stop.
- **jerk** (:func:`jerk_grid`): the same arms in turn, acceleration limits 1-50 rad/s²,
  jerk/acceleration 10-10,000 1/s, targets 1 mm to 1 m away: the time until the arm rests on
  the target (error below 1e-6, every joint below 1e-6 rad/s), beside Ruckig's time-optimal
  duration for the same joint motion within the same limits (10 rad/s for a joint without a
  speed limit; when installed), and the largest finite-difference speed, acceleration and
  jerk over their limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..solvers import SJTSolver, make_solver

ROBOTS = ("ur5", "ur10", "panda", "xarm7", "kinova")
METHODS = ("sjt", "jt", "jp", "dls")
POSITION_TOLERANCE = 1e-3  # m
ORIENTATION_TOLERANCE = 1e-2  # rad
DT = 1e-3


@dataclass
class ReachRow:
    """One robot and method over the same random pairs. ``failures`` is the share of runs that
    end beyond the tolerances; ``median_miss`` the median position error (m) of those runs;
    ``peer_only`` and ``only`` the pairs pink reaches and this method misses, and the reverse
    (``None`` without pink); ``worst_speed`` the largest finite-difference joint speed over its
    URDF limit; ``in_range`` whether every ``q`` stayed within the URDF range."""

    robot: str
    method: str
    pairs: int
    failures: float
    median_miss: float
    peer_only: int | None
    only: int | None
    worst_speed: float
    in_range: bool


@dataclass
class _Run:
    position: float
    orientation: float
    worst_speed: float
    in_range: bool

    @property
    def reached(self) -> bool:
        return self.position < POSITION_TOLERANCE and self.orientation < ORIENTATION_TOLERANCE


def _error(robot: Robot, q: np.ndarray, target: pin.SE3) -> tuple[float, float]:
    """The hand's distance to the target (m) and its rotation from the target's (rad)."""
    pose = robot.fk(q)
    return (float(np.linalg.norm(target.translation - pose.translation)),
            float(np.linalg.norm(pin.log3(pose.rotation.T @ target.rotation))))


def _in_range(robot: Robot, q: np.ndarray) -> bool:
    return bool(np.all(q >= robot.lower_limits - 1e-12) and np.all(q <= robot.upper_limits + 1e-12))


class _Watch:
    """Finite-difference joint speeds over the URDF limits, and the URDF range, along a run."""

    def __init__(self, robot: Robot, q: np.ndarray):
        self.robot, self.q, self.worst, self.in_range = robot, q, 0.0, True
        limits = robot.velocity_limits
        self.limits = np.where(np.isfinite(limits) & (limits > 0), limits, np.inf)
        self.still = 0

    def see(self, q: np.ndarray) -> bool:
        """Record ``q``; True once the arm has rested for 0.1 s (the run can stop)."""
        speed = np.abs(pin.difference(self.robot.model, self.q, q)) / DT
        self.worst = max(self.worst, float(np.max(speed / self.limits)))
        self.in_range &= _in_range(self.robot, q)
        self.still = self.still + 1 if speed.max() < 1e-9 else 0
        self.q = q
        return self.still > 100


def _reach(robot: Robot, method: str, q0: np.ndarray, target: pin.SE3, seconds: float) -> _Run:
    solver = make_solver(method, robot)
    q, watch = q0.copy(), _Watch(robot, q0)
    for _ in range(round(seconds / DT)):
        q = solver.step(q, target)
        if watch.see(q):
            break
    return _Run(*_error(robot, q, target), watch.worst, watch.in_range)


def _move_to(robot: Robot, q0: np.ndarray, target: pin.SE3, seconds: float) -> _Run | None:
    """``move_to`` then 1 s of ``step()``; None where ``solve()`` finds no configuration."""
    solver = SJTSolver(robot)
    try:
        move = solver.move_to(q0, target)
    except ValueError:
        return None
    q, watch = q0.copy(), _Watch(robot, q0)
    for _ in range(round(60.0 / DT)):  # (a move of a minute is not one the bench waits for)
        if move.done:
            break
        q = move.step(q)
        watch.see(q)
    for _ in range(round(seconds / DT)):
        q = solver.step(q, target)
        if watch.see(q):
            break
    return _Run(*_error(robot, q, target), watch.worst, watch.in_range)


def _pink(robot: Robot, q0: np.ndarray, target: pin.SE3, seconds: float) -> _Run:
    import pink
    import qpsolvers
    from pink.limits import ConfigurationLimit, VelocityLimit
    from pink.tasks import FrameTask

    qp = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    configuration = pink.Configuration(robot.model, robot.model.createData(), q0.copy())
    task = FrameTask(robot.ee_frame, position_cost=1.0, orientation_cost=1.0)
    task.set_target(target)
    limits = [ConfigurationLimit(robot.model), VelocityLimit(robot.model)]
    q, watch = q0.copy(), _Watch(robot, q0)
    for _ in range(round(seconds / DT)):
        try:
            velocity = pink.solve_ik(configuration, [task], DT, solver=qp, limits=limits,
                                     damping=1e-12)
        except Exception:  # noqa: BLE001 - pink's NoSolutionFound, or its QP's failure: it stops
            break
        q = configuration.integrate(velocity, DT)
        configuration.update(q)
        if watch.see(q):
            break
    return _Run(*_error(robot, q, target), watch.worst, watch.in_range)


def _has_pink() -> bool:
    try:
        import pink  # noqa: F401
        import qpsolvers  # noqa: F401
    except ImportError:
        return False
    return True


def _row(name: str, method: str, runs: list[_Run], peer: list[_Run] | None) -> ReachRow:
    ok = np.array([r.reached for r in runs])
    misses = [r.position for r in runs if not r.reached]
    peer_only = only = None
    if peer is not None:
        theirs = np.array([r.reached for r in peer])
        peer_only, only = int(np.sum(theirs & ~ok)), int(np.sum(ok & ~theirs))
    return ReachRow(name, method, len(runs), float(1 - ok.mean()) if runs else math.nan,
                    float(np.median(misses)) if misses else math.nan, peer_only, only,
                    max((r.worst_speed for r in runs), default=0.0),
                    all(r.in_range for r in runs))


def random_reaches(robots=ROBOTS, pairs: int = 50, seconds: float = 5.0, methods=METHODS,
                   peers: bool = True, seed: int = 0, progress=None) -> list[ReachRow]:
    """Rows per robot: every method of ``methods``, ``move_to`` (on the targets ``solve()``
    finds) and pink (when ``peers`` and installed), on ``pairs`` random (start, target)
    pairs."""
    rows = []
    with_pink = peers and _has_pink()
    for name in robots:
        robot = Robot.from_example(name)
        rng = np.random.default_rng(seed)
        draws = [(robot.random_configuration(rng), robot.random_configuration(rng))
                 for _ in range(pairs)]
        cases = [(q0, robot.fk(qt)) for q0, qt in draws]
        peer = [_pink(robot, q0, target, seconds) for q0, target in cases] if with_pink else None
        for method in methods:
            row = _row(name, method, [_reach(robot, method, q0, t, seconds) for q0, t in cases],
                       peer)
            rows.append(row)
            if progress:
                progress(row)
        moved = [_move_to(robot, q0, t, 1.0) for q0, t in cases]
        rows.append(_row(name, "move_to", [r for r in moved if r is not None], None))
        if progress:
            progress(rows[-1])
        if peer is not None:
            rows.append(_row(name, "pink", peer, None))
    return rows


@dataclass
class JerkRow:
    """One run of the jerk grid: the limits, the hand's distance (m) to the target, Ruckig's
    duration for the same joint motion (s; nan without Ruckig), the time the arm came to rest
    on the target (s; nan if it did not within the run), ``share``: that time over the
    target, 2 x Ruckig's duration + 0.1 s, and the largest finite-difference speed,
    acceleration and jerk over their limits."""

    robot: str
    acceleration: float
    ratio: float
    distance: float
    ruckig: float
    rest: float
    share: float
    worst_limit: float
    final_error: float


def ruckig_duration(q0: np.ndarray, q1: np.ndarray, velocity, acceleration, jerk) -> float:
    """Ruckig's time-optimal duration from rest at q0 to rest at q1 (nan without Ruckig)."""
    try:
        from ruckig import InputParameter, Ruckig, Trajectory
    except ImportError:
        return math.nan
    n = q0.size
    problem = InputParameter(n)
    problem.current_position, problem.target_position = list(q0), list(q1)
    problem.current_velocity = problem.current_acceleration = [0.0] * n
    problem.target_velocity = problem.target_acceleration = [0.0] * n
    problem.max_velocity, problem.max_acceleration = list(velocity), list(acceleration)
    problem.max_jerk = list(jerk)
    trajectory = Trajectory(n)
    Ruckig(n).calculate(problem, trajectory)
    return float(trajectory.duration)


def _target_at(robot: Robot, q0: np.ndarray, distance: float,
               rng: np.random.Generator) -> np.ndarray:
    """A configuration along a random joint direction whose hand is about ``distance`` from
    q0's (within the position limits: the distance the run records is the achieved one)."""
    direction, start, scale = rng.normal(size=robot.nv), robot.fk(q0).translation, 0.01
    for _ in range(60):
        q = pin.integrate(robot.model, q0, scale * direction)
        if np.linalg.norm(robot.fk(q).translation - start) >= distance:
            break
        scale *= 1.2
    return np.clip(q, robot.lower_limits, robot.upper_limits)


def jerk_grid(trials: int = 30, robots=ROBOTS, seconds: float = 20.0, seed: int = 0,
              progress=None) -> list[JerkRow]:
    """``trials`` runs of the default SJT solver, round-robin over ``robots``, each from a
    random configuration in the middle half of the ranges to a random target."""
    rng = np.random.default_rng(seed)
    loaded = {name: Robot.from_example(name) for name in dict.fromkeys(robots)}
    rows = []
    for trial in range(trials):
        robot = loaded[robots[trial % len(robots)]]
        lower, upper = robot.lower_limits, robot.upper_limits
        bounded = np.isfinite(lower) & np.isfinite(upper)  # (continuous joints: from q0)
        middle = 0.5 * (lower[bounded] + upper[bounded])
        half = 0.25 * (upper[bounded] - lower[bounded])
        q0 = robot.q0.copy()
        q0[bounded] = rng.uniform(middle - half, middle + half)
        q0 = np.clip(q0, robot.lower_limits, robot.upper_limits)
        acceleration = 10 ** rng.uniform(0, math.log10(50))
        ratio = 10 ** rng.uniform(1, 4)
        goal = _target_at(robot, q0, 10 ** rng.uniform(-3, 0), rng)
        target = robot.fk(goal)
        distance = float(np.linalg.norm(target.translation - robot.fk(q0).translation))
        solver = SJTSolver(robot, acceleration_limits=acceleration,
                           jerk_limits=acceleration * ratio)
        rows.append(_settle(robot, solver, q0, target, acceleration, ratio, distance, seconds))
        if progress:
            progress(rows[-1])
    return rows


def _settle(robot: Robot, solver: SJTSolver, q0: np.ndarray, target: pin.SE3,
            acceleration: float, ratio: float, distance: float, seconds: float) -> JerkRow:
    speed_limit = np.where(np.isfinite(robot.velocity_limits), robot.velocity_limits, np.inf)
    q, v0, a0, worst, rest = q0.copy(), np.zeros(robot.nv), np.zeros(robot.nv), 0.0, math.nan
    for k in range(round(seconds / DT)):
        q_next = solver.step(q, target)
        v = pin.difference(robot.model, q, q_next) / DT
        a = (v - v0) / DT
        j = (a - a0) / DT
        worst = max(worst, float(np.max(np.abs(v) / speed_limit)),
                    float(np.max(np.abs(a))) / acceleration,
                    float(np.max(np.abs(j))) / (acceleration * ratio))
        q, v0, a0 = q_next, v, a
        if solver.error_norm < 1e-6 and np.abs(v).max() < 1e-6:
            if math.isnan(rest):
                rest = (k + 1) * DT
            elif (k + 1) * DT > rest + 0.05:
                break
        else:
            rest = math.nan
    limit = np.where(np.isfinite(speed_limit), speed_limit, 10.0)
    ruckig = ruckig_duration(np.zeros(robot.nv), pin.difference(robot.model, q0, q), limit,
                             np.full(robot.nv, acceleration),
                             np.full(robot.nv, acceleration * ratio))
    return JerkRow(robot.name, acceleration, ratio, distance, ruckig, rest,
                   rest / (2 * ruckig + 0.1), worst, float(solver.error_norm))


def reach_table(rows: list[ReachRow]) -> str:
    lines = ["| robot | method | pairs | missed | median miss [m] | pink only / method only "
             "| max speed / limit | in range |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        versus = "–" if r.peer_only is None else f"{r.peer_only} / {r.only}"
        lines.append(f"| {r.robot} | {r.method} | {r.pairs} | {r.failures:.0%} | "
                     f"{r.median_miss:.3f} | {versus} | {r.worst_speed:.3f} | {r.in_range} |")
    return "\n".join(lines)


def jerk_table(rows: list[JerkRow]) -> str:
    lines = ["| robot | acc. [rad/s²] | jerk/acc. [1/s] | distance [m] | Ruckig [s] | at rest "
             "[s] | of 2 Ruckig + 0.1 s | max limit ratio |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.robot} | {r.acceleration:.1f} | {r.ratio:.0f} | {r.distance:.3f} | "
                     f"{r.ruckig:.3f} | {r.rest:.3f} | {r.share:.2f} | "
                     f"{r.worst_limit:.3f} |")
    return "\n".join(lines)
