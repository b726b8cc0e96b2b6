"""``sjt-pin bench ik``: solve-to-pose on random reachable poses (TRAC-IK's protocol).

For each robot, poses are the forward kinematics of random configurations within the limits
and each is solved from another random configuration within the limits. A solution counts when
its position error is below 1e-5 m, its rotation error below 1e-4 rad and every joint is within
its limits. Each method runs :meth:`~sjt_pin.solvers.DifferentialIKSolver.solve` with random
restarts until success or a 20 ms budget; peers, when installed (the ``bench`` extra): pink
iterated to convergence from the seed, and TRAC-IK (C++, through ``pytracik``) with its usual
5 ms timeout.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..solvers import make_solver
from ..robot import Robot

POSITION_TOL, ROTATION_TOL = 1e-5, 1e-4  # m, rad
TIMEOUT = 20e-3  # s per pose for this package's solvers (Python); TRAC-IK keeps its 5 ms
TRACIK_TIMEOUT = 5e-3
TIP_LINKS = {"ur5": ("base_link", "tool0"), "panda": ("panda_link0", "panda_hand")}


@dataclass
class IKRow:
    robot: str
    method: str
    poses: int
    success: float  # fraction of poses solved within tolerance and limits
    median_ms: float
    p90_ms: float


def problems(robot: Robot, count: int, seed: int = 0) -> list[tuple[pin.SE3, np.ndarray]]:
    """``count`` (target pose, seed configuration) pairs, both from random q within limits."""
    rng = np.random.default_rng(seed)
    return [(robot.fk(robot.random_configuration(rng)), robot.random_configuration(rng))
            for _ in range(count)]


def solved(robot: Robot, q: np.ndarray, target: pin.SE3) -> bool:
    """Position and rotation within tolerance, and every joint within its limits."""
    if q is None or not np.all(np.isfinite(q)):
        return False
    pose = robot.fk(q)
    position = np.linalg.norm(pose.translation - target.translation)
    rotation = np.linalg.norm(pin.log3(pose.rotation.T @ target.rotation))
    inside = np.all(q >= robot.lower_limits - 1e-9) and np.all(q <= robot.upper_limits + 1e-9)
    return bool(position < POSITION_TOL and rotation < ROTATION_TOL and inside)


def _ours(robot: Robot, method: str):
    solver = make_solver(method, robot, **({"damping": 1e-3} if method == "dls" else {}))
    rng = np.random.default_rng(1)

    def run(target, seed):
        return solver.solve(target, seed, tol=POSITION_TOL, max_iters=200, restarts=100,
                            rng=rng, timeout=TIMEOUT).q

    return run


def _pink(robot: Robot):
    import pink
    import qpsolvers
    from pink.tasks import FrameTask

    qp = "daqp" if "daqp" in qpsolvers.available_solvers else qpsolvers.available_solvers[0]
    task = FrameTask(robot.ee_frame, position_cost=1.0, orientation_cost=1.0)

    def run(target, seed):
        logging.disable(logging.WARNING)  # pink logs every configuration a hair past a limit
        try:
            return _pink_solve(target, seed)
        finally:
            logging.disable(logging.NOTSET)

    def _pink_solve(target, seed):
        configuration = pink.Configuration(robot.model, robot.model.createData(), seed)
        task.set_target(target)
        for _ in range(200):
            error = task.compute_error(configuration)
            if np.linalg.norm(error) < POSITION_TOL:
                break
            velocity = pink.solve_ik(configuration, [task], 1.0, solver=qp, damping=1e-12,
                                     safety_break=False)
            configuration.integrate_inplace(velocity, 1.0)
        return configuration.q

    return run


def _tracik(robot: Robot, name: str):
    import pytracik

    base, tip = TIP_LINKS[name]
    with open(robot.urdf) as f:
        urdf = f.read()
    if f'<child link="{base}"' not in urdf:
        # KDL drops a root link that has an inertia (Panda's link0): hang it from a bare link
        start = urdf.index(">", urdf.index("<robot")) + 1
        urdf = (urdf[:start] + f'<link name="bench_root"/><joint name="bench_root_joint" '
                f'type="fixed"><parent link="bench_root"/><child link="{base}"/></joint>'
                + urdf[start:])
        base = "bench_root"
    solver = pytracik.TRAC_IK(base, tip, urdf, TRACIK_TIMEOUT, POSITION_TOL,
                              pytracik.SolveType.Speed)
    n = pytracik.get_num_joints(solver)
    # its URDF parser reads Panda's limits as 0: give it the limits Pinocchio read
    pytracik.set_joint_limits(solver, robot.lower_limits[:n], robot.upper_limits[:n])

    def run(target, seed):
        xyzquat = pin.SE3ToXYZQUAT(target)  # x y z qx qy qz qw
        result = np.asarray(pytracik.ik(solver, seed[:n], *xyzquat))
        if result[0] < 0:  # status, then the joints
            return None
        q = seed.copy()
        q[:n] = result[1:]
        return q

    return run


def peers_available() -> dict[str, bool]:
    out = {}
    for module in ("pink", "pytracik"):
        try:
            __import__(module)
            out[module] = True
        except ImportError:
            out[module] = False
    return out


def ik_benchmark(robots=("ur5", "panda"), methods=("sjt", "jt", "dls", "jp"), poses: int = 1000,
                 peers: bool = True, progress=None) -> list[IKRow]:
    """Success rate and solve times per robot and method (and peers)."""
    rows = []
    available = peers_available() if peers else {}
    for name in robots:
        robot = Robot.from_example(name)
        pairs = problems(robot, poses)
        runners = [(m, _ours(robot, m)) for m in methods]
        if available.get("pink"):
            runners.append(("pink", _pink(robot)))
        if available.get("pytracik") and name in TIP_LINKS:
            runners.append(("trac-ik", _tracik(robot, name)))
        for label, run in runners:
            times, ok = np.empty(len(pairs)), 0
            for k, (target, seed) in enumerate(pairs):
                start = time.perf_counter()
                q = run(target, seed)
                times[k] = time.perf_counter() - start
                ok += solved(robot, q, target)
            rows.append(IKRow(name, label, len(pairs), ok / len(pairs),
                              1e3 * float(np.median(times)), 1e3 * float(np.percentile(times, 90))))
            if progress:
                progress(rows[-1])
    return rows


def ik_table(rows: list[IKRow]) -> str:
    lines = ["| robot | method | poses | success | median [ms] | p90 [ms] |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.robot} | {r.method} | {r.poses} | {100 * r.success:.1f} % | "
                     f"{r.median_ms:.3f} | {r.p90_ms:.3f} |")
    return "\n".join(lines)
