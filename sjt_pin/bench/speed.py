"""``sjt-pin bench speed``: one ``step()`` on every documented path, against its Pinocchio floor.

Times are ratios inside one run, because the machines are shared and noisy: for each path the
median (p90, p99, max) time of one ``step()`` against the same statistics of *the Pinocchio calls
that path makes* (its floor), timed the same way on the same configurations and targets: joint
Jacobians with forward kinematics, per task frame its placement, its frame Jacobian and (pose
tasks) ``actInv`` + ``log6``, ``difference`` for a posture task, and ``integrate``. The target
moves on a 1 cm circle (one turn per second) so that no step is trivial. ``track()`` is timed
per step over a whole run, against the floor of the step it makes timed the same way (whole
runs of its calls, each right after a run of ``track()``). With ``--peers``, pink's
``solve_ik`` + integration on the same robot, frame and targets.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import pinocchio as pin

from ..limits import Limit
from ..methods import Method
from ..robot import Robot
from ..solver import Solver
from ..solvers import make_solver
from ..tasks import PoseTask, PositionTask, PostureTask
from ..tracking import track
from ..trajectories import Circle

ROBOTS = ("ur5", "panda", "kinova")
#: a pose with acceleration (and jerk) limits: the constraint stage's compiled smoothing
ACCELERATION_PATHS = (("SJT pose, acceleration limits", {"acceleration_limits": 10.0}),
                      ("SJT pose, acceleration and jerk limits",
                       {"acceleration_limits": 10.0, "jerk_limits": 5000.0}))
#: a user's general-row limit beside acceleration and jerk limits: a floor under the end
#: effector (:class:`Floor`, the one of docs/extending.md), 1 m below its start (never acts) or
#: 1 mm above it (acts on every step: the task pulls the frame down onto it, the row holds it up)
USER_LIMIT_PATHS = (("SJT pose, acceleration + jerk limits + a user limit (inactive)", -1.0),
                    ("SJT pose, acceleration + jerk limits + a user limit (active)", 1e-3))
#: serial chains (random axes, seeded) timed with a pose task plus a posture task
CHAIN_JOINTS = (30, 100, 200)
#: Start configurations inside the limits and away from singularities.
STARTS = {"ur5": np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])}


@dataclass
class Timing:
    """Median, 90th and 99th percentiles and the largest of one operation's times, in
    microseconds (a control loop's deadline is met by the largest, not by the median)."""

    median: float
    p90: float
    p99: float
    max: float = float("nan")

    @classmethod
    def of(cls, samples_ns: np.ndarray) -> Timing:
        p50, p90, p99, most = np.percentile(samples_ns, [50, 90, 99, 100]) / 1e3
        return cls(float(p50), float(p90), float(p99), float(most))

    @property
    def jitter(self) -> float:
        """p90 / median."""
        return self.p90 / self.median


@dataclass
class SpeedRow:
    robot: str
    path: str
    step: Timing
    floor: Timing

    @property
    def ratio(self) -> float:
        return self.step.median / self.floor.median


@dataclass
class SpeedReport:
    rows: list[SpeedRow] = field(default_factory=list)
    machine: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"machine": self.machine,
                "rows": [asdict(r) | {"ratio": r.ratio, "jitter": r.step.jitter}
                         for r in self.rows]}


def machine() -> dict:
    """Versions and machine, for the record."""
    info = {"python": platform.python_version(), "pinocchio": pin.__version__,
            "numpy": np.__version__, "machine": platform.machine(),
            "system": platform.platform()}
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
        info["cpu"] = names[0] if names else ""
    except OSError:
        info["cpu"] = platform.processor()
    return info


def _time(function, args_list, warmup: int) -> np.ndarray:
    """Per-call times (ns) of ``function(*args)`` over ``args_list`` after ``warmup`` calls."""
    return _time_pair(function, args_list, None, None, warmup)[0]


def _time_pair(first, first_args, second, second_args, warmup: int):
    """Per-call times (ns) of two functions called alternately on their argument lists, so
    that both see the same state of a shared, noisy machine."""
    clock = time.perf_counter_ns
    for k in range(warmup):
        first(*first_args[k])
        if second is not None:
            second(*second_args[k])
    count = len(first_args) - warmup
    a, b = np.empty(count), np.empty(count)
    for k in range(count):
        args = first_args[warmup + k]
        start = clock()
        first(*args)
        middle = clock()
        if second is not None:
            second(*second_args[warmup + k])
            b[k] = clock() - middle
        a[k] = middle - start
    return a, b


@dataclass
class Path:
    """One way of calling ``step``: the solver's options, its frames and what it is given."""

    name: str
    method: str | Method = "sjt"  # a built-in's name, or a method of one's own
    options: dict = field(default_factory=dict)
    frames: tuple[str, ...] = ()  # several pose tasks on these frames (default: the end effector)
    position: bool = False  # a PositionTask on the end effector
    posture: bool = False
    feedforward: bool = False


class OwnTranspose(Method):
    """A method of one's own as docs/extending.md writes one, J^T as its matrix: the step is
    computed from the matrix (against the built-in "JT pose" row)."""

    name = "own J^T"

    def matrix(self, J):
        return J.T


class OwnPseudoinverse(Method):
    """docs/extending.md's own method, numpy's pseudoinverse (its SVD is most of the step)."""

    name = "own pinv"

    def matrix(self, J):
        return np.linalg.pinv(J, rcond=1e-6)


PATHS = [
    Path("SJT pose"),
    Path("SJT pose + target_velocity", feedforward=True),
    Path("SJT position", position=True),
    Path("SJT position + target_velocity", position=True, feedforward=True),
    Path("SJT pose + posture", posture=True),
    Path("SJT pose + posture + target_velocity", posture=True, feedforward=True),
    Path("SJT transpose feedback + target_velocity", options={"feedback": "transpose"},
         feedforward=True),
    Path("SJT paper eq. 21 + target_velocity",
         options={"feedback": "transpose", "feedforward": "transpose"}, feedforward=True),
    Path("JT pose", "jt"),
    Path("JT pose + target_velocity", "jt", feedforward=True),
    Path("JP pose + target_velocity", "jp", feedforward=True),
    Path("DLS pose + target_velocity", "dls", feedforward=True),
    Path("own method (M = J^T) pose", OwnTranspose()),
    Path("own method (M = numpy pinv) pose + target_velocity", OwnPseudoinverse(),
         feedforward=True),
]
#: Two frames per robot (the end effector and a link up the arm), and Talos' two hands.
TWO_FRAMES = {"ur5": ("tool0", "forearm_link"), "panda": ("panda_hand", "panda_link4"),
              "kinova": ("j2s6s200_end_effector", "j2s6s200_link_3"),
              "talos": ("gripper_left_joint", "gripper_right_joint")}


def _circle(robot: Robot, q: np.ndarray, frame: str, duration: float,
            radius: float = 0.01) -> Circle:
    """A ``radius`` circle through the frame's position at ``q``, one turn per second."""
    pose = robot.fk(q, frame)
    return Circle(pose.translation - [radius, 0.0, 0.0], radius, duration=duration,
                  rotation=pose.rotation, turns=duration)


class Floor(Limit):
    """A frame's origin stays above ``z_min`` (m): ``z_dot >= -gain (z - z_min) / dt`` (one
    general row; the example of docs/extending.md)."""

    name = "floor"
    uses_motion = False

    def __init__(self, robot: Robot, frame: str, z_min: float, gain: float = 0.5):
        self.frame_id, self.z_min, self.gain = robot.frame_id(frame), z_min, gain

    def rows(self, kinematics, motion):
        z = kinematics.placement(self.frame_id).translation[2]
        J_z = kinematics.world_aligned_jacobian(self.frame_id)[2]
        return -J_z[None, :], np.array([self.gain * (z - self.z_min) / motion.dt])


def _targets(robot: Robot, q0: np.ndarray, frames: tuple[str, ...], count: int, dt: float):
    """Per step: ``{frame: (pose, velocity 6-vector)}`` on 1 cm circles."""
    times = np.arange(count) * dt
    out = [dict() for _ in range(count)]
    for frame in frames:
        circle = _circle(robot, q0, frame, count * dt)
        positions, rotations, velocities = circle.samples(times)
        for k in range(count):
            out[k][frame] = (pin.SE3(np.array(rotations[k]), positions[k]), velocities[k])
    return out


def _floor(robot: Robot, frames: tuple[str, ...], position: bool, posture: bool):
    """The Pinocchio calls of a step on ``frames``, as the step makes them."""
    model, data = robot.model, robot.model.createData()
    ids = [robot.frame_id(f) for f in frames]
    delta = np.full(model.nv, 1e-6)
    local, aligned, q_ref = pin.LOCAL, pin.LOCAL_WORLD_ALIGNED, robot.q0

    def floor(q, targets):
        pin.computeJointJacobians(model, data, q)
        for fid, frame in zip(ids, frames, strict=True):
            oMf = pin.updateFramePlacement(model, data, fid)
            if position:
                pin.getFrameJacobian(model, data, fid, aligned)
            else:
                pin.getFrameJacobian(model, data, fid, local)
                pin.log6(oMf.actInv(targets[frame][0])).vector  # noqa: B018 (a step reads it)
        if posture:
            pin.difference(model, q, q_ref)
        return pin.integrate(model, q, delta)

    return floor


def time_path(robot: Robot, q0: np.ndarray, path: Path, steps: int, warmup: int,
              dt: float = 1e-3, frames: tuple[str, ...] | None = None) -> SpeedRow:
    """Median/p90/p99 of ``step`` on ``path`` and of its floor."""
    frames = frames or path.frames or (robot.ee_frame,)
    if path.position:
        task = PositionTask()
    elif len(frames) == 1:
        task = PoseTask(frame=frames[0])
    else:
        task = {f: PoseTask() for f in frames}
    posture = PostureTask() if path.posture else None
    if isinstance(path.method, Method):
        solver = Solver(robot, path.method, dt=dt, task=task, posture=posture, **path.options)
    else:
        solver = make_solver(path.method, robot, dt=dt, task=task, posture=posture,
                             **path.options)
    targets = _targets(robot, q0, frames, steps + warmup, dt)
    single = len(frames) == 1
    calls, q = [], q0
    for tk in targets:  # the configurations the timed loop will see
        if single:
            pose, velocity = tk[frames[0]]
            args = (q, pose.translation if path.position else pose,
                    velocity if path.feedforward else None)
        else:
            args = (q, {f: tk[f][0] for f in frames},
                    {f: tk[f][1] for f in frames} if path.feedforward else None)
        calls.append(args)
        q = solver.step(*args)
    floor_calls = [(args[0], tk) for args, tk in zip(calls, targets, strict=True)]
    steps, floors = _time_pair(solver.step, calls,
                               _floor(robot, frames, path.position, path.posture), floor_calls,
                               warmup)
    return SpeedRow(robot.name, path.name, Timing.of(steps), Timing.of(floors))


def time_track(robot: Robot, q0: np.ndarray, steps: int, dt: float = 1e-3,
               repeats: int = 15) -> SpeedRow:
    """``track()`` on a 1 cm circle, per step (a whole run's time / its steps), against the
    pose floor timed the same way: its calls on the run's configurations and targets, a whole
    run at a time, right after each run (medians of ``repeats`` pairs)."""
    frames = (robot.ee_frame,)
    circle = _circle(robot, q0, robot.ee_frame, steps * dt)
    solver = make_solver("sjt", robot, dt=dt)
    log = track(solver, circle, q0)
    floor = _floor(robot, frames, False, False)
    floor_calls = list(zip(log.q, _targets(robot, q0, frames, len(log), dt), strict=True))
    clock, runs, floors = time.perf_counter_ns, [], []
    for _ in range(repeats):
        start = clock()
        track(solver, circle, q0)
        middle = clock()
        for args in floor_calls:
            floor(*args)
        runs.append((middle - start) / len(log))
        floors.append((clock() - middle) / len(log))
    return SpeedRow(robot.name, "track() per step (SJT, circle)", Timing.of(np.array(runs)),
                    Timing.of(np.array(floors)))


def time_pink(robot: Robot, q0: np.ndarray, steps: int, warmup: int,
              dt: float = 1e-3) -> SpeedRow:
    """pink's ``solve_ik`` + ``integrate`` on the same frame and targets (one FrameTask, a
    small PostureTask, pink's default limits, its fastest available QP solver)."""
    import pink
    import qpsolvers
    from pink.tasks import FrameTask
    from pink.tasks import PostureTask as PinkPosture

    qp = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    frame = robot.ee_frame
    configuration = pink.Configuration(robot.model, robot.model.createData(), q0)
    task = FrameTask(frame, position_cost=1.0, orientation_cost=1.0)
    posture = PinkPosture(cost=1e-3)
    posture.set_target(robot.q0)
    targets = _targets(robot, q0, (frame,), steps + warmup, dt)

    def pink_step(q, target):
        configuration.update(q)
        task.set_target(target)
        velocity = pink.solve_ik(configuration, [task, posture], dt, solver=qp)
        return configuration.integrate(velocity, dt)

    calls, q = [], q0
    for tk in targets:
        calls.append((q, tk[frame][0]))
        q = pink_step(q, tk[frame][0])
    steps, floors = _time_pair(pink_step, calls, _floor(robot, (frame,), False, False),
                               [(c[0], tk) for c, tk in zip(calls, targets, strict=True)], warmup)
    return SpeedRow(robot.name, "pink solve_ik + integrate", Timing.of(steps), Timing.of(floors))


def start_configuration(robot: Robot) -> np.ndarray:
    return STARTS.get(robot.name, robot.q0).copy()


def speed(robots=ROBOTS, steps: int = 5000, warmup: int = 500, peers: bool = False,
          talos: bool = True, progress=None) -> SpeedReport:
    """Every path of :data:`PATHS`, two frames, ``track()`` (and pink) per robot; Talos' two
    hands."""
    report = SpeedReport(machine=machine())

    def add(row):
        report.rows.append(row)
        if progress:
            progress(row)

    for name in robots:
        robot = Robot.from_example(name)
        q0 = start_configuration(robot)
        for path in PATHS:
            add(time_path(robot, q0, path, steps, warmup))
        for label, options, ff in [("SJT two frames", {}, False),
                                   ("SJT two frames + target_velocity", {}, True)]:
            add(time_path(robot, q0, Path(label, options=options, feedforward=ff), steps,
                          warmup, frames=TWO_FRAMES[name]))
        add(time_track(robot, q0, steps))
        for label, options in ACCELERATION_PATHS:
            add(time_path(robot, q0, Path(label, options=options), steps, warmup))
        z0 = robot.fk(q0).translation[2]
        for label, offset in USER_LIMIT_PATHS:
            options = dict(ACCELERATION_PATHS[-1][1],
                           limits=[Floor(robot, robot.ee_frame, z0 + offset)])
            add(time_path(robot, q0, Path(label, options=options), steps, warmup))
        if peers:
            add(time_pink(robot, q0, steps, warmup))
    for joints in CHAIN_JOINTS:
        robot = chain(joints)
        add(time_path(robot, robot.q0.copy(), Path(f"SJT pose + posture, {joints} joints",
                                                   posture=True), steps // 2, warmup // 2))
    if talos:
        robot = Robot.from_example("talos")
        for label, ff in [("SJT two hands", False), ("SJT two hands + target_velocity", True)]:
            add(time_path(robot, robot.q0.copy(), Path(label, feedforward=ff), steps // 2,
                          warmup // 2, frames=TWO_FRAMES["talos"]))
    return report


def chain(joints: int) -> Robot:
    """A serial chain of ``joints`` revolute joints with random axes (seeded), 0.05-0.6 m links
    (the generator of ``robots/planar3.py``)."""
    from ..robots.planar3 import serial_chain, to_xml

    rng = np.random.default_rng(joints)
    xml = to_xml(serial_chain(list(rng.uniform(0.05, 0.6, joints)),
                              axes=rng.normal(size=(joints, 3)), gripper=0.1))
    robot = Robot.from_urdf(xml, ee_frame="ee", load_visuals=False)
    robot.name = f"chain{joints}"
    return robot


#: what a fresh process measures: import, first step, first track (JT), first solve (DLS)
COLD_SCRIPT = """
import time
t0 = time.perf_counter()
import numpy as np
import sjt_pin as sjt
t1 = time.perf_counter()
robot = sjt.Robot.from_example({robot!r})
t2 = time.perf_counter()
q = robot.q0.copy()
q = sjt.SJTSolver(robot).step(q, robot.fk(q))
t3 = time.perf_counter()
start = robot.fk(q)
circle = sjt.Circle(start.translation - [0.05, 0, 0], 0.05, duration=0.2,
                    rotation=start.rotation)
sjt.track(sjt.JTSolver(robot), circle, q)
t4 = time.perf_counter()
sjt.DLSSolver(robot).solve(robot.fk(robot.random_configuration(np.random.default_rng(0))), q)
t5 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)
"""

PINK_COLD_SCRIPT = """
import time
t0 = time.perf_counter()
import pink
from pink.tasks import FrameTask
t1 = time.perf_counter()
import example_robot_data as erd
robot = erd.load({robot!r})
t2 = time.perf_counter()
configuration = pink.Configuration(robot.model, robot.data, robot.q0)
task = FrameTask({frame!r}, position_cost=1.0, orientation_cost=1.0)
task.set_target(configuration.get_transform_frame_to_world({frame!r}))
import qpsolvers
solver = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
pink.solve_ik(configuration, [task], 1e-3, solver=solver)
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def cold_start(robot: str = "ur5", peers: bool = False) -> dict[str, float]:
    """Seconds, in a fresh Python process: ``import sjt_pin``, loading ``robot``, the first
    ``step``, the first ``track`` (JT) and the first ``solve`` (DLS); with ``peers``, pink's
    import and first ``solve_ik`` on the same robot."""
    import subprocess
    import sys

    from ..robot import DEFAULT_EE_FRAMES

    def run(script):
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=600, check=True)
        return [float(x) for x in done.stdout.split()]

    names = ("import", "load robot", "first step", "first track", "first solve")
    out = dict(zip(names, run(COLD_SCRIPT.format(robot=robot)), strict=True))
    if peers:
        try:
            pink = run(PINK_COLD_SCRIPT.format(robot=robot, frame=DEFAULT_EE_FRAMES[robot]))
        except (subprocess.CalledProcessError, KeyError):
            return out
        out.update({"pink import": pink[0], "pink first solve_ik": pink[2]})
    return out


def speed_table(report: SpeedReport) -> str:
    """Markdown table of a speed report."""
    lines = ["| robot | path | median [us] | p90 [us] | p99 [us] | max [us] | floor [us] | "
             "step / floor | p90 / median |", "|---|---|---|---|---|---|---|---|---|"]
    for r in report.rows:
        lines.append(f"| {r.robot} | {r.path} | {r.step.median:.2f} | {r.step.p90:.2f} | "
                     f"{r.step.p99:.2f} | {r.step.max:.2f} | {r.floor.median:.2f} | "
                     f"{r.ratio:.2f} | {r.step.jitter:.2f} |")
    return "\n".join(lines)


def peer_ratios(report: SpeedReport) -> dict[str, float]:
    """pink's step time over SJT's with a target velocity, per robot."""
    out = {}
    for robot in {r.robot for r in report.rows}:
        rows = {r.path: r for r in report.rows if r.robot == robot}
        pink_row = rows.get("pink solve_ik + integrate")
        sjt_row = rows.get("SJT pose + target_velocity")
        if pink_row and sjt_row:
            out[robot] = pink_row.step.median / sjt_row.step.median
    return out
