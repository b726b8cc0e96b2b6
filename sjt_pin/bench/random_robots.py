"""``solve()`` on seeded random robots: chains and trees of 1-40 joints of every type, with
random axes and link offsets from 1 mm to 10 m — the robots no table above was tuned on.

Each robot gets random reachable poses (the pose of a random configuration within the
limits) and random seeds; every method solves them with its defaults. A pose counts as solved
as in ``bench ik`` (:func:`sjt_pin.bench.ik.solved`: 1e-5 m, 1e-4 rad, within the limits).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..exceptions import URDFError
from ..robot import Robot
from ..solvers import make_solver
from .ik import problems, solved

#: joint types drawn (revolute twice as often), as in the tests' random robots
TYPES = ("revolute", "revolute", "prismatic", "continuous", "fixed")
METHODS = ("sjt", "jt", "dls", "jp")


def random_urdf(seed: int, joints: int) -> tuple[str, str]:
    """A random tree of ``joints`` joints (mostly a chain, sometimes a branch) and the name of
    its deepest link."""
    rng = np.random.default_rng(seed)
    links, depth, body = ["base"], {"base": 0}, []
    for k in range(joints):
        parent = links[-1] if rng.random() < 0.7 else links[rng.integers(len(links))]
        kind = TYPES[rng.integers(len(TYPES))]
        direction = rng.normal(size=3)
        xyz = direction / np.linalg.norm(direction) * 10 ** rng.uniform(-3, 1)
        rpy = rng.uniform(-np.pi, np.pi, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        limit = ""
        if kind in ("revolute", "prismatic"):
            limit = (f'<limit lower="{-rng.uniform(0.3, 3):.6f}" upper="{rng.uniform(0.3, 3):.6f}"'
                     ' effort="10" velocity="2"/>')
        child = f"l{k}"
        body.append(
            f'<link name="{child}"/><joint name="j{k}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{" ".join(f"{v:.9g}" for v in xyz)}" '
            f'rpy="{" ".join(f"{v:.9g}" for v in rpy)}"/>'
            f'<axis xyz="{" ".join(f"{v:.9g}" for v in axis)}"/>{limit}</joint>')
        links.append(child)
        depth[child] = depth[parent] + 1
    xml = '<robot name="random"><link name="base"/>' + "".join(body) + "</robot>"
    return xml, max(links, key=depth.__getitem__)


@dataclass
class RandomRow:
    """One method on the random robots: poses solved of those tried (and on how many robots
    every pose was solved)."""

    method: str
    robots: int
    poses: int
    solved: int
    robots_all_solved: int

    @property
    def success(self) -> float:
        return self.solved / self.poses if self.poses else float("nan")


def random_robots(count: int = 200, poses: int = 5, seed: int = 0, methods=METHODS,
                  progress: Callable[[int], None] | None = None) -> list[RandomRow]:
    """``solve()`` with each method's defaults on ``poses`` random reachable poses of each of
    ``count`` random robots (1-40 joints; seeded: the same robots every run). Robots where
    no joint moves the leaf are skipped (the documented error)."""
    rng = np.random.default_rng(seed)
    tally = {m: [0, 0, 0, 0] for m in methods}  # robots, poses, solved, robots all solved
    for k in range(count):
        xml, leaf = random_urdf(int(rng.integers(2**32)), int(rng.integers(1, 41)))
        try:
            robot = Robot.from_urdf(xml, ee_frame=leaf, load_visuals=False)
            solvers = {method: make_solver(method, robot) for method in methods}
        except (URDFError, ValueError):
            continue  # no joint moves the leaf: nothing to solve for (the documented error)
        pairs = problems(robot, poses, seed=k)
        for method, solver in solvers.items():
            good = sum(solved(robot, solver.solve(target, start).q, target)
                       for target, start in pairs)
            row = tally[method]
            row[0] += 1
            row[1] += len(pairs)
            row[2] += good
            row[3] += good == len(pairs)
        if progress is not None:
            progress(k)
    return [RandomRow(m, *tally[m]) for m in methods]


def random_table(rows: list[RandomRow]) -> str:
    """The Markdown table of :func:`random_robots`."""
    lines = ["| method | robots | poses | solved | robots with every pose solved |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.method.upper()} | {r.robots} | {r.poses} | "
                     f"{100 * r.success:.1f} % | {r.robots_all_solved} |")
    return "\n".join(lines)
