"""``sjt-pin bench ik``: solve-to-pose on random reachable poses (TRAC-IK's protocol).

Per robot, each target is the forward kinematics of a random configuration within the limits,
solved from another random configuration within the limits (seeded: every run draws the same
poses). A solution counts when its position error is below 1e-5 m, its rotation error below
1e-4 rad, every joint is within its limits and its (cos, sin) pairs are unit vectors; the check
(:func:`solved`) is this module's own, not the solver's claim.

Runners:

- sjt-pin's :meth:`~sjt_pin.Solver.solve` with its defaults, SJT and DLS (budget: 2000
  iterations, no time limit), and SJT with ``timeout=0.005`` (5 ms, TRAC-IK's budget, as
  well);
- TRAC-IK (C++, ``pytracik``): Speed mode, 5 ms timeout, eps 1e-5;
- robotics-toolbox's C++ ``ik_LM`` on the same URDF file, when ``roboticstoolbox`` imports.

The peers work in joint values on the chain from the URDF's root link to the link of the
end-effector frame (:class:`Chain`): continuous joints, (cos, sin) in Pinocchio's ``q``, become
angles and back, and joints off the chain (fingers) keep the seed's values.
"""

from __future__ import annotations

import logging
import re
import time
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..ik import TOL
from ..robot import Robot
from ..solvers import make_solver

ROBOTS = ("ur5", "ur10", "panda", "kinova", "xarm7", "baxter")
#: end-effector frames of the bench robots that have no default (Baxter's right arm: a 7-DoF
#: sub-chain of a 19-joint robot)
EE_FRAMES = {"baxter": "right_hand_link"}
POSITION_TOL, ROTATION_TOL = 1e-5, 1e-4  # m, rad: what counts as solved
LIMIT_SLACK = 1e-9  # rad or m past a limit still counted as within it
TRACIK_TIMEOUT, TRACIK_EPS = 5e-3, 1e-5  # s; m and rad, per component of the pose error
#: rtb's ik_LM: iterations per search, searches, and its tolerance on E = |e|^2 / 2 (m^2, rad^2),
#: set so that |e| < sjt-pin's own tol
RTB_ILIMIT, RTB_SLIMIT, RTB_TOL = 30, 100, 0.5 * TOL**2
BLOCK = 50  # poses one runner solves before the next takes its turn
PIP_NAMES = {"pytracik": "pytracik", "roboticstoolbox": "roboticstoolbox-python"}


class Answer(NamedTuple):
    """A runner's result: the configuration (nq,), or None when the solver gave up; the
    iterations (over all starts) and restarts, for the solvers that count them."""

    q: np.ndarray | None
    iterations: int | None = None
    restarts: int | None = None


Runner = Callable[[pin.SE3, np.ndarray], Answer]


@dataclass
class IKRow:
    """One runner on one robot; times in ms per pose, over all poses (failures included)."""

    robot: str
    method: str
    poses: int
    success: float  # fraction of the poses solved (see ``solved``)
    median_ms: float
    p90_ms: float
    p99_ms: float
    iterations_median: float | None = None  # over all starts; None: not counted
    iterations_p90: float | None = None
    restarts_mean: float | None = None


# -- problems and the check ------------------------------------------------------------------------
def problems(robot: Robot, count: int, seed: int = 0) -> list[tuple[pin.SE3, np.ndarray]]:
    """``count`` (target pose, seed configuration) pairs, both from random q within limits."""
    rng = np.random.default_rng(seed)
    return [(robot.fk(robot.random_configuration(rng)), robot.random_configuration(rng))
            for _ in range(count)]


def solved(robot: Robot, q: np.ndarray | None, target: pin.SE3) -> bool:
    """Position error < 1e-5 m, rotation error < 1e-4 rad, every joint within its limits
    (continuous joints have none: their limits are infinite) and unit (cos, sin) pairs."""
    if q is None or not np.all(np.isfinite(q)) or not pin.isNormalized(robot.model, q, 1e-9):
        return False
    pose = robot.fk(q)
    position = np.linalg.norm(pose.translation - target.translation)
    rotation = np.linalg.norm(pin.log3(pose.rotation.T @ target.rotation))
    inside = (np.all(q >= robot.lower_limits - LIMIT_SLACK)
              and np.all(q <= robot.upper_limits + LIMIT_SLACK))
    return bool(position < POSITION_TOL and rotation < ROTATION_TOL and inside)


# -- the peers' coordinates ------------------------------------------------------------------------
class Chain:
    """The joints from the root to the end-effector frame's joint, base to tip: Pinocchio's
    ``q`` to joint values (rad or m; an angle for a continuous joint) and back."""

    def __init__(self, robot: Robot):
        model = robot.model
        ids = model.supports[model.frames[robot.ee_frame_id].parentJoint][1:]  # no universe
        joints = [model.joints[j] for j in ids]
        self.index = np.array([j.idx_q for j in joints])  # a joint's value, or its cos
        self.circle = np.array([j.nq == 2 for j in joints])  # continuous: (cos, sin)
        self.lower = robot.lower_limits[self.index]  # rad or m; -inf for continuous joints
        self.upper = robot.upper_limits[self.index]

    def __len__(self) -> int:
        return len(self.index)

    def values(self, q: np.ndarray) -> np.ndarray:
        """The chain's joint values from ``q`` (nq,): atan2(sin, cos) for continuous joints."""
        out = q[self.index]
        cos = self.index[self.circle]
        out[self.circle] = np.arctan2(q[cos + 1], q[cos])
        return out

    def configuration(self, values: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """``seed`` (nq,) with the chain's joints set to ``values``."""
        q = seed.copy()
        q[self.index[~self.circle]] = values[~self.circle]
        cos = self.index[self.circle]
        q[cos], q[cos + 1] = np.cos(values[self.circle]), np.sin(values[self.circle])
        return q


def chain_links(robot: Robot) -> tuple[str, str]:
    """(base, tip): the root link of the robot's URDF file and the link that carries the
    end-effector frame."""
    frames = robot.model.frames
    frame = frames[robot.ee_frame_id]
    while frame.type != pin.FrameType.BODY:
        frame = frames[frame.parentFrame]
    urdf = ET.parse(robot.urdf).getroot()
    children = {joint.find("child").get("link") for joint in urdf.findall("joint")}
    roots = [link.get("name") for link in urdf.findall("link") if link.get("name") not in children]
    return roots[0], frame.name


# -- runners ---------------------------------------------------------------------------------------
def _sjt_pin(robot: Robot, method: str, **options) -> Runner:
    """``make_solver(method, robot).solve(target, seed, **options)``."""
    solver = make_solver(method, robot)
    solver.search().restart_table()  # built once, on first use: set-up, not timed

    def run(target, seed):
        result = solver.solve(target, seed, **options)
        return Answer(result.q, result.iterations, result.restarts)

    return run


def _with_bare_root(urdf: str, root: str) -> tuple[str, str]:
    """The URDF text with a link without inertia above ``root``, and that link's name: KDL
    drops a root link that has an inertia (Panda's, Kinova's)."""
    start = urdf.index(">", urdf.index("<robot")) + 1
    bare = "bench_root"
    link = (f'<link name="{bare}"/><joint name="{bare}_joint" type="fixed">'
            f'<parent link="{bare}"/><child link="{root}"/></joint>')
    return urdf[:start] + link + urdf[start:], bare


def tracik_solver(robot: Robot, chain: Chain):
    """A ``pytracik.TRAC_IK`` on the chain, with Pinocchio's limits (its parser reads Panda's
    as 0 and rounds Kinova's to 1e-3) except on continuous joints, which keep its own."""
    import pytracik

    root, tip = chain_links(robot)
    urdf, base = _with_bare_root(Path(robot.urdf).read_text(), root)
    solver = pytracik.TRAC_IK(base, tip, urdf, TRACIK_TIMEOUT, TRACIK_EPS,
                              pytracik.SolveType.Speed)
    own_lower = np.asarray(pytracik.get_joint_lower_bounds(solver))  # +-FLT_MAX: continuous
    own_upper = np.asarray(pytracik.get_joint_upper_bounds(solver))
    pytracik.set_joint_limits(solver, np.where(np.isfinite(chain.lower), chain.lower, own_lower),
                              np.where(np.isfinite(chain.upper), chain.upper, own_upper))
    return solver


def _tracik(robot: Robot) -> Runner:
    """TRAC-IK from the seed's joint values to the target (x, y, z, qx, qy, qz, qw)."""
    import pytracik

    chain = Chain(robot)
    solver = tracik_solver(robot, chain)

    def run(target, seed):
        result = pytracik.ik(solver, chain.values(seed), *pin.SE3ToXYZQUAT(target))
        if result[0] < 0:  # status (< 0: no solution in time), then the joint values
            return Answer(None)
        return Answer(chain.configuration(result[1:], seed))

    return run


def _rtb(robot: Robot) -> Runner:
    """robotics-toolbox's C++ ``ik_LM`` on the chain of the same URDF file, joint limits on
    (it reads the same finite limits, and +-2 pi for continuous joints)."""
    import roboticstoolbox as rtb
    from roboticstoolbox.models.URDF.URDFRobot import URDF_read

    path = Path(robot.urdf).resolve()
    links, name, _ = URDF_read(path, patch=lambda text: _local_packages(text, path))
    root, tip = chain_links(robot)
    ets = rtb.Robot(links, name=name).ets(start=root, end=tip)
    # the chain's joints keep the whole robot's numbering (Baxter's right arm: 1..7 after the
    # head); ik_LM indexes its q by it, so number them 0..n-1 as the chain's own
    joints = [et for et in ets if et.isjoint]
    for k, et in enumerate(joints):
        et.jindex = k
    ets = rtb.ETS(list(ets))
    chain = Chain(robot)

    def run(target, seed):
        found = ets.ik_LM(target.homogeneous, q0=chain.values(seed), ilimit=RTB_ILIMIT,
                          slimit=RTB_SLIMIT, tol=RTB_TOL, joint_limits=True)
        q = chain.configuration(found.q, seed) if found.success else None
        return Answer(q, int(found.iterations), int(found.searches) - 1)

    return run


def _local_packages(urdf: str, path: Path) -> str:
    """``urdf`` with each ``package://NAME/`` replaced by the folder called NAME above
    ``path``: xacro, which rtb's loader runs, cannot find example-robot-data's package."""
    def folder(match: re.Match) -> str:
        found = [parent for parent in path.parents if parent.name == match[1]]
        return f"{found[0]}/" if found else match[0]

    return re.sub(r"package://([^/]+)/", folder, urdf)


def peers_available() -> dict[str, bool]:
    """Which peers import: ``{"pytracik": ..., "roboticstoolbox": ...}``."""
    out = {}
    for module in PIP_NAMES:
        try:
            __import__(module)
            out[module] = True
        except ImportError:
            out[module] = False
    return out


def _runners(robot: Robot, peers: bool) -> dict[str, Runner]:
    """The runners for ``robot`` by label: sjt-pin's, then the peers that import."""
    runners = {
        "SJT": _sjt_pin(robot, "sjt"),
        "SJT, timeout=5 ms": _sjt_pin(robot, "sjt", timeout=TRACIK_TIMEOUT),
        "DLS": _sjt_pin(robot, "dls"),
    }
    available = peers_available() if peers else {}
    if available.get("pytracik"):
        runners["TRAC-IK"] = _tracik(robot)
    if available.get("roboticstoolbox"):
        runners["rtb ik_LM"] = _rtb(robot)
    return runners


# -- the benchmark ---------------------------------------------------------------------------------
def _timed(run: Runner, pairs) -> tuple[list[Answer], list[float]]:
    """``run`` on every (target, seed) pair: its answers and the seconds each took."""
    answers, seconds = [], []
    for target, seed in pairs:
        start = time.perf_counter()
        answers.append(run(target, seed))
        seconds.append(time.perf_counter() - start)
    return answers, seconds


def _row(robot: Robot, method: str, pairs, answers: list[Answer], seconds: list[float]) -> IKRow:
    """Success rate, time percentiles (ms) and, where counted, iterations and restarts."""
    ok = [solved(robot, a.q, target) for a, (target, _) in zip(answers, pairs, strict=True)]
    ms = 1e3 * np.array(seconds)
    row = IKRow(robot.name, method, len(pairs), float(np.mean(ok)), float(np.median(ms)),
                float(np.percentile(ms, 90)), float(np.percentile(ms, 99)))
    if answers[0].iterations is not None:
        iterations = [a.iterations for a in answers]
        row.iterations_median = float(np.median(iterations))
        row.iterations_p90 = float(np.percentile(iterations, 90))
        row.restarts_mean = float(np.mean([a.restarts for a in answers]))
    return row


def _robot_rows(name: str, poses: int, peers: bool) -> list[IKRow]:
    """Every runner on ``poses`` seeded problems of robot ``name``. The runners take turns on
    blocks of ``BLOCK`` poses: a change in the machine's load reaches all of them alike, and
    one runner's threads and caches seldom slow another's timing."""
    robot = Robot.from_example(name, ee_frame=EE_FRAMES.get(name))
    pairs = problems(robot, poses)
    runners = _runners(robot, peers)
    for run in runners.values():  # warm-up (compiles sjt-pin's kernels): not timed
        run(*pairs[0])
    answers = {label: [] for label in runners}
    seconds = {label: [] for label in runners}
    for start in range(0, poses, BLOCK):
        for label, run in runners.items():
            block_answers, block_seconds = _timed(run, pairs[start:start + BLOCK])
            answers[label] += block_answers
            seconds[label] += block_seconds
    return [_row(robot, label, pairs, answers[label], seconds[label]) for label in runners]


def ik_benchmark(robots=ROBOTS, poses: int = 1000, peers: bool = True,
                 progress: Callable[[IKRow], object] | None = None) -> list[IKRow]:
    """Success rate, solve times (ms), iterations and restarts per robot and runner on
    ``poses`` poses per robot; ``peers=False`` runs sjt-pin only, and a peer that does not
    import is skipped with a warning. ``progress`` gets each row when its robot is done."""
    for module, available in (peers_available() if peers else {}).items():
        if not available:
            warnings.warn(f"{module} does not import: its runner is skipped (pip install "
                          f"{PIP_NAMES[module]})", stacklevel=2)
    rows = []
    for name in robots:
        for row in _robot_rows(name, poses, peers):
            rows.append(row)
            if progress:
                progress(row)
    return rows


def ik_table(rows: list[IKRow]) -> str:
    """The rows as a markdown table (times in ms; iterations over all starts)."""
    lines = ["| robot | method | poses | success | median [ms] | p90 [ms] | p99 [ms] | "
             "iterations median / p90 | restarts (mean) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        counted = r.iterations_median is not None
        iterations = f"{r.iterations_median:.0f} / {r.iterations_p90:.0f}" if counted else "–"
        restarts = f"{r.restarts_mean:.2f}" if counted else "–"
        lines.append(f"| {r.robot} | {r.method} | {r.poses} | {100 * r.success:.1f} % | "
                     f"{r.median_ms:.3f} | {r.p90_ms:.3f} | {r.p99_ms:.3f} | {iterations} | "
                     f"{restarts} |")
    return "\n".join(lines)


@dataclass
class ManyRow:
    """``solve_many`` throughput on one robot, in one run: poses per second in 1 process, in
    its pool of ``processes`` processes, and on a Dask ``LocalCluster`` of ``processes`` worker
    processes of one thread each (None: distributed does not import); ``identical``: the three
    gave the same q for every pose (default arguments)."""

    robot: str
    poses: int
    processes: int
    single: float  # poses/s
    parallel: float  # poses/s, the pool
    dask: float | None = None  # poses/s, the LocalCluster
    identical: bool = True

    @property
    def speedup(self) -> float:
        return self.parallel / self.single

    @property
    def dask_ratio(self) -> float | None:
        """Dask's throughput over the pool's."""
        return None if self.dask is None else self.dask / self.parallel


def many_throughput(name: str = "ur5", poses: int = 20_000, processes: int = 2,
                    dask: bool = True) -> ManyRow:
    """Wall-clock throughput of :func:`~sjt_pin.solve_many` with its defaults: in this
    process, in its pool (the pool's start included) and, with ``dask`` and when distributed
    imports, on a ``LocalCluster`` started beforehand (the call includes sending the solver to
    the workers)."""
    from ..batch import solve_many

    robot = Robot.from_example(name)
    pairs = problems(robot, poses, seed=1)
    targets, seeds = [t for t, _ in pairs], np.array([s for _, s in pairs])
    solver = make_solver("sjt", robot)

    def timed(**where):
        start = time.perf_counter()
        results = solve_many(solver, targets, seeds, progress=False, **where)
        return poses / (time.perf_counter() - start), np.array([r.q for r in results])

    single, reference = timed(processes=1)
    parallel, pooled = timed(processes=processes)
    identical = bool(np.array_equal(pooled, reference))
    row = ManyRow(robot.name, poses, processes, single, parallel, identical=identical)
    if dask:
        try:
            import distributed
        except ImportError:
            warnings.warn("distributed does not import: no Dask throughput (pip install "
                          "'dask[distributed]')", stacklevel=2)
            return row
        with distributed.LocalCluster(n_workers=processes, threads_per_worker=1,
                                      processes=True, dashboard_address=None,
                                      silence_logs=logging.CRITICAL) as cluster, \
                distributed.Client(cluster) as client:
            row.dask, on_dask = timed(executor=client.get_executor())
        row.identical = identical and bool(np.array_equal(on_dask, reference))
    return row


def many_line(row: ManyRow) -> str:
    """The throughput line of ``sjt-pin bench ik``."""
    line = (f"solve_many on {row.robot}, {row.poses} poses: {row.single:.0f} poses/s in 1 "
            f"process, {row.parallel:.0f} in the pool of {row.processes} ({row.speedup:.2f}x)")
    if row.dask is not None:
        line += (f", {row.dask:.0f} on Dask (LocalCluster, {row.processes} worker processes: "
                 f"{row.dask_ratio:.2f}x the pool)")
    return line + f"; identical q everywhere: {'yes' if row.identical else 'NO'}"
