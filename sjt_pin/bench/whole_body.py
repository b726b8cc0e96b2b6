"""``sjt-pin bench accuracy``'s priority tables: what a posture task at the lowest level costs
the tasks above it, and a humanoid's whole-body scene beside pink's solution of the same tasks.

- **posture** (:func:`posture_rows`): Panda and xArm7 (7 joints each; xArm7 from a bent
  start, its ``q0`` is folded and singular), SJT and DLS with their defaults. An 8 cm pose
  circle (2 s, the orientation held, Δt = 1 ms, the recipe of docs/tasks.md): its max task
  error (m and rad, the ``log6`` norm) without a posture task, with ``PostureTask`` at the
  lowest level (the default; ``q_ref`` the start) and with a weighted posture on the tasks'
  level (``PostureTask(weight=1e-2, priority=0)``). Then the drift of the self-motion: a
  15 cm circle (normal x, 4 s a turn) tracked for 60 s at Δt = 10 ms with a
  ``PositionTask`` (3 rows, 4 redundant joints), the largest joint change (rad, max abs of
  Pinocchio's ``difference``) between the start of the first and of the last turn, without
  and with the posture at the lowest level; and the same from the start of the second turn
  (with the posture the first turn is a transient: the configuration settles on a periodic
  orbit a little off ``q_ref``, which the posture pulls toward with a 1 s time constant at
  Δt = 10 ms, and stays on it). Targets: the error with the posture at most twice the one
  without it, the drift (from the first turn) with it at most 0.002 rad.
- **whole body** (:func:`whole_body_rows`): TALOS (30 joints and a free flyer), the scene of
  docs/whole-body.md: both soles held (``ContactTask``, level 0), both hands
  (``PositionTask``) and the centre of mass's ground position (``CoMTask(axes="xy")``) at
  level 1, ``PostureTask`` at the lowest level, ``SupportLimit(soles, sole=(0.1, 0.05),
  margin=0.02)``; the hands reach 12 and 11 cm along a minimum-jerk path in 1.5 s, then hold
  1 s (Δt = 1 ms), for SJT, DLS and JP. Beside them pink (when installed), the same tasks as
  weighted costs: a ``FrameTask`` on each sole (cost 100 in position and orientation), a
  position-only ``FrameTask`` on each hand (cost 1), a ``ComTask`` (cost 1 on x and y, 0 on
  z), a ``PostureTask`` (cost 1e-3), pink's default configuration and velocity limits, its
  QP (daqp where installed), integrated with the same Δt; and again with the soles as pink's
  hard equality ``constraints``. pink has no support-polygon limit. Per solver: the final
  hand error (m, the worse hand), the largest sole slip over the run (the ``log6`` norm of
  the sole's pose against its start: m and rad), the least centre-of-mass margin (the ground
  projection's distance to the soles' support polygon, taken from the soles' corners at the
  start as ``SupportLimit`` takes it, minus the 0.02 m margin; m, negative: inside the
  margin), the largest joint-limit violation (rad), and the time per step (µs: median, p90,
  max over every step after the first, which binds the tasks). The hands' targets of every
  step are made before the runs. For sjt ``solver.step`` alone is timed; for pink the hand
  tasks' ``set_target``, ``solve_ik``, ``integrate`` and ``Configuration.update`` (its
  kinematics for the next step). Each step is followed on the same configuration by the
  *Pinocchio floor* of these tasks, timed the same way: ``computeJointJacobians``, each of
  the four frames' placement and Jacobian, and ``jacobianCenterOfMass``. Targets: slip at
  most 1e-6, the margin kept (>= 0), hands within 1e-4 m, a step at most 3 times its floor
  and faster than pink.

placo (another QP whole-body solver) is not among the peers: its wheels pin Pinocchio 3.8,
and this package is built against Pinocchio 4.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..kinematics import Kinematics
from ..limits import SupportLimit
from ..limits.support import sole_corners, support_polygon
from ..robot import Robot
from ..solvers import make_solver
from ..tasks import CoMTask, ContactTask, PositionTask, PostureTask
from ..tracking import track
from ..trajectories import Circle, min_jerk
from .speed import Timing

POSTURE_ROBOTS = ("panda", "xarm7")
POSTURE_METHODS = ("sjt", "dls")
#: start configurations (default: the robot's q0): xArm7's q0 is folded and singular
STARTS = {"xarm7": np.array([0.0, -0.5, 0.0, 0.8, 0.0, 1.3, 0.0])}
CIRCLE_RADIUS, CIRCLE_SECONDS = 0.08, 2.0  # m, s: the pose circle
DRIFT_RADIUS, DRIFT_TURN, DRIFT_DT = 0.15, 4.0, 1e-2  # m, s a turn, s
POSTURE_RATIO_TARGET, DRIFT_TARGET = 2.0, 2e-3  # dimensionless, rad

SOLES = ("left_sole_link", "right_sole_link")
HANDS = ("gripper_left_base_link", "gripper_right_base_link")
REACH = (np.array([0.1, 0.05, 0.05]), np.array([0.08, -0.05, -0.05]))  # m, per hand
SOLE, MARGIN = (0.1, 0.05), 0.02  # m: the soles' half length and width; the support margin
WHOLE_BODY_METHODS = ("sjt", "dls", "jp")
PINK_SOLE_COST, PINK_HAND_COST, PINK_COM_COST, PINK_POSTURE_COST = 100.0, 1.0, 1.0, 1e-3
SLIP_TARGET, HAND_TARGET, FLOOR_TARGET = 1e-6, 1e-4, 3.0  # m (log6 norm), m, x floor


@dataclass
class PostureRow:
    """One robot and method: max error of the pose circle (m and rad, log6 norm) without a
    posture task, with it at the lowest level and weighted on the tasks' level; the drift
    over ``seconds`` (rad, max abs) from the start of the first turn to the start of the last
    without and with the posture at the lowest level, the same from the start of the second
    turn (``settled_*``), and the drift runs' largest position error (m)."""

    robot: str
    method: str
    plain: float
    below: float
    weighted: float
    ratio: float  # below / plain
    drift_plain: float
    drift_below: float
    settled_plain: float
    settled_below: float
    drift_error: float
    seconds: float

    @property
    def holds(self) -> bool:
        return self.ratio <= POSTURE_RATIO_TARGET and self.drift_below <= DRIFT_TARGET


def _posture_robot(name: str) -> tuple[Robot, np.ndarray]:
    robot = Robot.from_example(name)
    return robot, STARTS.get(name, robot.q0).copy()


def circle_errors(robot: Robot, q0: np.ndarray, method: str) -> tuple[float, float, float]:
    """Max error on the 8 cm pose circle: no posture, posture lowest, weighted posture."""
    start = robot.fk(q0)
    circle = Circle(start.translation - [CIRCLE_RADIUS, 0.0, 0.0], CIRCLE_RADIUS,
                    duration=CIRCLE_SECONDS, rotation=start.rotation)
    out = []
    for posture in (None, PostureTask(q_ref=q0), PostureTask(q_ref=q0, weight=1e-2, priority=0)):
        out.append(track(make_solver(method, robot, posture=posture), circle, q0).max_error)
    return out[0], out[1], out[2]


def drift(robot: Robot, q0: np.ndarray, method: str, posture: bool,
          seconds: float = 60.0) -> tuple[float, float, float]:
    """A periodic 15 cm circle tracked with a position task at Δt = 10 ms for ``seconds`` (at
    least three turns): the largest joint change (rad) from the start of the first turn to the
    start of the last one, the same from the start of the second turn, and the run's max
    position error (m)."""
    p0 = robot.fk(q0).translation
    turns = max(round(seconds / DRIFT_TURN), 3)
    circle = Circle(p0 - [0.0, DRIFT_RADIUS, 0.0], DRIFT_RADIUS, duration=turns * DRIFT_TURN,
                    normal=[1.0, 0.0, 0.0], turns=turns)
    solver = make_solver(method, robot, dt=DRIFT_DT, task=PositionTask(),
                         posture=PostureTask(q_ref=q0) if posture else None)
    log = track(solver, circle, q0)
    period = round(DRIFT_TURN / DRIFT_DT)
    last = log.q[(turns - 1) * period]  # (log.q[k]: the configuration at t = k dt)

    def change(q):
        return float(np.abs(pin.difference(robot.model, q, last)).max())

    return change(log.q[0]), change(log.q[period]), log.max_error


def posture_rows(robots=POSTURE_ROBOTS, methods=POSTURE_METHODS, seconds: float = 60.0,
                 progress=None) -> list[PostureRow]:
    """A row per robot and method (module docstring); ``seconds``: the drift runs' length."""
    rows = []
    for name in robots:
        robot, q0 = _posture_robot(name)
        for method in methods:
            plain, below, weighted = circle_errors(robot, q0, method)
            free, free_settled, free_error = drift(robot, q0, method, False, seconds)
            held, held_settled, held_error = drift(robot, q0, method, True, seconds)
            rows.append(PostureRow(name, method.upper(), plain, below, weighted,
                                   below / plain, free, held, free_settled, held_settled,
                                   max(free_error, held_error),
                                   max(round(seconds / DRIFT_TURN), 3) * DRIFT_TURN))
            if progress:
                progress(rows[-1])
    return rows


@dataclass
class WholeBodyRow:
    """One solver on the humanoid scene (module docstring): final hand error (m), largest sole
    slip (log6 norm), least centre-of-mass margin (m, distance to the support polygon minus
    the margin), largest joint-limit violation (rad), time per step and its Pinocchio floor
    (µs), and step / floor (medians)."""

    solver: str
    hand_error: float
    slip: float
    com_margin: float
    limit_violation: float
    step: Timing
    floor: Timing
    ratio: float
    steps: int

    @property
    def holds(self) -> bool:
        return (self.slip <= SLIP_TARGET and self.com_margin >= 0.0
                and self.hand_error <= HAND_TARGET)


def talos() -> Robot:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (no end effector known: the tasks name their frames)
        return Robot.from_example("talos")


class _Scene:
    """What every solver of the scene shares: the robot, its start, the held soles, the hands'
    targets, the support polygon, the floor, and the measures of a run."""

    def __init__(self, robot: Robot, reach_seconds: float, hold_seconds: float, dt: float):
        self.robot, self.dt, self.q0 = robot, dt, robot.q0.copy()
        self.held = {f: robot.fk(self.q0, f) for f in SOLES}
        self.start = {h: robot.fk(self.q0, h).translation.copy() for h in HANDS}
        self.goal = {h: self.start[h] + r for h, r in zip(HANDS, REACH, strict=True)}
        kinematics = Kinematics(robot.model)
        kinematics.update(self.q0)
        self.com = kinematics.center_of_mass()[0].copy()
        _, self.normals, self.offsets = support_polygon(self.held.values(), sole_corners(SOLE),
                                                        SOLES)
        self.steps = round((reach_seconds + hold_seconds) / dt)
        self.reach_steps = round(reach_seconds / dt)
        #: the hands' targets of every step, made before the runs: a step's time is the
        #: solver's alone, not that of the minimum-jerk path's arithmetic (6 us a step)
        self.targets = [self.hand_targets(k) for k in range(self.steps)]
        self.data = robot.model.createData()
        self.lower, self.upper = robot.lower_limits, robot.upper_limits
        ids = [robot.frame_id(f) for f in (*SOLES, *HANDS)]
        frames = list(zip(ids, [pin.LOCAL] * len(SOLES) + [pin.LOCAL_WORLD_ALIGNED] * len(HANDS),
                          strict=True))
        model, data = robot.model, robot.model.createData()

        def floor(q):
            pin.computeJointJacobians(model, data, q)
            for fid, frame in frames:
                pin.updateFramePlacement(model, data, fid)
                pin.getFrameJacobian(model, data, fid, frame)
            pin.jacobianCenterOfMass(model, data, False)

        self.floor = floor

    def hand_targets(self, k: int) -> dict[str, np.ndarray]:
        s = min_jerk(k / self.reach_steps)
        return {h: self.start[h] + s * (self.goal[h] - self.start[h]) for h in HANDS}

    def run(self, name: str, step) -> WholeBodyRow:
        """``step(q, k) -> q`` over the scene's steps, timed against the floor, measured."""
        model, data, clock = self.robot.model, self.data, time.perf_counter_ns
        q, slip, margin, violation = self.q0.copy(), 0.0, np.inf, 0.0
        steps, floors = np.empty(self.steps), np.empty(self.steps)
        for k in range(self.steps):
            begin = clock()
            q_next = step(q, k)
            middle = clock()
            self.floor(q)
            steps[k], floors[k] = middle - begin, clock() - middle
            q = q_next
            pin.framesForwardKinematics(model, data, q)
            for f, held in self.held.items():
                oMf = data.oMf[model.getFrameId(f)]
                slip = max(slip, float(np.linalg.norm(pin.log6(oMf.actInv(held)).vector)))
            c = pin.centerOfMass(model, data, q, False)
            margin = min(margin, float((self.normals @ c[:2] - self.offsets).min()) - MARGIN)
            violation = max(violation, float(np.max(self.lower - q, initial=0.0)),
                            float(np.max(q - self.upper, initial=0.0)))
        pin.framesForwardKinematics(model, data, q)
        error = max(float(np.linalg.norm(data.oMf[model.getFrameId(h)].translation
                                         - self.goal[h])) for h in HANDS)
        step_time, floor_time = Timing.of(steps[1:]), Timing.of(floors[1:])
        return WholeBodyRow(name, error, slip, margin, violation, step_time, floor_time,
                            step_time.median / floor_time.median, self.steps)


def _sjt_run(scene: _Scene, method: str) -> WholeBodyRow:
    tasks = {f: ContactTask(f) for f in SOLES}
    tasks.update({h: PositionTask(h, priority=1) for h in HANDS})
    tasks["com"] = CoMTask(axes="xy", priority=1)
    support = SupportLimit(list(SOLES), sole=SOLE, margin=MARGIN)
    solver = make_solver(method, scene.robot, dt=scene.dt, task=tasks, limits=[support],
                         posture=PostureTask())

    targets = [{**hands, "com": scene.com} for hands in scene.targets]

    def step(q, k):
        return solver.step(q, targets[k])

    return scene.run(method.upper(), step)


def _has_pink() -> bool:
    try:
        import pink  # noqa: F401
        import qpsolvers  # noqa: F401
    except ImportError:
        return False
    return True


def _pink_run(scene: _Scene, constrained: bool) -> WholeBodyRow:
    import pink
    import qpsolvers
    from pink.tasks import ComTask, FrameTask
    from pink.tasks import PostureTask as PinkPosture

    qp = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    robot = scene.robot
    configuration = pink.Configuration(robot.model, robot.model.createData(), scene.q0)
    soles = []
    for f in SOLES:
        task = FrameTask(f, position_cost=PINK_SOLE_COST, orientation_cost=PINK_SOLE_COST)
        task.set_target(scene.held[f])
        soles.append(task)
    hands = {h: FrameTask(h, position_cost=PINK_HAND_COST, orientation_cost=0.0) for h in HANDS}
    com = ComTask(cost=np.array([PINK_COM_COST, PINK_COM_COST, 0.0]))
    com.set_target(scene.com)
    posture = PinkPosture(cost=PINK_POSTURE_COST)
    posture.set_target(scene.q0)
    tasks = [*hands.values(), com, posture] + ([] if constrained else soles)
    constraints = soles if constrained else None
    rotations = {h: configuration.get_transform_frame_to_world(h).rotation for h in HANDS}

    def step(q, k):
        for h, p in scene.targets[k].items():
            hands[h].set_target(pin.SE3(rotations[h], p))
        velocity = pink.solve_ik(configuration, tasks, scene.dt, solver=qp,
                                 constraints=constraints)
        q_next = configuration.integrate(velocity, scene.dt)
        configuration.update(q_next)
        return q_next

    name = f"pink ({qp}, soles as {'constraints' if constrained else 'costs'})"
    return scene.run(name, step)


def whole_body_rows(methods=WHOLE_BODY_METHODS, peers: bool = True, reach_seconds: float = 1.5,
                    hold_seconds: float = 1.0, dt: float = 1e-3, progress=None
                    ) -> list[WholeBodyRow]:
    """A row per method of ``methods`` on the humanoid scene, and pink's two rows (when
    ``peers`` and installed)."""
    scene = _Scene(talos(), reach_seconds, hold_seconds, dt)
    runs = [lambda m=m: _sjt_run(scene, m) for m in methods]
    if peers and _has_pink():
        runs += [lambda c=c: _pink_run(scene, c) for c in (False, True)]
    rows = []
    for run in runs:
        rows.append(run())
        if progress:
            progress(rows[-1])
    return rows


def posture_table(rows: list[PostureRow]) -> str:
    lines = ["| robot | method | circle, no posture | posture lowest | weighted posture, level 0 "
             "| lowest / none | drift, no posture [rad] | drift, posture lowest [rad] "
             "| from turn 2: no posture, posture lowest [rad] | drift runs' max error [m] "
             "| targets |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.robot} | {r.method} | {r.plain:.2g} | {r.below:.2g} | "
                     f"{r.weighted:.2g} | {r.ratio:.2f} | {r.drift_plain:.3g} | "
                     f"{r.drift_below:.2g} | {r.settled_plain:.3g}, {r.settled_below:.2g} | "
                     f"{r.drift_error:.2g} | {'hold' if r.holds else 'MISS'} |")
    return "\n".join(lines)


def whole_body_table(rows: list[WholeBodyRow]) -> str:
    lines = ["| solver | hand error [m] | max slip | min CoM margin [m] | limit violation [rad] "
             "| median [µs] | p90 [µs] | max [µs] | floor [µs] | step / floor |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.solver} | {r.hand_error:.1e} | {r.slip:.1e} | {r.com_margin:.4f} | "
                     f"{r.limit_violation:.1e} | {r.step.median:.0f} | {r.step.p90:.0f} | "
                     f"{r.step.max:.0f} | {r.floor.median:.1f} | {r.ratio:.1f} |")
    return "\n".join(lines)
