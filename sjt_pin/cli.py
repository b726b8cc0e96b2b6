"""The ``sjt-pin`` command: ``demo``, ``reproduce`` (the paper's simulations), ``bench``,
``robots`` (the names ``Robot.from_example`` takes).

Every argument is checked while the command line is parsed, before any work, by its ``type=``
(:mod:`sjt_pin.cli_arguments`: numbers by their value, output paths by trying to write there). A
bad argument is one line on stderr (``sjt-pin demo: error: ...``) and exit code 2, never a
traceback. Each command's work is imported when it runs (``bench``'s from
:mod:`sjt_pin.bench.command`).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
import webbrowser
from collections.abc import Sequence
from pathlib import Path

from .cli_arguments import (
    Parser,
    at_least,
    grid_step,
    non_negative_float,
    output_file,
    output_folder,
    positive_int,
)
from .exceptions import FrameNotFound
from .paper import scenarios
from .solvers import SOLVERS, make_solver
from .tracking import TrackingLog, track

DEMO_DT = 1e-3
#: The names ``demo --robot`` takes for the page's whole-body scenes (one SJT run each, with
#: task priorities; :data:`sjt_pin.viewer.demo.WHOLE_BODY_SCENES`): TALOS reaching with both
#: hands over its held soles, Solo-12 moving its body over its held feet.
WHOLE_BODY = ("talos", "solo12")


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
    """Track each robot's demo trajectory with each method, print the table, write the page
    (with the whole-body scenes asked for)."""
    circles = [name for name in args.robot if name not in WHOLE_BODY]
    whole = [name for name in args.robot if name in WHOLE_BODY]
    rows, runs = [], {}
    total = len(circles) * len(args.method)
    if circles:
        print(f"Tracking {len(circles)} robot(s) x {len(args.method)} method(s), dt = "
              f"{DEMO_DT:g} s (a few seconds: the kernels were compiled at install)", flush=True)
    for name in circles:
        print(f"  {name}: loading the robot, finding its start on the path ...", end=" ",
              flush=True)
        start = time.perf_counter()
        sc = scenarios.scenario(name)
        print(f"{time.perf_counter() - start:.1f} s", flush=True)
        runs[name] = (sc.robot, {})
        for method in args.method:
            solver = make_solver(method, sc.robot, gain="auto", dt=DEMO_DT, task=sc.task)
            start = time.perf_counter()
            log = track(solver, sc.trajectory, sc.q0)
            seconds = time.perf_counter() - start
            rows.append((name, method, log, seconds))
            runs[name][1][method] = log
            print(f"  [{len(rows)}/{total}] {name} {method}: {len(log)} steps in "
                  f"{seconds:.2f} s, max error {log.max_error:.2g}", flush=True)
    if circles:
        print(f"\nErrors in m/rad, joint speeds in rad/s (gain = auto)\n{_table(rows)}",
              flush=True)
    if args.no_viewer:
        if whole:
            print(f"{', '.join(whole)}: drawn on the page only (whole-body scenes), not run "
                  "with --no-viewer", flush=True)
        return 0
    from .viewer.demo import WHOLE_BODY_SCENES, demo_viewer, describe, obstacle_scene

    scenes = []
    for name in whole:
        print(f"  {name}: loading the robot, running its whole-body scene (SJT) ...", end=" ",
              flush=True)
        start = time.perf_counter()
        scenes.append(WHOLE_BODY_SCENES[name](DEMO_DT))
        log = scenes[-1].log
        print(f"{len(log)} steps, {time.perf_counter() - start:.1f} s, max error "
              f"{log.max_error:.2g}", flush=True)
    print("\nWriting the page ...", flush=True)
    methods = ", ".join(m.upper() for m in args.method)
    viewer = demo_viewer(runs, live=args.keep > 0, obstacle=obstacle_scene(DEMO_DT),
                         whole_body=scenes)
    try:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        title = f"sjt-pin demo: {methods} on a circle" if circles else "sjt-pin demo"
        path = viewer.save_html(args.out, title, describe(circles, DEMO_DT, obstacle=True))
        print(f"Wrote {path.resolve()} ({path.stat().st_size / 1e6:.1f} MB, self-contained, "
              "works offline): open it in a web browser", flush=True)
        if args.open:
            _open_in_browser(path)
        if args.keep > 0:
            print(f"Live viewer at {viewer.url} for the next {args.keep:g} s "
                  "(Ctrl+C stops it)", flush=True)
            with contextlib.suppress(KeyboardInterrupt):
                time.sleep(args.keep)
            print("Live viewer stopped", flush=True)
    finally:
        viewer.close()
    return 0


def _open_in_browser(path: Path) -> None:
    """Open ``path`` in the default web browser, or say that there is none."""
    uri = path.resolve().as_uri()
    try:
        opened = webbrowser.get().open(uri, new=2)
    except webbrowser.Error:
        opened = False
    if opened:
        print("Opened it in the web browser", flush=True)
    else:
        print(f"--open: no web browser found on this machine; open {uri} in one yourself",
              flush=True)


def reproduce(args: argparse.Namespace) -> int:
    """Run the paper's experiments and write figures and results.md into ``--out``."""
    from .paper.reproduce import reproduce as run

    path = run(args.out, processes=args.processes, progress=not args.quiet, grid=args.grid)
    print(f"wrote {path} and its figures")
    return 0


def robots(args: argparse.Namespace) -> int:
    """Print the robot names ``Robot.from_example`` takes (example-robot-data's)."""
    from example_robot_data.robots_loader import ROBOTS

    names = sorted(ROBOTS)
    print(f"{len(names)} robots of example-robot-data, for sjt.Robot.from_example(name):")
    width = max(map(len, names)) + 2
    columns = max(1, 96 // width)
    for start in range(0, len(names), columns):
        print("  " + "".join(n.ljust(width) for n in names[start:start + columns]).rstrip())
    return 0


def bench(args: argparse.Namespace) -> int:
    """``sjt-pin bench speed|accuracy|reach|settle|ik|collision``: the tables of the documentation's
    Benchmarks page (docs/benchmarks.md); :func:`sjt_pin.bench.command.bench`."""
    from .bench.command import bench as run

    return run(args)


def reach(args: argparse.Namespace) -> int:
    """``sjt-pin reach ROBOT``: the reachability map (:mod:`sjt_pin.reach`)."""
    from .reach import reach_command

    try:
        reach_command(args.robot, args.step, args.orientations, out=args.out, page=args.html,
                      processes=args.processes, scheduler=args.scheduler, budget=args.budget,
                      seed=args.seed, quiet=args.quiet, frame=args.frame)
    except (ValueError, FrameNotFound) as exc:  # an unknown robot or frame, a partial map
        print(f"sjt-pin reach: error: {exc}", file=sys.stderr)
        return 2
    return 0


def _reach_parser(sub) -> None:
    about = ("reachability map: solve() on a grid of positions x orientations over the "
             "robot's workspace; writes an .npz and a self-contained page")
    p = sub.add_parser("reach", help=about, description=about[0].upper() + about[1:] + ".")
    p.add_argument("robot", help="an example-robot-data robot, e.g. panda, ur5")
    p.add_argument("--frame", default=None, help="the frame placed (default: the robot's "
                   "end effector; needed for robots without one, e.g. baxter)")
    p.add_argument("--step", type=grid_step, default=0.05,
                   help="grid spacing in m (default 0.05)")
    p.add_argument("--orientations", type=positive_int, default=20,
                   help="orientations per point (default 20)")
    p.add_argument("--budget", type=positive_int, default=500,
                   help="solve() iterations per pose (default 500)")
    p.add_argument("--seed", type=at_least(0), default=0, help="seed of the random restarts")
    p.add_argument("--out", default=None, metavar="PATH", type=output_file(parents=False),
                   help="the .npz (default reach_ROBOT.npz); a partial one resumes")
    p.add_argument("--html", default=None, metavar="PATH", type=output_file(parents=False),
                   help="the page (default reach_ROBOT.html)")
    p.add_argument("--processes", type=positive_int, default=None,
                   help="worker processes (default: one per core)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="solve on the Dask cluster at ADDRESS (e.g. tcp://host:8786; "
                   "pip install 'sjt-pin[cluster]')")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=reach)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="sjt-pin", description="Differential IK with the scaled Jacobian "
                    "transpose: a demo page, the paper's simulations, the benchmarks. "
                    "Run 'sjt-pin COMMAND --help' for a command's options.")
    sub = parser.add_subparsers(dest="command", required=True)
    about = ("track a circle on the planar arm, UR5 and Panda with each method; print a table "
             "and write a self-contained animated page, with TALOS and Solo-12 balancing on "
             "their feet")
    p = sub.add_parser("demo", help=about, description=about[0].upper() + about[1:] + ".")
    shown = (*scenarios.ROBOTS, *WHOLE_BODY)
    p.add_argument("--robot", nargs="+", choices=shown, default=list(shown),
                   help="robots to track (default: all); talos and solo12 are the page's "
                   "whole-body scenes (SJT with task priorities, whatever --method)")
    p.add_argument("--method", nargs="+", choices=sorted(SOLVERS),
                   default=["sjt", "jt", "dls", "jp"], help="methods to compare "
                   "(default: sjt jt dls jp)")
    p.add_argument("--out", default="demo.html", metavar="PATH", type=output_file(parents=True),
                   help="where to write the page; missing folders are made (default: "
                   "./demo.html)")
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument("--no-viewer", action="store_true", help="print the table only, no page")
    p.add_argument("--keep", type=non_negative_float, default=0.0, metavar="SECONDS",
                   help="also serve the live meshcat viewer on 127.0.0.1 for SECONDS before "
                   "exiting (default 0: no live viewer)")
    p.set_defaults(func=demo)
    about = "the paper's simulations: figures and results.md"
    p = sub.add_parser("reproduce", help=about, description="Run the simulations of Lee, Yim "
                       "and Choi's paper on its 3-link planar arm (its three tasks, gain sweeps "
                       "against the stability bound, the motion ellipsoids) and write the "
                       "figures and results.md into the output folder.")
    p.add_argument("--out", default="results", type=output_folder, metavar="FOLDER",
                   help="output folder, made if missing (default: results)")
    p.add_argument("--processes", type=positive_int, default=None,
                   help="worker processes for the sweeps (default: one per core)")
    p.add_argument("--grid", type=at_least(2), default=30,
                   help="gains per sweep, at least 2 (default: 30)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=reproduce)
    p = sub.add_parser("bench", help="benchmarks: step speed, accuracy, solve to a pose",
                       description="The benchmarks of docs/benchmarks.md: speed (every step "
                       "path against its Pinocchio floor), accuracy (tracking near singularities, "
                       "rest at unreachable targets, exits from saddles), reach (random "
                       "full-range reaches beside pink, settling under jerk limits beside "
                       "Ruckig), settle (rest and swing from starts against the ranges under "
                       "random acceleration and jerk limits, on nine arms), ik (TRAC-IK's "
                       "protocol on five arms), collision (three scenes with and without "
                       "CollisionLimit, and pink's barrier; a moving ball and a mesh, beside "
                       "pink and mink; targets behind an obstacle under acceleration limits).")
    p.add_argument("kind", choices=["speed", "accuracy", "reach", "settle", "ik", "collision"],
                   help="which benchmark")
    p.add_argument("--peers", action="store_true",
                   help="speed: add pink's solve_ik (pip install -e '.[bench]')")
    p.add_argument("--steps", type=positive_int, default=5000, help="speed: timed steps per path "
                   "(default: 5000)")
    p.add_argument("--poses", type=positive_int, default=1000, help="ik: random poses per robot "
                   "(default: 1000)")
    p.add_argument("--no-peers", action="store_true",
                   help="ik: skip TRAC-IK and robotics-toolbox's ik_LM; collision: skip pink and "
                   "mink; reach, accuracy: skip pink")
    p.add_argument("--pairs", type=positive_int, default=50, help="reach: random (start, "
                   "target) pairs per robot (default: 50)")
    p.add_argument("--trials", type=positive_int, default=30, help="reach: runs of the jerk "
                   "grid (default: 30)")
    p.add_argument("--seeds", type=positive_int, default=40, help="settle: draws per arm "
                   "(default: 40, 1,440 runs)")
    p.add_argument("--json", default=None, metavar="PATH", type=output_file(parents=False),
                   help="also write the results as JSON (its folder must exist)")
    p.set_defaults(func=bench)
    about = "list the robot names of example-robot-data (for Robot.from_example)"
    p = sub.add_parser("robots", help=about, description=about[0].upper() + about[1:] + ".")
    p.set_defaults(func=robots)
    _reach_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
