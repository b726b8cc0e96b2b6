"""``sjt-pin bench settle``: does the arm get where it is sent and come to rest there, under
random acceleration and jerk limits, from starts against its ranges?

Nine arms of example-robot-data (UR3, UR5 and UR10 limited, UR5 with its gripper, Kinova,
xArm7, Z1, Bravo 7, TALOS's arm), four methods, ``seeds`` draws per arm (1 kHz, the default
``PositionTask`` or ``PoseTask`` of the arm's end-effector frame). Each draw (seeded: the same
runs on every machine):

- a start over the URDF ranges (a continuous joint over a turn) with each joint at one end of
  its range with probability 1/4;
- limits per joint: acceleration log-uniform in 1-50 rad/s^2 (none with probability 1/4),
  jerk log-uniform in 10-10,000 times that (none with probability 0.3);
- one of three scenes in turn: a **reach** (a target at the pose of random joint values over
  the ranges, position or pose task), a target **beyond** reach (in the direction of such a
  pose's position from the base, 0.1-1 m further than the farthest of 1,000 random
  configurations' positions; position task), or a **stream** (a new target every 0.5 s for 4 s,
  a third of them 0.5 m further out, then a reachable one held).

Each run lasts 10 s, and up to 30 s where the arm is still moving at 10 s. Per run: the final
error, the largest joint speed over the last second, the number of times the fastest joint
reverses over the last 2 s, when it last moved faster than 1e-5 rad/s (rest) and when it
reached the final target (error below 1e-3), and the largest ratio of finite-difference
speed, acceleration and jerk to their limits over the run (after the final target is set, for
acceleration and jerk: a target stream's jumps may ask more of a joint than its limits give,
which the stage then yields and reports). A run *rests* below 1e-6 rad/s, *swings* where the
fastest joint reversed 4 times or more in its last 2 s above 1e-4 rad/s, *moves* above 1e-3
rad/s otherwise and *creeps* in between.

The reach scenes' misses are local minima against the ranges (``Solver.move_to`` reaches
those; see ``sjt-pin bench reach``); this table is about rest, swing and the limits.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..solvers import make_solver
from ..tasks import PoseTask, PositionTask

ARMS = ("ur3_limited", "ur5_limited", "ur10_limited", "ur5_gripper", "kinova", "xarm7", "z1",
        "bravo7_no_ee", "talos_arm")
METHODS = ("sjt", "dls", "jp", "jt")
SCENES = ("reach", "beyond", "stream")
DT, SECONDS, LONGEST = 1e-3, 10.0, 30.0  # s
REST, CREEP, SWING = 1e-6, 1e-3, 1e-4  # rad/s
REACHED = 1e-3  # the task error's norm (m and rad)


@dataclass
class SettleRow:
    """One run (module docstring): speeds in rad/s (m/s), times in s from the run's start."""

    robot: str
    seed: int
    method: str
    scene: str
    task: str
    acceleration: bool
    jerk: bool
    reachable: bool
    error: float
    speed: float
    reversals: int
    seconds: float
    rest_s: float
    reach_s: float | None
    ratio_v: float
    ratio_a: float  # NaN without an acceleration limit
    ratio_j: float  # NaN without a jerk limit

    @property
    def state(self) -> str:
        """``rest``, ``swing``, ``move`` or ``creep`` (module docstring)."""
        if self.speed < REST:
            return "rest"
        if self.reversals >= 4 and self.speed > SWING:
            return "swing"
        return "move" if self.speed > CREEP else "creep"


@dataclass
class Draw:
    """One draw of the module docstring: the start, the scene, the task (``"position"`` or
    ``"pose"``), the limits (None where not drawn) and the targets from their times (s)."""

    q0: np.ndarray
    scene: str
    task: str
    acceleration: np.ndarray | None
    jerk: np.ndarray | None
    targets: list  # (time s, target)


def _ranges(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    wide = ~(np.isfinite(lo) & np.isfinite(hi)) | (hi - lo > 20.0)
    lo[wide], hi[wide] = -np.pi, np.pi
    return lo, hi


def _random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    lo, hi = _ranges(model)
    pin.seed(int(rng.integers(1 << 30)))
    return pin.randomConfiguration(model, lo, hi)


_REACH: dict[str, float] = {}


def _reach(robot: Robot) -> float:
    """The frame's largest distance from the base (m) over 1,000 random configurations."""
    if robot.name not in _REACH:
        rng = np.random.default_rng(0)
        _REACH[robot.name] = max(
            float(np.linalg.norm(robot.fk(_random_q(robot.model, rng)).translation))
            for _ in range(1000))
    return _REACH[robot.name]


def draw(robot: Robot, seed: int) -> Draw:
    """The draw ``seed`` of ``robot`` (module docstring): the same on every machine."""
    model = robot.model
    rng = np.random.default_rng(1000 * seed + sum(map(ord, robot.name)))
    q0 = _random_q(model, rng)
    for joint in model.joints[1:]:  # a quarter of the limited joints start at a range's end
        if joint.nq == 1 and rng.random() < 0.25:
            i = joint.idx_q
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            if np.isfinite(lo) and np.isfinite(hi) and hi - lo < 20.0:
                q0[i] = lo if rng.random() < 0.5 else hi
    scene = SCENES[seed % 3]
    nv = model.nv
    acceleration = None if rng.random() < 0.25 else np.exp(rng.uniform(0.0, np.log(50.0), nv))
    jerk = (None if acceleration is None or rng.random() < 0.3
            else acceleration * np.exp(rng.uniform(np.log(10.0), np.log(1e4), nv)))
    task = "position" if scene == "beyond" or rng.random() < 0.5 else "pose"

    def target(q, beyond=0.0):
        pose = robot.fk(q)
        out = pose.translation / max(np.linalg.norm(pose.translation), 1e-9)
        p = pose.translation + beyond * out
        return p if task == "position" else pin.SE3(pose.rotation, p)

    final = target(_random_q(model, rng))
    if scene == "beyond":  # (position task: its direction from the base, past the reach)
        out = final / max(np.linalg.norm(final), 1e-9)
        final = (_reach(robot) + rng.uniform(0.1, 1.0)) * out
        return Draw(q0, scene, task, acceleration, jerk, [(0.0, final)])
    targets = []
    if scene == "stream":
        for k in range(8):
            q = _random_q(model, rng)
            targets.append((0.5 * k, target(q, 0.5 if rng.random() < 1 / 3 else 0.0)))
    targets.append((4.0 if targets else 0.0, final))
    return Draw(q0, scene, task, acceleration, jerk, targets)


def joint_angles(model: pin.Model, qs: np.ndarray) -> np.ndarray:
    """``qs`` (k, nq) as (k, nv) joint coordinates: a continuous joint's (cos, sin) as its
    unwrapped angle (its finite differences then keep the digits Pinocchio's ``difference``
    loses on tiny steps of such a joint). Revolute, prismatic and continuous joints only."""
    out = np.empty((len(qs), model.nv))
    for joint in model.joints[1:]:
        i, v = joint.idx_q, joint.idx_v
        if joint.nq == 1:
            out[:, v] = qs[:, i]
        elif joint.nq == 2 and joint.nv == 1:
            out[:, v] = np.unwrap(np.arctan2(qs[:, i + 1], qs[:, i]))
        else:
            raise ValueError(f"joint {joint.shortname()}: only 1-dof joints are measured")
    return out


def run(robot: Robot, seed: int, method: str) -> SettleRow:
    """One run of the module docstring."""
    drawn = draw(robot, seed)
    limits = {}
    if drawn.acceleration is not None:
        limits["acceleration_limits"] = drawn.acceleration
    if drawn.jerk is not None:
        limits["jerk_limits"] = drawn.jerk
    task = PositionTask() if drawn.task == "position" else PoseTask()
    solver = make_solver(method, robot, dt=DT, task=task, **limits)
    steps, longest = round(SECONDS / DT), round(LONGEST / DT)
    qs = np.empty((longest + 1, robot.model.nq))
    errors = np.empty(longest)
    q = qs[0] = drawn.q0
    switches = [round(t / DT) for t, _ in drawn.targets]
    k, goal = 0, drawn.targets[0][1]
    i = 0
    while i < longest:
        while k + 1 < len(switches) and i >= switches[k + 1]:
            k += 1
            goal = drawn.targets[k][1]
        q = qs[i + 1] = solver.step(q, goal)
        errors[i] = solver.error_norm
        i += 1
        if i == steps and np.abs(np.diff(qs[i - 1000:i + 1], axis=0)).max() < REST * DT:
            break
    x = joint_angles(robot.model, qs[:i + 1])
    v = np.diff(x, axis=0) / DT
    a = np.diff(v, axis=0) / DT
    j = np.diff(a, axis=0) / DT
    held = switches[-1] + 2  # (the last target's jump: a stream may ask more than the limits)
    speed_limit = robot.model.velocityLimit
    ratio_v = float(np.max(np.abs(v) / np.where(speed_limit > 0, speed_limit, np.inf)))
    ratio_a = (float(np.max(np.abs(a[held:]) / drawn.acceleration))
               if drawn.acceleration is not None else np.nan)
    ratio_j = float(np.max(np.abs(j[held:]) / drawn.jerk)) if drawn.jerk is not None else np.nan
    last = v[-2000:]
    peak = np.abs(last).max(axis=0)
    fastest = last[:, int(np.argmax(peak))]
    signs = np.sign(fastest[np.abs(fastest) > 0.05 * peak.max()])
    reversals = int(np.sum(signs[1:] != signs[:-1])) if peak.max() > 1e-5 else 0
    moving = np.nonzero(np.abs(v).max(axis=1) > 1e-5)[0]
    reached = np.nonzero(errors[switches[-1]:i] < REACHED)[0]
    return SettleRow(robot.name, seed, method, drawn.scene, drawn.task,
                     drawn.acceleration is not None, drawn.jerk is not None,
                     drawn.scene != "beyond", float(errors[i - 1]),
                     float(np.abs(v[-1000:]).max()), reversals, i * DT,
                     float((moving[-1] + 1) * DT) if len(moving) else 0.0,
                     float((switches[-1] + reached[0] + 1) * DT) if len(reached) else None,
                     ratio_v, ratio_a, ratio_j)


def settle(seeds: int = 40, arms=ARMS, methods=METHODS,
           progress: Callable[[SettleRow], None] | None = None) -> list[SettleRow]:
    """Every run of the module docstring: ``seeds`` draws per arm, each with every method."""
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (starts at a range's end are meant)
        robots = {name: Robot.from_example(name) for name in arms}
        for seed in range(seeds):
            for name in arms:
                for method in methods:
                    row = run(robots[name], seed, method)
                    rows.append(row)
                    if progress is not None:
                        progress(row)
    return rows


def _largest(values: list[float]) -> float:
    given = [v for v in values if not np.isnan(v)]
    return max(given) if given else float("nan")


def settle_summary(rows: list[SettleRow]) -> list[dict]:
    """Per arm, then ``all``: runs; at rest, swinging, moving and creeping at the end;
    reachable targets and those reached; the median time to rest (s) of the runs at rest; the
    largest speed, acceleration and jerk ratios (NaN where no run had that limit)."""
    groups: dict[str, list[SettleRow]] = {}
    for row in rows:
        groups.setdefault(row.robot, []).append(row)
    groups["all"] = rows
    out = []
    for name, group in groups.items():
        states = [r.state for r in group]
        reachable = [r for r in group if r.reachable]
        rest = [r.rest_s for r in group if r.state == "rest"]
        out.append({"arm": name, "runs": len(group), "rest": states.count("rest"),
                    "swing": states.count("swing"), "move": states.count("move"),
                    "creep": states.count("creep"), "reachable": len(reachable),
                    "reached": sum(r.error < REACHED for r in reachable),
                    "median_rest": float(np.median(rest)) if rest else float("nan"),
                    "ratio_v": max(r.ratio_v for r in group),
                    "ratio_a": _largest([r.ratio_a for r in group]),
                    "ratio_j": _largest([r.ratio_j for r in group])})
    return out


def settle_table(rows: list[SettleRow]) -> str:
    """Markdown table of :func:`settle_summary`."""
    lines = ["| arm | runs | at rest | swing | move | creep | reached | median rest (s) | "
             "max v / a / j ratio |", "|---|---|---|---|---|---|---|---|---|"]
    for s in settle_summary(rows):
        lines.append(f"| {s['arm']} | {s['runs']} | {s['rest']} | {s['swing']} | {s['move']} | "
                     f"{s['creep']} | {s['reached']} / {s['reachable']} | "
                     f"{s['median_rest']:.2f} | {s['ratio_v']:.3f} / {s['ratio_a']:.3f} / "
                     f"{s['ratio_j']:.3f} |")
    return "\n".join(lines)
