"""Accuracy near singularities (``sjt-pin bench accuracy``): each method at its own largest
stable gain and at ``gain="auto"``, on paths through UR5's wrist singularity, UR5's stretched
elbow and Panda's stretched arm.

The methods run bare (no joint limits), as in the paper, so a blow-up shows; the largest stable
gain comes from the same bisection and stability criterion as the paper's sweeps
(:mod:`.stability`), between 1 1/s and 2 / dt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..solvers import make_solver
from ..robot import Robot
from ..paper.stability import largest_stable, stability
from ..tasks import PoseTask
from ..tracking import TrackingLog, track
from ..trajectories import PoseInterpolation, Trajectory

METHODS = ("sjt", "jt", "jp", "dls")
DT = 2e-3  # s, the same for every method and path


@dataclass
class SingularPath:
    """A robot, a start configuration and a pose path that passes near a singularity."""

    name: str
    robot: Robot
    q0: np.ndarray
    trajectory: Trajectory
    note: str


def singular_paths() -> list[SingularPath]:
    """The three paths of the benchmark (3 s each, minimum-jerk, starting on the path)."""
    ur5 = Robot.from_example("ur5")
    panda = Robot.from_example("panda")
    # UR5 wrist: 0.01 rad from q5 = 0 (joints 4 and 6 aligned), turn the tool by 0.3 along
    # the task direction that the singular Jacobian loses (a screw about a nearly lost axis)
    wrist = np.array([0.3, -1.2, 1.5, -1.8, 0.0, 0.2])
    lost = np.linalg.svd(ur5.jacobian(wrist))[0][:, -1]
    wrist[4] = 0.01
    start = ur5.fk(wrist)
    wrist_path = PoseInterpolation(start, start * pin.exp6(pin.Motion(0.3 * lost)), 3.0)
    # UR5 elbow: from a bent elbow to the straight arm (elbow angle 0, sigma_min = 0 at the end)
    elbow_a = np.array([0.0, -1.2, 1.4, -1.8, -1.5, 0.0])
    elbow_b = np.array([0.0, -0.5, 0.0, -1.2, -1.5, 0.0])
    # Panda: from the ready pose to the arm stretched upward, joint 4 at its stop (-0.07 rad)
    stretched = panda.q0.copy()
    stretched[1], stretched[3], stretched[5] = 0.0, -0.0698, 1.0
    return [
        SingularPath("ur5 wrist (q5 -> 0)", ur5, wrist, wrist_path,
                     "a screw about the wrist's nearly lost direction, from q5 = 0.01"),
        SingularPath("ur5 elbow stretch", ur5, elbow_a,
                     PoseInterpolation(ur5.fk(elbow_a), ur5.fk(elbow_b), 3.0),
                     "to the straight elbow (singular at the end)"),
        SingularPath("panda stretch", panda, panda.q0.copy(),
                     PoseInterpolation(panda.fk(panda.q0), panda.fk(stretched), 3.0),
                     "from the ready pose to the arm stretched upward"),
    ]


@dataclass
class AccuracyRow:
    path: str
    method: str
    gain: float | str
    max_error: float
    rms_error: float
    max_joint_speed: float
    diverged: bool
    reason: str


def _run(path: SingularPath, method: str, gain) -> TrackingLog:
    solver = make_solver(method, path.robot, gain=gain, dt=DT, task=PoseTask(),
                         position_limits=False, velocity_limits=False, check_stability=False)
    return track(solver, path.trajectory, path.q0, duration=path.trajectory.duration + 0.5)


def _row(path, method, gain, log) -> AccuracyRow:
    stable, why = stability(log)
    return AccuracyRow(path.name, method, gain, float(log.error_norm.max()),
                       float(np.sqrt(np.mean(log.error_norm**2))), log.max_joint_speed,
                       not stable, why)


def accuracy(methods=METHODS, paths: list[SingularPath] | None = None,
             progress=None) -> list[AccuracyRow]:
    """Rows for each path and method at its largest stable gain and at ``"auto"``."""
    rows = []
    for path in singular_paths() if paths is None else paths:
        for method in methods:
            best = largest_stable(lambda g: stability(_run(path, method, g))[0],  # noqa: B023
                                  1.0, 2.0 / DT, rtol=0.02)
            for gain in ([best] if best > 0 else []) + ["auto"]:
                rows.append(_row(path, method, gain, _run(path, method, gain)))
                if progress:
                    progress(rows[-1])
    return rows


def accuracy_table(rows: list[AccuracyRow]) -> str:
    lines = ["| path | method | gain [1/s] | max error | RMS error | max joint speed [rad/s] | "
             "unstable |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        gain = r.gain if isinstance(r.gain, str) else f"{r.gain:.4g}"
        lines.append(f"| {r.path} | {r.method} | {gain} | {r.max_error:.3g} | {r.rms_error:.3g} | "
                     f"{r.max_joint_speed:.3g} | {r.reason or 'no'} |")
    return "\n".join(lines)
