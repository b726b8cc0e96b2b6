"""The ``sjt-pin`` command: ``demo`` (tracking table), ``reproduce`` (the paper's simulations)."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from . import scenarios
from .solvers import SOLVERS, make_solver
from .tracking import TrackingLog, track

DEMO_DT = 1e-3


def _table(rows: list[tuple[str, str, TrackingLog, float]]) -> str:
    head = (f"{'robot':8s} {'method':6s} {'max error':>10s} {'RMS error':>10s} "
            f"{'max |dq|':>9s} {'us/step':>8s}  note")
    lines = [head, "-" * len(head)]
    for robot, method, log, seconds in rows:
        note = f"diverged: {log.reason}" if log.diverged else ""
        lines.append(
            f"{robot:8s} {method:6s} {log.max_error:10.3g} {log.rms_error:10.3g} "
            f"{log.max_joint_speed:9.3g} {1e6 * seconds / max(len(log), 1):8.1f}  {note}"
        )
    return "\n".join(lines)


def demo(args: argparse.Namespace) -> int:
    """Track each robot's demo trajectory with each method and print the table."""
    rows = []
    for name in args.robot:
        sc = scenarios.scenario(name)
        for method in args.method:
            solver = make_solver(method, sc.robot, gain="auto", dt=DEMO_DT, task=sc.task)
            start = time.perf_counter()
            log = track(solver, sc.trajectory, sc.q0)
            rows.append((name, method, log, time.perf_counter() - start))
    print(f"Tracking the demo trajectories (dt = {DEMO_DT:g} s, gain = auto; errors in m/rad, "
          "joint speeds in rad/s)")
    print(_table(rows))
    return 0


def reproduce(args: argparse.Namespace) -> int:
    """Run the paper's experiments and write figures and results.md into ``--out``."""
    from .reproduce import reproduce as run

    path = run(args.out, processes=args.processes, progress=not args.quiet, grid=args.grid)
    print(f"wrote {path} and its figures")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sjt-pin", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="track a trajectory on the planar arm, UR5 and Panda")
    p.add_argument("--robot", nargs="+", choices=scenarios.ROBOTS, default=list(scenarios.ROBOTS))
    p.add_argument("--method", nargs="+", choices=sorted(SOLVERS),
                   default=["sjt", "jt", "dls", "jp"])
    p.set_defaults(func=demo)
    p = sub.add_parser("reproduce", help="the paper's simulations: figures and results.md")
    p.add_argument("--out", default="results", help="output folder (default: results)")
    p.add_argument("--processes", type=int, default=None,
                   help="worker processes for the sweeps (default: one per core)")
    p.add_argument("--grid", type=int, default=30, help="gains per sweep (default: 30)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=reproduce)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
