"""``sjt-pin bench accuracy``: tracking near singularities, rest at unreachable targets, and
exits from exact saddles, for every method with its default arguments and the URDF limits on.

Variants (:data:`VARIANTS`): the paper's SJT (eq. 21 with "auto"), this package's SJT (its
defaults: the damped update), SJT with the paper's transpose feedback and the damped
feed-forward, JT, DLS at this package's damping (0.05) and at the best damping of a small grid
(chosen per path on its max error), and JP. Three measurements:

- **tracking** (:func:`tracking`): max and RMS task error (m and rad, log6 norm) and the
  largest joint speed along paths that pass near or through singular configurations, and along
  plain circles and lines;
- **rest** (:func:`rest`): RMS joint speed over the last second of 5 s at a target held 0.3 m
  beyond the reach (an arm that cannot reach must come to rest), also for a redundant arm
  (Baxter's left arm, 7 joints);
- **saddle** (:func:`saddles`): steps from an exact saddle (UR5 at q = 0 asked to roll about
  the lost axis; UR5 and Bravo 7 at their wrist singularities and Baxter's redundant arm at a
  singular configuration, asked to move along the lost task direction) until the error is 1 %
  of its start, and the largest joint speed on the way relative to the URDF's;
- **units** (:func:`units`): Baxter's arm in mm and in m, the joint trajectories of the same
  runs and the ratio of their errors in the scaled unit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..solvers import make_solver
from ..tasks import PositionTask
from ..tasks.pose import characteristic_length
from ..tracking import track
from ..trajectories import Circle, Line, PoseInterpolation, Trajectory

#: name -> (method, options)
VARIANTS = {
    "SJT (paper, eq. 21)": ("sjt", {"feedback": "transpose", "feedforward": "transpose"}),
    "SJT": ("sjt", {}),
    "SJT, transpose feedback": ("sjt", {"feedback": "transpose"}),
    "JT": ("jt", {}),
    "DLS (0.05)": ("dls", {}),
    "DLS (best)": ("dls", None),  # damping from DLS_GRID, best per path
    "JP": ("jp", {}),
}
DLS_GRID = (0.005, 0.01, 0.02, 0.05, 0.1)
DTS = (1e-3, 2e-3)
UR5_START = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])


@dataclass
class TrackingPath:
    """A robot, a start configuration and a pose path starting where the end effector is."""

    name: str
    robot: Robot
    q0: np.ndarray
    trajectory: Trajectory


def paths() -> list[TrackingPath]:
    """The tracking paths: near singularities (UR5 wrist and elbow, Panda stretched), through
    UR5's wrist singularity q5 = 0, and plain 10 cm circles and 20 cm lines."""
    ur5, panda = Robot.from_example("ur5"), Robot.from_example("panda")
    out = []
    # UR5 wrist: from q5 = 0.01, a screw about the task direction the wrist nearly loses
    wrist = np.array([0.3, -1.2, 1.5, -1.8, 0.0, 0.2])
    lost = np.linalg.svd(ur5.jacobian(wrist))[0][:, -1]
    wrist[4] = 0.01
    start = ur5.fk(wrist)
    out.append(TrackingPath("UR5 wrist (q5 -> 0)", ur5, wrist, PoseInterpolation(
        start, start * pin.exp6(pin.Motion(0.3 * lost)), 3.0)))
    elbow_a = np.array([0.0, -1.2, 1.4, -1.8, -1.5, 0.0])
    elbow_b = np.array([0.0, -0.5, 0.0, -1.2, -1.5, 0.0])
    out.append(TrackingPath("UR5 elbow stretch", ur5, elbow_a,
                            PoseInterpolation(ur5.fk(elbow_a), ur5.fk(elbow_b), 3.0)))
    stretched = panda.q0.copy()
    stretched[1], stretched[3], stretched[5] = 0.0, -0.0698, 1.0
    out.append(TrackingPath("Panda stretch", panda, panda.q0.copy(),
                            PoseInterpolation(panda.fk(panda.q0), panda.fk(stretched), 3.0)))
    through = np.array([0.3, -1.2, 1.5, -1.8, 0.25, 0.2])
    beyond = through.copy()
    beyond[4] = -0.25
    out.append(TrackingPath("UR5 through q5 = 0", ur5, through,
                            PoseInterpolation(ur5.fk(through), ur5.fk(beyond), 2.0)))
    for robot, q0, normal, shift in ((ur5, UR5_START, [0, 0, 1], [0.1, 0, 0]),
                                     (panda, panda.q0, [1, 0, 0], [0, 0.1, 0])):
        pose = robot.fk(q0)
        label = "UR5" if robot is ur5 else "Panda"
        out.append(TrackingPath(f"{label} circle", robot, q0.copy(), Circle(
            pose.translation - shift, 0.1, 2.0, normal=normal, rotation=pose.rotation)))
        out.append(TrackingPath(f"{label} line", robot, q0.copy(), Line(
            pose.translation, pose.translation + [0.1, -0.15, -0.1], 1.5,
            rotation=pose.rotation, timing="min_jerk")))
    return out


def _solver(variant: str, robot: Robot, dt: float, damping: float | None = None):
    method, options = VARIANTS[variant]
    options = {"damping": damping} if options is None else options
    return make_solver(method, robot, dt=dt, **options)


@dataclass
class TrackingRow:
    path: str
    variant: str
    dt: float
    max_error: float
    rms_error: float
    max_joint_speed: float  # rad/s
    diverged: bool
    damping: float | None = None  # DLS (best): the damping chosen


def tracking(dts=DTS, variants=tuple(VARIANTS), progress=None) -> list[TrackingRow]:
    """Every variant on every path of :func:`paths` (held 0.5 s at its end)."""
    rows = []
    for path in paths():
        for dt in dts:
            for variant in variants:
                dampings = DLS_GRID if VARIANTS[variant][1] is None else (None,)
                best = None
                for damping in dampings:
                    log = track(_solver(variant, path.robot, dt, damping), path.trajectory,
                                path.q0, duration=path.trajectory.duration + 0.5)
                    row = TrackingRow(path.name, variant, dt, log.max_error, log.rms_error,
                                      log.max_joint_speed, log.diverged, damping)
                    if best is None or row.max_error < best.max_error:
                        best = row
                rows.append(best)
                if progress:
                    progress(best)
    return rows


@dataclass
class RestRow:
    robot: str
    variant: str
    dt: float
    rms_speed: float  # rad/s over the last second
    escapes: int


def rest(dts=DTS, variants=tuple(VARIANTS), seconds: float = 5.0, progress=None
         ) -> list[RestRow]:
    """A target 0.3 m beyond the reach (radially from the base), held for ``seconds``: RMS
    joint speed over the last second. UR5, Panda and Baxter's left arm (7 joints, redundant)."""
    rows = []
    for name in ("ur5", "panda", "baxter arm"):
        if name == "baxter arm":
            robot, q0 = baxter_arm()
        else:
            robot = Robot.from_example(name)
            q0 = UR5_START if name == "ur5" else robot.q0
        pose = robot.fk(q0)
        reach = _reach(robot, pose.translation)
        target = pin.SE3(pose.rotation, (reach + 0.3) * pose.translation
                         / np.linalg.norm(pose.translation))
        for dt in dts:
            for variant in variants:
                solver = _solver(variant, robot, dt, 0.05 if VARIANTS[variant][1] is None
                                 else None)
                q, speeds = q0.copy(), []
                for _ in range(int(round(seconds / dt))):
                    q = solver.step(q, target)
                    speeds.append(float(np.linalg.norm(solver.displacement)) / dt)
                last = np.array(speeds[-int(round(1.0 / dt)):])
                escapes = solver.escape.escapes if getattr(solver, "escape", None) else 0
                rows.append(RestRow(name, variant, dt, float(np.sqrt(np.mean(last**2))),
                                    escapes))
                if progress:
                    progress(rows[-1])
    return rows


def _reach(robot: Robot, direction: np.ndarray) -> float:
    """How far the end effector gets along ``direction`` (m): a solve to 5 m, distance kept."""
    goal = pin.SE3(np.eye(3), 5.0 * direction / np.linalg.norm(direction))
    solver = make_solver("sjt", robot, task=PositionTask())
    q = robot.q0.copy()
    for _ in range(4000):
        q = solver.step(q, goal.translation)
    return float(np.linalg.norm(robot.fk(q).translation))


@dataclass
class SaddleRow:
    saddle: str
    variant: str
    dt: float
    steps: int | None  # to 1 % of the start error; None: not within the budget
    peak_speed_ratio: float  # max over steps of max_j |q_dot_j| / v_max,j (URDF)
    escapes: int


def lost_direction(robot: Robot, q: np.ndarray) -> np.ndarray:
    """The pose error direction d ([m; rad], unit norm) that a pose task with the robot's
    length L cannot correct at ``q``: ``J_w^T W d = 0`` with ``J_w = W J``, ``W = diag(1, 1, 1,
    L, L, L)``, i.e. ``d`` along ``W^-1 u`` for the left singular vector ``u`` of ``J_w`` with
    the smallest singular value (at an exactly singular q, an exact saddle of the transpose
    updates)."""
    length = characteristic_length(robot, robot.ee_frame_id)
    w = np.array([1.0, 1.0, 1.0, length, length, length])
    u = np.linalg.svd(w[:, None] * robot.jacobian(q))[0][:, -1]
    d = u / w
    return d / np.linalg.norm(d)


#: Baxter's left arm at an exactly singular configuration (sigma_min 2e-17): the elbow nearly
#: straight and the wrist aligned, 0.21 rad or more from every position limit
BAXTER_SINGULAR = {"left_e0": -0.00669422744323612, "left_e1": 0.16193479126285196,
                   "left_w1": -0.00196592454542699}


def saddle_problems(angle: float = 0.1) -> list[tuple[str, Robot, np.ndarray, pin.SE3]]:
    """Exact saddles, each ``angle`` along :func:`lost_direction`: UR5 at q = 0 asked to roll
    about the lost axis, and at its wrist singularity q5 = 0; Bravo 7 at its wrist singularity
    q5 = pi; Baxter's left arm (7 joints, redundant) at a singular configuration, pulled
    inward along the lost direction."""
    ur5 = Robot.from_example("ur5")
    bravo = Robot.from_example("bravo7_no_ee", ee_frame="end_effector_ball")
    bravo_wrist = bravo.q0.copy()
    bravo_wrist[bravo.model.joints[bravo.model.getJointId("joint5")].idx_q] = np.pi
    baxter, stretched = baxter_arm()
    for name, value in BAXTER_SINGULAR.items():
        stretched[baxter.velocity_names.index(name)] = value
    out = []
    for label, robot, q in (("UR5 q = 0, roll about the lost axis", ur5, np.zeros(6)),
                            ("UR5 q5 = 0, along u_min", ur5,
                             np.array([0.3, -1.2, 1.5, -1.8, 0.0, 0.2])),
                            ("Bravo 7 q5 = pi, along u_min", bravo, bravo_wrist),
                            ("Baxter arm singular, along u_min", baxter, stretched)):
        lost = lost_direction(robot, q)
        if robot is baxter and lost[2] > 0.0:
            lost = -lost  # inward: outward the target is out of reach
        out.append((label, robot, q, robot.fk(q) * pin.exp6(pin.Motion(angle * lost))))
    return out


def saddles(dts=(1e-3, 4e-3), variants=tuple(VARIANTS), seconds: float = 30.0, progress=None
            ) -> list[SaddleRow]:
    """Steps to 1 % of the start error from each saddle of :func:`saddle_problems`, within
    ``seconds`` of simulated time."""
    rows = []
    for label, robot, q0, target in saddle_problems():
        limits = robot.velocity_limits
        for dt in dts:
            for variant in variants:
                solver = _solver(variant, robot, dt, 0.05 if VARIANTS[variant][1] is None
                                 else None)
                q, start, steps, peak = q0.copy(), None, None, 0.0
                for k in range(int(round(seconds / dt))):
                    q = solver.step(q, target)
                    start = solver.error_norm if start is None else start
                    peak = max(peak, float(np.max(np.abs(solver.displacement) / dt / limits)))
                    if solver.error_norm < 0.01 * start:
                        steps = k + 1
                        break
                escapes = solver.escape.escapes if getattr(solver, "escape", None) else 0
                rows.append(SaddleRow(label, variant, dt, steps, peak, escapes))
                if progress:
                    progress(rows[-1])
    return rows


def scaled_urdf(text: str, scale: float) -> str:
    """The URDF XML ``text`` with every length multiplied by ``scale`` (1000: m -> mm): the
    ``xyz`` of every ``origin`` and the position and speed limits of prismatic joints (mesh
    scales and inertias are left alone: load it without visuals)."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text)
    for origin in root.iter("origin"):
        if "xyz" in origin.attrib:
            origin.set("xyz", " ".join(repr(float(v) * scale) for v in origin.get("xyz").split()))
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") == "prismatic" and limit is not None:
            for key in ("lower", "upper", "velocity"):
                if key in limit.attrib:
                    limit.set(key, repr(float(limit.get(key)) * scale))
    return ET.tostring(root, encoding="unicode")


#: Baxter's left arm (7 joints) away from its singularities, the unit-invariance case
BAXTER_ARM = {"left_s1": -0.5, "left_e0": 0.3, "left_e1": 1.2, "left_w0": 0.2, "left_w1": 0.8}
UNIT_VARIANTS = ("SJT (paper, eq. 21)", "SJT", "SJT, transpose feedback", "JT", "DLS (0.05)")


def baxter_arm(scale: float = 1.0) -> tuple[Robot, np.ndarray]:
    """Baxter with the left gripper as end effector, its URDF lengths times ``scale``, and a
    configuration of the left arm away from singularities."""
    import pathlib

    path = Robot.from_example("baxter", ee_frame="left_gripper").urdf
    assert path is not None
    text = scaled_urdf(pathlib.Path(path).read_text(), scale)
    robot = Robot.from_urdf(text, ee_frame="left_gripper", load_visuals=False)
    q0 = robot.q0.copy()
    for name, value in BAXTER_ARM.items():
        q0[robot.velocity_names.index(name)] = value
    return robot, q0


@dataclass
class UnitRow:
    path: str
    variant: str
    dt: float
    joint_difference: float  # max |q_mm - q_m| over the run (rad)
    position_ratio: float  # max position error in mm / 1000 over the one in m
    orientation_ratio: float  # max orientation error in mm over the one in m


def units(dts=(1e-3, 4e-3), variants=UNIT_VARIANTS, progress=None) -> list[UnitRow]:
    """Baxter's left arm in m and in mm (every length of the URDF and of the paths times
    1000): a 10 cm circle and a 0.4 rad screw of the wrist, 2.5 s each, with each variant's
    defaults. The joint trajectories of the two runs and their errors in the scaled unit."""
    (metres, q0), (millimetres, _) = baxter_arm(1.0), baxter_arm(1000.0)
    pose = metres.fk(q0)

    def paths(s: float) -> dict[str, Trajectory]:
        scaled = pin.SE3(pose.rotation, s * pose.translation)
        turned = pose * pin.exp6(pin.Motion(np.array([0.0, 0.0, 0.0, 0.4, 0.25, 0.15])))
        return {"Baxter arm, 10 cm circle": Circle(s * (pose.translation - [0.0, 0.1, 0.0]),
                                                   s * 0.1, 2.0, normal=[1, 0, 0],
                                                   rotation=pose.rotation),
                "Baxter arm, wrist screw": PoseInterpolation(
                    scaled, pin.SE3(turned.rotation, s * turned.translation), 2.0)}

    rows = []
    for name in paths(1.0):
        for dt in dts:
            for variant in variants:
                logs = [track(_solver(variant, robot, dt), paths(s)[name], q0, duration=2.5)
                        for s, robot in ((1.0, metres), (1000.0, millimetres))]
                (m, mm) = logs
                ratio = [float(np.linalg.norm(mm.error[:, rows_], axis=1).max() / scale
                               / np.linalg.norm(m.error[:, rows_], axis=1).max())
                         for rows_, scale in ((slice(0, 3), 1000.0), (slice(3, 6), 1.0))]
                rows.append(UnitRow(name, variant, dt, float(np.abs(mm.q - m.q).max()), *ratio))
                if progress:
                    progress(rows[-1])
    return rows


def unit_table(rows: list[UnitRow]) -> str:
    return _table(rows, "path", lambda r: f"{r.joint_difference:.1e} ({r.position_ratio:.3g}, "
                                          f"{r.orientation_ratio:.3g})")


def _table(rows: list, what: str, cell) -> str:
    """Markdown: one line per (``row.<what>``, dt), one column per variant, ``cell(row)``."""
    variants = list(dict.fromkeys(r.variant for r in rows))
    by = {(getattr(r, what), r.dt, r.variant): r for r in rows}
    lines = [f"| {what} | dt [ms] | " + " | ".join(variants) + " |",
             "|---|---|" + "---|" * len(variants)]
    for key, dt in dict.fromkeys((getattr(r, what), r.dt) for r in rows):
        cells = [cell(by[(key, dt, v)]) for v in variants]
        lines.append(f"| {key} | {1e3 * dt:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _tracking_cell(r: TrackingRow) -> str:
    cell = "diverged" if r.diverged else f"{r.max_error:.2g}"
    return cell if r.damping is None else f"{cell} (λ {r.damping:g})"


def _saddle_cell(r: SaddleRow) -> str:
    steps = "not within the budget" if r.steps is None else f"{r.steps}"
    return f"{steps} ({r.peak_speed_ratio:.2f})"


def tracking_table(rows: list[TrackingRow]) -> str:
    return _table(rows, "path", _tracking_cell)


def rest_table(rows: list[RestRow]) -> str:
    return _table(rows, "robot", lambda r: f"{r.rms_speed:.1e}")


def saddle_table(rows: list[SaddleRow]) -> str:
    return _table(rows, "saddle", _saddle_cell)
