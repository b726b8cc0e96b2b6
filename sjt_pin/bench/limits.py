"""``sjt-pin bench accuracy``'s limit tables: paths where one joint saturates, and a run under
Franka's conditions, for every method (and pink, with its own limits, when installed).

- **saturating** (:func:`saturating`): TIAGo's torso lift allows 0.07 m/s; 15 cm circles that
  need about twice that from it, and that the arm can follow within every limit. Max pose
  error, and the largest joint speed over its URDF limit.
- **franka** (:func:`franka`): Panda at 1 kHz with its published acceleration and jerk limits,
  targets jumping every 0.5 s (every third one out of reach), then a reachable target held for
  8 s; then the same stream on three more arms (xArm7, Kinova's Jaco² j2s6s200, UR10), with
  acceleration and jerk limits of their class. The largest finite-difference velocity,
  acceleration and jerk of the returned ``q`` over their limits, whether ``q`` left the URDF
  range, the final error, and the RMS joint speed over the last second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..solvers import make_solver
from ..tracking import track
from ..trajectories import Circle
from .collision import rates

#: Franka Panda's published joint limits (its control interface's "necessary conditions"),
#: and small ones for the fingers
PANDA_ACCELERATION = np.array([15, 7.5, 10, 12.5, 15, 20, 20, 1.0])  # rad/s^2, m/s^2
PANDA_JERK = np.array([7500, 3750, 5000, 6250, 7500, 10000, 10000, 500])  # rad/s^3
METHODS = ("sjt", "dls", "jp", "jt")
#: TIAGo's arm with the torso raised, where circles in these planes need about 0.14 and
#: 0.19 m/s of the torso (found by sampling; the arm follows them within every other limit)
TIAGO_START = [0.201, 1.436, 0.208, -1.368, 1.266, 0.445, -0.493, -0.092]
TIAGO_NORMALS = {"TIAGo 15 cm circle, y-z plane": (1.0, 0.0, 0.0),
                 "TIAGo 15 cm circle, x-y plane": (0.0, 0.0, 1.0)}


@dataclass
class LimitRow:
    path: str
    method: str
    max_error: float
    speed: float  # the largest |q_dot| / limit
    acceleration: float = float("nan")
    jerk: float = float("nan")
    in_range: bool = True
    final_error: float = float("nan")
    rest: float = float("nan")


def _circle(robot: Robot, q0: np.ndarray, normal) -> Circle:
    start = robot.fk(q0)
    around = Circle(start.translation, 0.075, 3.0, normal=normal, rotation=start.rotation)
    first, _ = around.sample(0.0)
    return Circle(2 * start.translation - first.translation, 0.075, 3.0, normal=normal,
                  rotation=start.rotation)


def saturating(methods=METHODS, peers: bool = True, progress=None) -> list[LimitRow]:
    """Every method on TIAGo's circles (module docstring)."""
    tiago = Robot.from_example("tiago_no_hand", ee_frame="arm_tool_link")
    q0 = tiago.q0.copy()
    q0[:len(TIAGO_START)] = TIAGO_START
    vmax = tiago.velocity_limits
    rows = []
    for path, normal in TIAGO_NORMALS.items():
        circle = _circle(tiago, q0, normal)
        for method in methods:
            log = track(make_solver(method, tiago), circle, q0)
            row = LimitRow(path, method.upper(), log.max_error,
                           float(np.max(np.abs(log.dq) / vmax)))
            rows.append(row)
            if progress:
                progress(row)
        if peers:
            row = _pink_circle(tiago, q0, circle, path)
            if row is not None:
                rows.append(row)
                if progress:
                    progress(row)
    return rows


def _pink_circle(robot: Robot, q0: np.ndarray, circle: Circle, path: str) -> LimitRow | None:
    """pink's solve_ik on the same circle: a FrameTask, a small PostureTask, its configuration
    and velocity limits (its QP keeps per-joint bounds)."""
    try:
        import pink
        import qpsolvers
        from pink.tasks import FrameTask
        from pink.tasks import PostureTask as PinkPosture
    except ImportError:
        return None
    qp = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    dt = 1e-3
    configuration = pink.Configuration(robot.model, robot.model.createData(), q0)
    task = FrameTask(robot.ee_frame, position_cost=1.0, orientation_cost=1.0)
    posture = PinkPosture(cost=1e-3)
    posture.set_target(q0)
    q, worst, speed = q0.copy(), 0.0, 0.0
    for t in circle.times(dt):
        target, _ = circle.sample(float(t))
        configuration.update(q)
        error = pin.log6(robot.fk(q).actInv(target)).vector
        worst = max(worst, float(np.linalg.norm(error)))
        task.set_target(target)
        velocity = pink.solve_ik(configuration, [task, posture], dt, solver=qp)
        speed = max(speed, float(np.max(np.abs(velocity) / robot.velocity_limits)))
        q = configuration.integrate(velocity, dt)
    return LimitRow(path, "pink", worst, speed)


#: the arms the stream also runs on (xArm7, Kinova's Jaco² j2s6s200, UR10), with acceleration
#: and jerk limits of their class (rad/s^2, rad/s^3)
OTHER_ARMS = {"xarm7": (10.0, 5000.0), "kinova": (10.0, 5000.0), "ur10": (8.0, 2000.0)}


def franka(methods=METHODS, seconds: float = 20.0, arms=OTHER_ARMS, progress=None
           ) -> list[LimitRow]:
    """Every method under Franka's conditions (module docstring), then the same stream on
    ``arms`` (name: acceleration and jerk limit of every joint)."""
    rows = []
    runs = [("panda", PANDA_ACCELERATION, PANDA_JERK, "Franka's limits")]
    runs += [(name, acc, jerk, f"{acc:g} rad/s², {jerk:g} rad/s³")
             for name, (acc, jerk) in arms.items()]
    for name, acceleration, jerk, what in runs:
        robot = Robot.from_example(name)
        for method in methods:
            rows.append(_stream(robot, method, acceleration, jerk, seconds,
                                f"{name}, targets jumping ({what})"))
            if progress:
                progress(rows[-1])
    return rows


def _stream(robot: Robot, method: str, acceleration, jerk, seconds: float, path: str
            ) -> LimitRow:
    """Targets jumping every 0.5 s (every third 1.5-2 m from the base, out of reach), then a
    reachable target near the last configuration held for 8 s."""
    dt, nv = 1e-3, robot.nv
    acceleration = np.broadcast_to(np.asarray(acceleration, float), (nv,))
    jerk = np.broadcast_to(np.asarray(jerk, float), (nv,))
    rng = np.random.default_rng(0)
    solver = make_solver(method, robot, dt=dt, acceleration_limits=acceleration,
                         jerk_limits=jerk)
    q = robot.q0.copy()
    qs = [q]
    for jump in range(int(seconds / 0.5)):
        if jump % 3 == 2:  # out of reach: 1.5-2 m from the base
            direction = rng.normal(size=3)
            target = pin.SE3(pin.exp3(rng.normal(size=3)),
                             rng.uniform(1.5, 2.0) * direction / np.linalg.norm(direction))
        else:
            target = robot.fk(robot.random_configuration(rng))
        for _ in range(500):
            q = solver.step(q, target)
            qs.append(q)
    arm = 7 if robot.name == "panda" else nv  # not the Panda's fingers
    near = pin.integrate(robot.model, q, np.r_[rng.uniform(-0.3, 0.3, arm), np.zeros(nv - arm)])
    held = robot.fk(np.clip(near, robot.lower_limits, robot.upper_limits))
    for _ in range(8000):
        q = solver.step(q, held)
        qs.append(q)
    v, a, j = rates(robot.model, qs, dt)
    qs = np.array(qs)
    return LimitRow(
        path, method.upper(), float("nan"), float(np.max(np.abs(v) / robot.velocity_limits)),
        float(np.max(np.abs(a) / acceleration)), float(np.max(np.abs(j) / jerk)),
        bool(np.all(qs >= robot.lower_limits) and np.all(qs <= robot.upper_limits)),
        float(solver.error_norm), float(np.sqrt(np.mean(v[-1000:] ** 2))))


def saturating_table(rows: list[LimitRow]) -> str:
    out = ["| path | method | max error | max speed / limit |", "|---|---|---|---|"]
    out += [f"| {r.path} | {r.method} | {r.max_error:.2g} | {r.speed:.3f} |" for r in rows]
    return "\n".join(out)


def franka_table(rows: list[LimitRow]) -> str:
    out = ["| path | method | max speed / limit | max acceleration / limit | max jerk / limit | "
           "within range | final error | RMS speed, last 1 s [rad/s] |",
           "|---|---|---|---|---|---|---|---|"]
    out += [f"| {r.path} | {r.method} | {r.speed:.3f} | {r.acceleration:.3f} | {r.jerk:.3f} | "
            f"{'yes' if r.in_range else 'NO'} | {r.final_error:.2g} | {r.rest:.2g} |"
            for r in rows]
    return "\n".join(out)
