"""Step-speed benchmarks (DESIGN.md section 6): one ``step()`` against the Pinocchio floor.

Times are ratios inside one run, because the machines are shared and noisy: the median time of
one ``step()`` against the median time of the Pinocchio calls a step cannot avoid, made the same
way (joint Jacobians with forward kinematics, the frame placement, the frame Jacobian, the pose
error's ``actInv`` and ``log6``, ``integrate``), on the same robot, with the target moving on a
1 cm circle so that no step is trivial; and, with ``--peers``, against pink's ``solve_ik`` and
integration on the same robot, frame and targets.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import pinocchio as pin

from ..solvers import make_solver
from ..robot import Robot
from ..paper.scenarios import PLANAR3_START, UR5_START, load_robot
from ..tasks import PoseTask

METHODS = ("sjt", "jt", "jp", "dls")
SPEED_ROBOTS = ("planar3", "ur5", "panda")


@dataclass
class Timing:
    """Median and 90th percentile of one operation, in microseconds."""

    median: float
    p90: float

    @classmethod
    def of(cls, samples_ns: np.ndarray) -> Timing:
        return cls(float(np.median(samples_ns)) / 1e3, float(np.percentile(samples_ns, 90)) / 1e3)


@dataclass
class SpeedRow:
    robot: str
    nv: int
    method: str
    step: Timing
    primitives: Timing
    peer: str = ""

    @property
    def ratio(self) -> float:
        return self.step.median / self.primitives.median


@dataclass
class SpeedReport:
    rows: list[SpeedRow] = field(default_factory=list)
    machine: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"machine": self.machine,
                "rows": [asdict(r) | {"ratio": r.ratio} for r in self.rows]}


def machine() -> dict:
    """Versions and machine, for the record."""
    import numpy

    info = {"python": platform.python_version(), "pinocchio": pin.__version__,
            "numpy": numpy.__version__, "machine": platform.machine(),
            "processor": platform.processor() or "", "system": platform.platform()}
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
        info["cpu"] = names[0] if names else ""
    except OSError:
        pass
    return info


def _targets(robot: Robot, q: np.ndarray, frame_id: int, steps: int, dt: float,
             radius: float = 0.01) -> list[pin.SE3]:
    """Poses of the frame's start moving on a ``radius`` circle, one turn per second."""
    pose = robot.fk(q, robot.model.frames[frame_id].name)
    angles = 2.0 * np.pi * np.arange(steps) * dt
    return [pin.SE3(pose.rotation, pose.translation + radius * np.array([np.cos(a) - 1.0,
                                                                          np.sin(a), 0.0]))
            for a in angles]


def _time(function, args_list, warmup: int) -> np.ndarray:
    """Per-call times (ns) of ``function(*args)`` over ``args_list`` after ``warmup`` calls."""
    clock = time.perf_counter_ns
    for args in args_list[:warmup]:
        function(*args)
    samples = np.empty(len(args_list) - warmup)
    for k, args in enumerate(args_list[warmup:]):
        start = clock()
        function(*args)
        samples[k] = clock() - start
    return samples


def _start(robot: Robot) -> np.ndarray:
    """A configuration inside the limits and away from singularities for the benchmark."""
    if robot.name == "ur5":
        return UR5_START.copy()
    if robot.name == "planar3":
        return PLANAR3_START.copy()
    return robot.q0.copy()


def primitives_timing(robot: Robot, frame_id: int, qs: list, targets: list,
                      warmup: int) -> Timing:
    """The Pinocchio calls of one pose-task step, made as ``step()`` makes them."""
    model, data = robot.model, robot.model.createData()
    step = np.full(model.nv, 1e-6)
    local = pin.LOCAL

    def floor(q, oMd):
        pin.computeJointJacobians(model, data, q)
        oMf = pin.updateFramePlacement(model, data, frame_id)
        pin.getFrameJacobian(model, data, frame_id, local)
        return pin.log6(oMf.actInv(oMd)).vector, pin.integrate(model, q, step)

    return Timing.of(_time(floor, list(zip(qs, targets, strict=True)), warmup))


def step_timing(solver, q0: np.ndarray, targets: list, warmup: int) -> tuple[Timing, list]:
    """Times of ``solver.step`` along the moving target; returns the configurations visited."""
    qs, q = [], q0
    for target in targets:  # the path the timed loop will follow, so both see the same q
        qs.append(q)
        q = solver.step(q, target)
    samples = _time(solver.step, list(zip(qs, targets, strict=True)), warmup)
    return Timing.of(samples), qs


def pink_timing(robot: Robot, frame: str, qs: list, targets: list, dt: float,
                warmup: int) -> Timing:
    """pink's ``solve_ik`` + ``integrate`` on the same frame and targets (one FrameTask, a
    small PostureTask, pink's default limits, its fastest available QP solver)."""
    import pink
    import qpsolvers
    from pink.tasks import FrameTask, PostureTask

    solver = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    model = robot.model
    configuration = pink.Configuration(model, model.createData(), qs[0])
    task = FrameTask(frame, position_cost=1.0, orientation_cost=1.0)
    posture = PostureTask(cost=1e-3)
    posture.set_target(robot.q0)
    tasks = [task, posture]

    def pink_step(q, target):
        configuration.update(q)
        task.set_target(target)
        velocity = pink.solve_ik(configuration, tasks, dt, solver=solver)
        return configuration.integrate(velocity, dt)

    return Timing.of(_time(pink_step, list(zip(qs, targets, strict=True)), warmup))


def speed(robots=SPEED_ROBOTS, methods=METHODS, steps: int = 5000, warmup: int = 500,
          dt: float = 1e-3, peers: bool = False, progress=None) -> SpeedReport:
    """Median/p90 of one step per method and robot, beside the Pinocchio floor (and pink)."""
    report = SpeedReport(machine=machine())
    for name in robots:
        robot = load_robot(name)
        q0 = _start(robot)
        targets = _targets(robot, q0, robot.ee_frame_id, steps + warmup, dt)
        variants = [(m, {}) for m in methods]
        if "sjt" in methods:  # the paper's method as it stands, without the limits' checks
            variants.insert(1, ("sjt", {"position_limits": False, "velocity_limits": False}))
        floor = None
        for method, options in variants:
            solver = make_solver(method, robot, dt=dt, task=PoseTask(), **options)
            timing, qs = step_timing(solver, q0, targets, warmup)
            if floor is None:
                floor = primitives_timing(robot, robot.ee_frame_id, qs, targets, warmup)
            label = method + (" (no limits)" if options else "")
            report.rows.append(SpeedRow(name, robot.nv, label, timing, floor))
            if progress:
                progress(report.rows[-1])
        if peers:
            timing = pink_timing(robot, robot.ee_frame, qs, targets, dt, warmup)
            report.rows.append(SpeedRow(name, robot.nv, "pink", timing, floor, peer="pink"))
            if progress:
                progress(report.rows[-1])
    return report


def chain_robot(joints: int) -> Robot:
    """A serial chain of ``joints`` revolute joints, 1 m long in all, axes turning z, y, x."""
    from ..robots import planar3 as generator

    axes = [[0, 0, 1], [0, 1, 0], [1, 0, 0]]
    urdf = generator.serial_chain([1.0 / joints] * joints, name=f"chain{joints}",
                                  axes=[axes[k % 3] for k in range(joints)])
    robot = Robot.from_urdf(generator.to_xml(urdf), ee_frame="ee", load_visuals=False)
    robot.name = f"chain{joints}"
    robot.q0 = np.full(joints, 0.1)
    return robot


def scale(chains=(20, 50, 100), steps: int = 2000, warmup: int = 200, dt: float = 1e-3,
          progress=None) -> SpeedReport:
    """SJT step time against the number of joints: the speed robots, Talos' two hands, chains."""
    report = SpeedReport(machine=machine())
    cases: list[tuple[str, Robot, object, list]] = []
    for name in SPEED_ROBOTS:
        robot = load_robot(name)
        cases.append((name, robot, PoseTask(), None))
    talos = Robot.from_example("talos")
    hands = ["gripper_left_joint", "gripper_right_joint"]
    cases.append(("talos (2 hands)", talos, {h: PoseTask() for h in hands}, hands))
    for n in chains:
        cases.append((f"chain{n}", chain_robot(n), PoseTask(), None))
    for label, robot, task, frames in cases:
        q0 = _start(robot) if label in SPEED_ROBOTS else robot.q0.copy()
        solver = make_solver("sjt", robot, dt=dt, task=task, position_limits=False,
                             velocity_limits=False)
        if frames is None:
            targets = _targets(robot, q0, robot.ee_frame_id, steps + warmup, dt)
            floor_frame = robot.ee_frame_id
        else:
            per_frame = [_targets(robot, q0, robot.frame_id(f), steps + warmup, dt) for f in frames]
            targets = [dict(zip(frames, t, strict=True)) for t in zip(*per_frame, strict=True)]
            floor_frame = robot.frame_id(frames[0])
        timing, qs = step_timing(solver, q0, targets, warmup)
        floor_targets = targets if frames is None else [t[frames[0]] for t in targets]
        floor = primitives_timing(robot, floor_frame, qs, floor_targets, warmup)
        report.rows.append(SpeedRow(label, robot.nv, "sjt", timing, floor))
        if progress:
            progress(report.rows[-1])
    return report


def speed_table(report: SpeedReport) -> str:
    """Markdown table of a speed or scale report."""
    lines = ["| robot | nv | method | step median [us] | step p90 [us] | Pinocchio floor [us] | "
             "step / floor | us per joint |", "|---|---|---|---|---|---|---|---|"]
    for r in report.rows:
        lines.append(f"| {r.robot} | {r.nv} | {r.method} | {r.step.median:.2f} | "
                     f"{r.step.p90:.2f} | {r.primitives.median:.2f} | {r.ratio:.2f} | "
                     f"{r.step.median / r.nv:.2f} |")
    return "\n".join(lines)


def peer_ratios(report: SpeedReport) -> dict[str, float]:
    """pink's step time over SJT's (with limits) per robot."""
    out = {}
    for robot in {r.robot for r in report.rows}:
        rows = {r.method: r for r in report.rows if r.robot == robot}
        if "pink" in rows and "sjt" in rows:
            out[robot] = rows["pink"].step.median / rows["sjt"].step.median
    return out


def breakdown(name: str = "ur5", samples: int = 20000) -> list[tuple[str, float]]:
    """Where an SJT pose step spends its time: the median cost (us) of each stage, measured
    by timing the stages cumulatively (Pinocchio's calls, then the compiled SJT loop)."""
    from ..kernels import transpose_step

    robot = load_robot(name)
    model, data, fid = robot.model, robot.model.createData(), robot.ee_frame_id
    q = _start(robot)
    target = _targets(robot, q, fid, 2, 1e-3)[1]
    solver = make_solver("sjt", robot, dt=1e-3, position_limits=False, velocity_limits=False)
    numerator, off_chain = solver._chain_kdt, solver._not_chain
    local = pin.LOCAL

    def stage(level):
        pin.computeJointJacobians(model, data, q)
        oMf = pin.updateFramePlacement(model, data, fid)
        J = pin.getFrameJacobian(model, data, fid, local)
        e = pin.log6(oMf.actInv(target)).vector
        step = np.empty(robot.nv)
        if level:
            sjt_step(J, e, numerator, off_chain, step)
        else:
            step[:] = 0.0
        return pin.integrate(model, q, step)

    cumulative = [float(np.median(_time(stage, [(level,)] * samples, samples // 10))) / 1e3
                  for level in range(2)]
    limited = make_solver("sjt", robot, dt=1e-3)
    full = Timing.of(_time(solver.step, [(q, target)] * samples, samples // 10)).median
    with_limits = Timing.of(_time(limited.step, [(q, target)] * samples, samples // 10)).median
    return [
        ("Pinocchio calls (the floor)", cumulative[0]),
        ("+ compiled SJT loop: |e|^2, alpha_i = 1 / |J_i|^2, k dt D J^T e",
         cumulative[1] - cumulative[0]),
        ("+ Python around it (checks, state, StepInfo record)", full - cumulative[1]),
        ("+ joint limits test (position and speed)", with_limits - full),
    ]
