"""Reachability map: which poses of a grid over a robot's workspace :func:`~sjt_pin.ik.solve`
reaches, within the limits.

The sampling (:func:`reachability`):

- **Box and grid.** Take a point on each revolute joint's axis on the chain of the end-effector
  frame: consecutive points are fixed in the same link, so their distances do not change as the
  joints turn, and their sum (plus the last point's distance to the frame, plus the travel of
  any prismatic joint) bounds how far the frame gets from the first point. The points are slid
  along their axes to make that sum short (:func:`reach_sphere`: 0.858 m for Panda's hand
  frame, where the farthest of 5,000 random configurations is 0.857 m away). The centre is the
  first point (on the first joint's axis: the shoulder; world frame, m) and ``R`` the sum. The
  grid is the cube ``centre + k * step`` (k integer, ``|k * step| <= R`` on each axis); only its
  points within the sphere of radius ``R`` are kept, the others cannot be reached.
- **Orientations.** At every point the same ``orientations`` rotations of the end-effector frame
  (world axes): the points of an ``orientations``-point super-Fibonacci spiral on the unit
  quaternions (Alexa, "Super-Fibonacci Spirals: Fast, Low-Discrepancy Sampling of SO(3)", CVPR
  2022), evenly spread over all rotations (no two of 20 closer than 48 degrees) and the same on
  every run.
- **Solve.** Pose ``k = point * orientations + orientation`` is solved from the robot's reference
  configuration ``q0`` with ``rng = default_rng([seed, k])`` and an iteration budget of
  ``budget`` (default 500, against :func:`~sjt_pin.ik.solve`'s 2000: of 1,500 random poses
  within 0.99 m of Panda's shoulder, every one solved within 2000 iterations was solved within
  500). A pose
  counts as reached when ``solve`` succeeds (``|e| < 1e-6``, within the position limits and any
  ``limits=``): the map is a lower bound. The results do not depend on how the work is spread
  (one process, a pool, a Dask cluster) nor on interruptions: a partial ``.npz`` resumes.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .batch import solve_chunks
from .robot import Robot
from .validation import integer, positive

STEP = 0.05  # m
ORIENTATIONS = 20
BUDGET = 500  # iterations per pose
CHECKPOINT = 30.0  # s between writes of the partial map
#: the super-Fibonacci spiral's two irrational steps (Alexa 2022): sqrt(2) and the real root of
#: psi^4 = psi + 4
PHI, PSI = math.sqrt(2.0), 1.533751168755204288118041


def reach_sphere(robot: Robot, frame: str | None = None) -> tuple[np.ndarray, float]:
    """(centre (3,), R): a point on the axis of the first moving joint of ``frame``'s chain
    (default the end-effector frame; world, m) and a bound on the distance from it to
    ``frame``'s origin (m); see the module docstring."""
    model = robot.model
    frame_id = robot.frame_id(frame or robot.ee_frame)
    joints = [j for j in model.supports[model.frames[frame_id].parentJoint]
              if j > 0 and model.joints[j].nv > 0]
    if not joints:
        raise ValueError(f"frame {frame or robot.ee_frame!r} of {robot.name} moves with no joint")
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.q0)
    pin.updateFramePlacements(model, data)
    origins, axes, travel = [], [], 0.0
    for j in joints:
        joint = model.joints[j]
        origins.append(data.oMi[j].translation.copy())
        if joint.nv == 1:
            J = pin.getJointJacobian(model, data, j, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            axis = J.reshape(6, model.nv)[3:, joint.idx_v]  # ((6,) where nv = 1)
            if np.linalg.norm(axis) > 0.5:  # revolute: any point on its axis will do
                axes.append(axis / np.linalg.norm(axis))
                continue
        axes.append(np.zeros(3))  # its origin: a spherical joint turns about it
        if joint.nq != 4:  # it translates (prismatic, planar, free): add its travel
            span = (robot.upper_limits[joint.idx_q:joint.idx_q + joint.nq]
                    - robot.lower_limits[joint.idx_q:joint.idx_q + joint.nq])
            if not np.all(np.isfinite(span)):
                raise ValueError(f"{robot.name}: joint {model.names[j]!r} translates without "
                                 "limits, so the reach has no bound")
            travel += float(np.linalg.norm(span))
    end = data.oMf[frame_id].translation.copy()
    t = _shortest_chain(np.array(origins), np.array(axes), end)
    points = np.array(origins) + t[:, None] * np.array(axes)
    return points[0], _chain_length(points, end) + travel


def _chain_length(points: np.ndarray, end: np.ndarray) -> float:
    hops = np.diff(np.vstack([points, end]), axis=0)
    return float(np.sum(np.sqrt(np.einsum("ij,ij->i", hops, hops))))


def _shortest_chain(origins: np.ndarray, axes: np.ndarray, end: np.ndarray,
                    sweeps: int = 60) -> np.ndarray:
    """Positions ``t`` along the axes that shorten the chain ``origins + t axes`` -> ``end``:
    coordinate descent on the length (convex in ``t``), each coordinate by golden-section
    search. Any ``t`` gives a bound; this one a tight one."""
    t = np.zeros(len(origins))
    scale = _chain_length(origins, end) + 1.0
    ratio = (math.sqrt(5.0) - 1.0) / 2.0

    def length(i: int, value: float) -> float:
        trial = t.copy()
        trial[i] = value
        return _chain_length(origins + trial[:, None] * axes, end)

    for _ in range(sweeps):
        for i in np.flatnonzero(np.any(axes != 0.0, axis=1)).tolist():
            a, b = t[i] - scale, t[i] + scale
            for _ in range(40):
                c, d = b - ratio * (b - a), a + ratio * (b - a)
                if length(i, c) < length(i, d):
                    b = d
                else:
                    a = c
            best = 0.5 * (a + b)
            if length(i, best) < length(i, t[i]):
                t[i] = best
    return t


def grid(centre, radius: float, step: float = STEP) -> np.ndarray:
    """The points ``centre + k * step`` (k integer) within ``radius`` of ``centre``: (P, 3), m,
    in x-major order."""
    step = positive(step, "step", "m")
    count = int(math.floor(radius / step + 1e-9))
    if (2 * count + 1) ** 3 > 10**8:
        raise ValueError(f"step must be larger: {step} m gives {(2 * count + 1) ** 3:.3g} grid "
                         f"points within {radius:.3g} m")
    k = np.arange(-count, count + 1) * step
    offsets = np.stack(np.meshgrid(k, k, k, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = np.einsum("ij,ij->i", offsets, offsets) <= radius * radius * (1 + 1e-12)
    return np.asarray(centre, dtype=float) + offsets[inside]


def spread_rotations(count: int = ORIENTATIONS) -> np.ndarray:
    """``count`` rotations evenly spread over SO(3): unit quaternions (x, y, z, w), (count, 4),
    the first points of a super-Fibonacci spiral (Alexa 2022; ``w >= 0``)."""
    count = integer(count, "orientations")
    s = np.arange(count) + 0.5
    r, R = np.sqrt(s / count), np.sqrt(1.0 - s / count)
    alpha, beta = 2.0 * np.pi * s / PHI, 2.0 * np.pi * s / PSI
    quaternions = np.stack([r * np.sin(alpha), r * np.cos(alpha), R * np.sin(beta),
                            R * np.cos(beta)], axis=1)
    return quaternions * np.where(quaternions[:, 3:] < 0, -1.0, 1.0)


@dataclass
class ReachMap:
    """A reachability map (see the module docstring); :meth:`save` writes it as ``.npz``.

    ``positions`` (P, 3) m and ``orientations`` (O, 4) unit quaternions (x, y, z, w), world
    frame; ``reached`` (P, O) bool; ``q`` (P, O, nq): the solution, or the best configuration
    found where the pose was not reached; ``error`` (P, O): the error norm at ``q`` (m and rad);
    ``done``: poses solved so far, in the order ``k = point * O + orientation`` (a partial map
    has ``done < P * O``; the rest is False / NaN).
    """

    robot: str
    frame: str
    step: float
    centre: np.ndarray
    radius: float
    seed: int
    budget: int
    positions: np.ndarray
    orientations: np.ndarray
    reached: np.ndarray
    q: np.ndarray
    error: np.ndarray
    done: int = 0
    seconds: float = 0.0  # solving time, over all sessions
    extra: dict = field(default_factory=dict)

    @property
    def poses(self) -> int:
        return self.reached.size

    @property
    def complete(self) -> bool:
        return self.done == self.poses

    @property
    def fraction(self) -> np.ndarray:
        """(P,): the fraction of the orientations reached at each point."""
        return self.reached.mean(axis=1)

    def _settings(self) -> dict:
        return {"robot": self.robot, "frame": self.frame, "step": self.step,
                "centre": self.centre.tolist(), "radius": self.radius, "seed": self.seed,
                "budget": self.budget, "orientations": len(self.orientations),
                "nq": self.q.shape[-1]}

    def save(self, path: str | Path) -> Path:
        """Write the map to ``path`` (``.npz``; atomically: a partial map resumes)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".part.npz")
        np.savez(tmp, positions=self.positions, orientations=self.orientations,
                 reached=self.reached, q=self.q, error=self.error, done=self.done,
                 seconds=self.seconds, robot=self.robot, frame=self.frame, step=self.step,
                 centre=self.centre, radius=self.radius, seed=self.seed, budget=self.budget)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> ReachMap:
        """A map written by :meth:`save`."""
        with np.load(path) as f:
            return cls(str(f["robot"]), str(f["frame"]), float(f["step"]), f["centre"],
                       float(f["radius"]), int(f["seed"]), int(f["budget"]), f["positions"],
                       f["orientations"], f["reached"], f["q"], f["error"], int(f["done"]),
                       float(f["seconds"]))

    def save_html(self, path: str | Path, robot: Robot) -> Path:
        """The page of the map: ``robot`` (its meshes) at its reference configuration and the
        point cloud coloured by :attr:`fraction` (:mod:`sjt_pin.viewer.reachmap`)."""
        # imported by name: the viewer (meshcat) is no part of the core, nor of its type check
        page = importlib.import_module(".viewer.reachmap", __package__)
        return page.save_reach_page(self, robot, path)


class _Poses:
    """The map's poses ``k = start, start + 1, ...`` as ``pin.SE3`` targets, made on demand."""

    def __init__(self, positions: np.ndarray, rotations: Sequence[np.ndarray], start: int):
        self.positions, self.rotations, self.start = positions, rotations, start

    def __len__(self) -> int:
        return len(self.positions) * len(self.rotations) - self.start

    def __iter__(self) -> Iterator[pin.SE3]:
        count = len(self.rotations)
        for k in range(self.start, len(self.positions) * count):
            yield pin.SE3(self.rotations[k % count], self.positions[k // count])


def reachability(robot: Robot, step: float = STEP, orientations: int = ORIENTATIONS, *,
                 solver=None, limits: Sequence = (), out: str | Path | None = None,
                 processes: int | None = None, executor=None, seed: int = 0,
                 budget: int = BUDGET, progress: bool = True,
                 checkpoint: float = CHECKPOINT,
                 report: Callable[[ReachMap], object] | None = None) -> ReachMap:
    """The reachability map of ``robot`` (see the module docstring for the sampling).

    Args:
        robot: the robot; its end-effector frame is the one placed.
        step: the grid's spacing (m).
        orientations: rotations per point (the same at every point).
        solver: the solver whose ``solve`` decides (default: ``SJTSolver(robot,
            limits=limits)``; URDF position limits on).
        limits: further :class:`~sjt_pin.limits.Limit` objects every solution must respect.
        out: an ``.npz`` path: written every ``checkpoint`` seconds and at the end (also when
            interrupted); if it holds a partial map with the same settings, the run resumes
            from it.
        processes, executor: where the poses are solved (as :func:`~sjt_pin.solve_many`;
            e.g. Dask's ``client.get_executor()``).
        seed: the seed of the random restarts (pose ``k``: ``default_rng([seed, k])``).
        budget: iterations of ``solve`` per pose.
        progress: a progress bar (tqdm, on a terminal) with the elapsed time and an estimate
            of the rest.
        checkpoint: seconds between writes of ``out`` (and calls of ``report``).
        report: called with the partial map every ``checkpoint`` seconds.
    """
    from .solvers import SJTSolver

    budget, seed = integer(budget, "budget"), integer(seed, "seed", 0)
    checkpoint = positive(checkpoint, "checkpoint", "s")
    if solver is None:
        solver = SJTSolver(robot, limits=list(limits))
    elif limits:
        raise ValueError("pass limits= or solver=, not both (the solver carries its limits)")
    task = solver.stack.tasks[0]
    frame = getattr(task, "frame", None) or robot.ee_frame
    fresh, rotations = _empty_map(robot, frame, step, orientations, seed, budget)
    result = _resumed(out, fresh)
    if result.complete:
        return result
    parts = solve_chunks(solver, _Poses(result.positions, rotations, result.done), robot.q0,
                         processes=processes, executor=executor, progress=progress, seed=seed,
                         first=result.done, budget=budget)
    _fill(result, parts, out, report, checkpoint)
    return result


def _fill(result: ReachMap, parts, out: str | Path | None,
          report: Callable[[ReachMap], object] | None, checkpoint: float) -> None:
    """Write the solved ``parts`` (:class:`~sjt_pin.batch.BatchPart`, from ``result.done``
    on) into ``result``, saving it to ``out`` and calling ``report`` every ``checkpoint``
    seconds, and saving it at the end (also when interrupted)."""
    reached, q, error = (a.reshape(-1, *a.shape[2:]) for a in (result.reached, result.q,
                                                               result.error))
    start, last = result.done, time.monotonic()
    began = time.perf_counter() - result.seconds
    try:
        for part in parts:
            a, b = start + part.start, start + part.start + len(part)
            reached[a:b], q[a:b], error[a:b] = part.success, part.q, part.error
            result.done = b
            if time.monotonic() - last > checkpoint:
                result.seconds = time.perf_counter() - began
                if out is not None:
                    result.save(out)
                if report is not None:
                    report(result)
                last = time.monotonic()
    finally:
        result.seconds = time.perf_counter() - began
        if out is not None:
            result.save(out)

def _empty_map(robot: Robot, frame: str, step: float, orientations: int, seed: int,
               budget: int) -> tuple[ReachMap, list[np.ndarray]]:
    """A map with nothing solved yet (see the module docstring for the sampling), and the
    rotation matrix of each of its orientations."""
    centre, radius = reach_sphere(robot, frame)
    positions = grid(centre, radius, step)
    quaternions = spread_rotations(orientations)
    rotations = [pin.Quaternion(w, x, y, z).toRotationMatrix() for x, y, z, w in quaternions]
    shape = (len(positions), len(quaternions))
    return ReachMap(robot.name, frame, float(step), centre, radius, int(seed), int(budget),
                    positions, quaternions, np.zeros(shape, dtype=bool),
                    np.full(shape + (robot.nq,), np.nan), np.full(shape, np.nan)), rotations


def _resumed(out: str | Path | None, fresh: ReachMap) -> ReachMap:
    """The partial map in ``out`` when it has ``fresh``'s settings, else ``fresh``."""
    if out is None or not Path(out).exists():
        return fresh
    result = ReachMap.load(out)
    if result._settings() != fresh._settings():
        raise ValueError(f"out: {out} holds a map with other settings "
                         f"({result._settings()}); remove it or choose another path")
    return result


def reach_command(name: str, step: float = STEP, orientations: int = ORIENTATIONS, *,
                  out: str | Path | None = None, page: str | Path | None = None,
                  processes: int | None = None,
                  scheduler: str | None = None, budget: int = BUDGET, seed: int = 0,
                  quiet: bool = False, frame: str | None = None) -> ReachMap:
    """``sjt-pin reach NAME``: the map of example-robot-data's robot ``name`` (its ``frame``,
    default its end effector), written to ``out`` (default ``reach_NAME.npz``, resumed if
    partial) and ``page`` (default ``reach_NAME.html``); on the Dask cluster at ``scheduler``
    when given."""
    robot = Robot.from_example(name, ee_frame=frame)
    out = out or f"reach_{name}.npz"
    page = page or f"reach_{name}.html"
    centre, radius = reach_sphere(robot)
    points = len(grid(centre, radius, step))
    print(f"{robot.name}: {points:,} grid points ({100 * step:g} cm) within {radius:.2f} m of "
          f"the shoulder x {orientations} orientations = {points * orientations:,} poses, "
          f"{budget} iterations each; saved to {out} every {CHECKPOINT:g} s (rerun to resume)",
          flush=True)
    executor, client = None, None
    if scheduler is not None:
        try:
            import distributed
        except ImportError as exc:
            raise ImportError("--scheduler needs Dask's distributed: python -m pip install "
                              "'sjt-pin[cluster]'") from exc

        client = distributed.Client(scheduler)
        workers = len(client.scheduler_info()["workers"])
        print(f"on the Dask cluster at {scheduler} ({workers} workers)", flush=True)
        executor = client.get_executor()
    def report(partial: ReachMap) -> None:  # a line per checkpoint where no bar is drawn
        rate = (partial.done - resumed) / max(time.perf_counter() - start, 1e-9)
        print(f"  {partial.done:,} of {partial.poses:,} poses, {partial.seconds:.0f} s; about "
              f"{(partial.poses - partial.done) / max(rate, 1e-9):.0f} s left", flush=True)

    resumed = ReachMap.load(out).done if Path(out).exists() else 0
    try:
        start = time.perf_counter()
        result = reachability(robot, step, orientations, out=out, processes=processes,
                              executor=executor, seed=seed, budget=budget, progress=not quiet,
                              report=None if quiet or sys.stderr.isatty() else report)
        elapsed = time.perf_counter() - start
    finally:
        if client is not None:
            client.close()
    print(f"{result.poses:,} poses in {result.seconds:.0f} s of solving ({elapsed:.0f} s this "
          f"run): {100 * result.reached.mean():.1f} % reached, "
          f"{np.count_nonzero(result.fraction > 0):,} of {points:,} points in some orientation",
          flush=True)
    try:
        path = result.save_html(page, robot)
    except ImportError as exc:  # the viewer's extra is not installed: the map is saved anyway
        print(f"wrote {out}; no page: {exc}", flush=True)
        return result
    print(f"wrote {out} and {path} (self-contained: open it in a web browser)", flush=True)
    return result
