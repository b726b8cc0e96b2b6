"""The paper's simulations (Sections 3.3 and 4), one function per experiment.

The paper gives the arm (links 0.3, 0.4, 0.28 m, gripper 0.2 m), the three desired paths of
Fig. 5 and the largest stable gains of JT (36 / 25 / 33) and SJT (680 / 500 / 660). It gives no
control period, durations, start configuration or circle centre; the choices made here
(:class:`PaperSettings`) are documented in ``results.md`` and docs/paper.md:

- dt = 1 ms: with it the linear SJT bound ``2 / (dt lambda_max(J D J^T))`` is 667 1/s wherever the
  arm is stretched (``J D J^T`` tends to the rank-one matrix of eigenvalue n = 3), next to the
  paper's 680 and 660.
- start: elbow up at (60, 45, 30) deg, refined onto (-0.293, 0.986), the start point of Fig. 5.
- task 1 and 2: 0.8 m lines in 2 s (0.4 m/s); task 2 then holds its unreachable end for 1 s.
- task 3: the circle of radius 0.194 m about (0, 0.986) — it touches the reach (1.18 m) at its
  top — once in 4 s, counter-clockwise from its leftmost point (-0.194, 0.986).

Every length is multiplied by ``scale`` (the arm, the paths and the errors): a scale of 100 is
the same arm in centimetres. SJT's stable gain does not change with it; JT's falls as 1/scale^2.
"""

from __future__ import annotations

import functools
import os
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace

import numpy as np
import pinocchio as pin

from ..extras import require

require("yourdfpy")  # the planar arms are generated as URDF

from ..methods import JT, SJT  # noqa: E402
from ..robot import Robot  # noqa: E402
from ..robots import planar3 as generator  # noqa: E402
from ..solvers import make_solver  # noqa: E402
from ..tasks import PositionTask  # noqa: E402
from ..tracking import TrackingLog, track  # noqa: E402
from ..trajectories import Circle, Line, Trajectory  # noqa: E402
from .ellipsoids import linear_gain_bound, motion_ellipsoid  # noqa: E402
from .scenarios import PLANAR3_START, settle  # noqa: E402
from .stability import largest_stable  # noqa: E402
from .stability import stability as run_stability  # noqa: E402

#: The paper's own updates: eq. (10) and eq. (21) exactly (alpha_i = 1 / J_i^T J_i, eq. 18).
PAPER_FORM = {
    "sjt": {"feedback": "transpose", "feedforward": "transpose", "length": 0.0, "escape": False},
    "jt": {"feedforward": "transpose", "escape": False},
    # the textbook least squares, without the error's Levenberg-Marquardt damping
    "jp": {"error_damping": 0.0},
    "dls": {"error_damping": 0.0},
}
#: The paper's largest stable gains (1/s) for tasks 1, 2 and 3 (Section 4).
PAPER_GAINS = {"jt": (36.0, 25.0, 33.0), "sjt": (680.0, 500.0, 660.0)}
TASKS = (1, 2, 3)
METHODS = ("jt", "sjt", "jp", "dls")
#: ``scale`` for a length unit: the arm's numbers in that unit are ``scale`` times those in m.
LENGTH_UNITS = {"m": 1.0, "dm": 10.0, "cm": 100.0, "mm": 1000.0}


@dataclass(frozen=True)
class PaperSettings:
    """Everything the paper leaves open, with the values used here (SI units)."""

    dt: float = 1e-3  # s
    scale: float = 1.0  # length unit: 1 = m, 100 = cm, ...
    line_duration: float = 2.0  # s, tasks 1 and 2
    circle_duration: float = 4.0  # s, task 3
    hold: float = 1.0  # s of holding the final target after the path
    damping: float = 0.01  # DLS damping, in m at scale 1 (scaled with the lengths)
    oscillation_tol: float = 1e-4  # m at scale 1: smallest period-2 amplitude called unstable
    speed_bound: float = 100.0  # rad/s: a faster joint is flailing (10x the URDF limit)


@dataclass
class PaperTask:
    """One of the tasks of Fig. 5: trajectory, start, and how long the target stays reachable."""

    number: int
    robot: Robot
    trajectory: Trajectory
    q0: np.ndarray
    duration: float  # s simulated (path + hold)
    reachable_until: float  # s; the max error counts only before this time


@functools.lru_cache(maxsize=16)
def planar_arm(scale: float = 1.0) -> Robot:
    """The paper's 3-link arm with every length multiplied by ``scale``."""
    if scale == 1.0:
        return Robot.planar3()
    robot = Robot.from_urdf(generator.to_xml(generator.planar3(scale)), ee_frame="ee")
    robot.name = f"planar3 x{scale:g}"
    return robot


@functools.lru_cache(maxsize=64)
def paper_task(number: int, settings: PaperSettings = PaperSettings()) -> PaperTask:
    """Task ``number`` (1, 2 or 3) of Fig. 5 under ``settings``."""
    if number not in TASKS:
        raise ValueError(f"number must be one of {TASKS}, got {number!r}")
    s = settings.scale
    robot = planar_arm(s)
    start = s * np.array([-0.293, 0.986, 0.0])
    reach = s * (0.3 + 0.4 + 0.28 + 0.2)
    if number == 3:
        trajectory: Trajectory = Circle(s * np.array([0.0, 0.986, 0.0]), s * 0.194,
                                        duration=settings.circle_duration, start_angle=np.pi)
        reachable_until = np.inf
    else:
        end = s * np.array([0.507 if number == 1 else -1.092, 0.986, 0.0])
        trajectory = Line(start, end, duration=settings.line_duration)
        # time at which the line leaves the reach |p| = 1.18 m (task 2 only)
        x_exit = -np.sqrt(reach**2 - start[1] ** 2)
        reachable_until = (np.inf if number == 1 else
                           settings.line_duration * (start[0] - x_exit) / (start[0] - end[0]))
    q0 = settle(robot, PositionTask(axes="xy"), PLANAR3_START, trajectory.sample(0.0)[0])
    return PaperTask(number, robot, trajectory, q0, trajectory.duration + settings.hold,
                     reachable_until)


def _solver(method: str, gain: float, settings: PaperSettings, robot: Robot):
    options = {"damping": settings.damping * settings.scale} if method == "dls" else {}
    if method in PAPER_FORM:
        options.update(PAPER_FORM[method])
    # the paper's methods have no joint limits: the URDF's +-pi and 10 rad/s stay unused
    return make_solver(method, robot, gain=gain, dt=settings.dt, task=PositionTask(axes="xy"),
                       check_stability=False, position_limits=False, velocity_limits=False,
                       **options)


def run(method: str, number: int, gain: float,
        settings: PaperSettings = PaperSettings()) -> TrackingLog:
    """Track task ``number`` with ``method`` at scalar ``gain`` (1/s)."""
    task = paper_task(number, settings)
    solver = _solver(method, gain, settings, task.robot)
    return track(solver, task.trajectory, task.q0, duration=task.duration,
                 max_error=100.0 * settings.scale)


def reachable_max_error(log: TrackingLog, task: PaperTask) -> float:
    """Largest error norm while the target is reachable (m in the task's unit)."""
    if log.diverged:
        return np.inf
    return float(log.error_norm[log.t < task.reachable_until].max())


def stability(log: TrackingLog, settings: PaperSettings = PaperSettings()) -> tuple[bool, str]:
    """:func:`sjt_pin.paper.stability.stability` with the settings' tolerances (scaled lengths)."""
    return run_stability(log, settings.oscillation_tol * settings.scale, settings.speed_bound)


def _evaluate(args: tuple[str, int, float, PaperSettings]) -> tuple[float, bool]:
    method, number, gain, settings = args
    log = run(method, number, gain, settings)
    stable, _ = stability(log, settings)
    return reachable_max_error(log, paper_task(number, settings)), stable


def _map(function, items: Sequence, processes: int | None, progress: str | None) -> list:
    """``[function(x) for x in items]``, in ``processes`` processes, with progress: a tqdm bar on
    a terminal, else a line per tenth of the items (CI logs, ``| tee``)."""
    items = list(items)
    if processes is None or processes > 1:
        workers = processes or os.cpu_count() or 1
        with ProcessPoolExecutor(max_workers=workers) as pool:
            return list(_progress(pool.map(function, items), len(items), progress))
    return list(_progress(map(function, items), len(items), progress))


def _progress(results: Iterator, total: int, label: str | None) -> Iterator:
    """``results``, reporting on stderr how many of ``total`` are done under ``label``."""
    if label is None:
        yield from results
        return
    if sys.stderr.isatty():
        from tqdm.auto import tqdm

        yield from tqdm(results, total=total, desc=label, leave=False)
        return
    start, reported = time.perf_counter(), 0
    for done, result in enumerate(results, 1):
        yield result
        if done * 10 // total > reported or done == total:
            reported = done * 10 // total
            print(f"{label}: {done}/{total} ({time.perf_counter() - start:.0f} s)",
                  file=sys.stderr, flush=True)


@dataclass
class Sweep:
    """Max tracking error per gain and the largest stable gain of one method on one task."""

    method: str
    task: int
    gains: np.ndarray  # 1/s
    max_errors: np.ndarray  # m (task unit), inf where unstable
    stable: np.ndarray
    largest_stable_gain: float  # refined by bisection; 0 if no gain of the grid is stable
    error_at_largest: float  # max error (m) of the run at largest_stable_gain
    k_lin: float  # linear bound 2 / (dt max_t lambda_max(J M)) along the reference path
    settings: PaperSettings


def linear_bound(method: str, number: int, settings: PaperSettings = PaperSettings()) -> float:
    """``k_lin = 2 / (dt max_t lambda_max(J M))`` along the path the arm follows on task ``number``.

    The path is that of an accurate DLS run (so it is the same for every method); for SJT
    ``lambda_max <= n_active`` and k_lin >= 2 / (3 dt) whatever the arm's size.
    """
    reference = run("dls", number, 0.5 / settings.dt, settings)
    task = paper_task(number, settings)
    solver = _solver(method, 1.0, settings, task.robot)
    # the x-y task's rows: the world-aligned linear rows x and y
    jacobians = [task.robot.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:2]
                 for q in reference.q]
    matrices = [solver.method.matrix(J) for J in jacobians]
    return linear_gain_bound(jacobians, matrices, settings.dt)


def largest_stable_gain(method: str, number: int, low: float, high: float,
                        settings: PaperSettings = PaperSettings(), rtol: float = 0.005) -> float:
    """Bisect between a stable gain ``low`` and an unstable ``high`` to relative width ``rtol``.

    Returns 0 when ``low`` itself is unstable (JT in centimetres: its feed-forward
    ``J^T x_dot_d`` alone flails, whatever the gain).
    """
    return largest_stable(lambda gain: _evaluate((method, number, gain, settings))[1],
                          low, high, rtol)


def _refine(args) -> float:
    return largest_stable_gain(*args)


def gain_sweep(method: str, task: int, gains: Iterable[float] | None = None,
               settings: PaperSettings = PaperSettings(), processes: int | None = 1,
               progress: bool = False, grid: int = 30) -> Sweep:
    """Max error per gain (Fig. 6) and the largest stable gain of ``method`` on ``task``.

    ``gains`` defaults to ``grid`` gains spaced geometrically from k_lin / 2000 to 2 k_lin. The
    largest stable gain is refined by bisection between the last stable grid gain and the next.
    """
    k_lin = linear_bound(method, task, settings)
    gains = np.geomspace(k_lin / 2000.0, 2.0 * k_lin, grid) if gains is None else np.asarray(
        list(gains), dtype=float)
    label = f"{method.upper()} task {task}" if progress else None
    results = _map(_evaluate, [(method, task, g, settings) for g in gains], processes, label)
    errors = np.array([r[0] for r in results])
    stable = np.array([r[1] for r in results])
    errors[~stable] = np.inf
    largest, error = 0.0, np.inf
    ok = np.flatnonzero(stable)
    if ok.size:
        largest, error = gains[ok[-1]], errors[ok[-1]]
        above = np.flatnonzero(~stable[ok[-1]:])
        if above.size:
            largest = largest_stable_gain(method, task, largest, gains[ok[-1] + above[0]],
                                          settings)
            error = _evaluate((method, task, largest, settings))[0]
    return Sweep(method, task, gains, errors, stable, float(largest), float(error), k_lin,
                 settings)


def gain_sweeps(methods: Sequence[str] = METHODS, tasks: Sequence[int] = TASKS,
                settings: PaperSettings = PaperSettings(), processes: int | None = None,
                progress: bool = True, grid: int = 30) -> dict[tuple[str, int], Sweep]:
    """:func:`gain_sweep` for every method and task, the runs spread over ``processes``."""
    return {(m, t): gain_sweep(m, t, settings=settings, processes=processes, progress=progress,
                               grid=grid)
            for t in tasks for m in methods}


def stable_gain_table(
    variants: dict[str, PaperSettings],
    methods: Sequence[str] = ("jt", "sjt"),
    tasks: Sequence[int] = (1, 3),
    processes: int | None = None,
    progress: str | None = None,
) -> dict[tuple[str, int, str], tuple[float, float]]:
    """Largest stable gain ``(simulated, k_lin)`` per method, task and labelled settings.

    Used for the length-unit study (``variants`` differing in ``scale``, e.g. from
    :data:`LENGTH_UNITS`) and the control-period study (differing in ``dt``). The simulated
    value is bisected between k_lin / 4 and 4 k_lin.
    """
    jobs, keys = [], []
    for label, variant in variants.items():
        for method in methods:
            for number in tasks:
                k_lin = linear_bound(method, number, variant)
                keys.append((method, number, label, k_lin))
                jobs.append((method, number, k_lin / 4.0, 4.0 * k_lin, variant))
    found = _map(_refine, jobs, processes, progress)
    return {(m, t, label): (g, k) for (m, t, label, k), g in zip(keys, found, strict=True)}


def unit_variants(settings: PaperSettings = PaperSettings()) -> dict[str, PaperSettings]:
    """``settings`` in each of :data:`LENGTH_UNITS`."""
    return {unit: replace(settings, scale=scale) for unit, scale in LENGTH_UNITS.items()}


def dt_variants(settings: PaperSettings = PaperSettings(),
                dts: Sequence[float] = (1e-3, 2e-3, 5e-3, 1e-2)) -> dict[str, PaperSettings]:
    """``settings`` at each control period in ``dts`` (s), labelled in ms."""
    return {f"{1e3 * dt:g} ms": replace(settings, dt=dt) for dt in dts}


def ellipsoids(postures: int = 5) -> list[dict]:
    """Motion ellipsoids of T1 = J^T and T2 = D J^T for the unit 2-link arm (Figs. 2-3).

    Posture 0 is q = (pi/2, -pi/2), the last q = (pi, 0) (stretched, singular), evenly between.
    Each entry: ``q``, ``elbow`` and ``hand`` positions (m), and the ``jt`` and ``sjt``
    :class:`~sjt_pin.paper.ellipsoids.MotionEllipsoid` (2-row position Jacobian, as in Section 3.3).
    """
    arm = Robot.from_urdf(generator.to_xml(generator.planar2()), load_visuals=False)
    out = []
    for q in np.linspace([np.pi / 2, -np.pi / 2], [np.pi, 0.0], postures):
        pose = arm.fk(q)
        J = arm.jacobian(q, reference=pin.LOCAL_WORLD_ALIGNED)[:2]  # the x-y position rows
        out.append({
            "q": q,
            "elbow": arm.fk(q, frame="link2").translation[:2],
            "hand": pose.translation[:2],
            "jt": motion_ellipsoid(JT(feedforward="transpose").matrix(J)),
            "sjt": motion_ellipsoid(SJT(feedforward="transpose").matrix(J)),
        })
    return out


def error_series(sweeps: dict[tuple[str, int], Sweep], number: int = 3,
                 methods: Sequence[str] = METHODS) -> dict[str, TrackingLog]:
    """Fig. 7: the runs of task ``number`` at each method's largest stable gain."""
    logs = {}
    for method in methods:
        sweep = sweeps[(method, number)]
        if sweep.largest_stable_gain > 0:
            logs[method] = run(method, number, sweep.largest_stable_gain, sweep.settings)
    return logs


def settings_table(settings: PaperSettings) -> str:
    """The settings as a Markdown list."""
    return "\n".join(f"- `{k}` = {v:g}" for k, v in asdict(settings).items())
