"""The ``sjt-pin`` command: ``demo``, ``reproduce`` (the paper's simulations), ``bench``."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
import webbrowser
from collections.abc import Sequence
from pathlib import Path

from .paper import scenarios
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
    """Track each robot's demo trajectory with each method, print the table, write the page."""
    rows, runs = [], {}
    total = len(args.robot) * len(args.method)
    print(f"Tracking {len(args.robot)} robot(s) x {len(args.method)} method(s), dt = "
          f"{DEMO_DT:g} s\n(the first time on a machine, the solvers' kernels are compiled "
          "first: about half a minute on 2 cores)", flush=True)
    for name in args.robot:
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
    print(f"\nErrors in m/rad, joint speeds in rad/s (gain = auto)\n{_table(rows)}", flush=True)
    if args.no_viewer:
        return 0
    from .viewer.demo import demo_viewer, describe

    print("\nWriting the page ...", flush=True)
    methods = ", ".join(m.upper() for m in args.method)
    viewer = demo_viewer(runs, live=args.keep > 0)
    try:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        path = viewer.save_html(args.out, f"sjt-pin demo: tracking a circle with {methods}",
                                describe(args.robot, DEMO_DT))
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


def _write_json(path: str | None, payload) -> None:
    if path:
        import json

        with open(path, "w") as f:
            json.dump(payload, f, indent=1, default=float)
        print(f"wrote {path}")


def bench(args: argparse.Namespace) -> int:
    """``sjt-pin bench speed|accuracy|ik``: the tables of the README's Benchmarks section."""
    from dataclasses import asdict

    from .bench import speed as speed_bench

    machine = speed_bench.machine()
    print(f"{machine.get('cpu') or machine['machine']}; Python {machine['python']}, "
          f"Pinocchio {machine['pinocchio']}, NumPy {machine['numpy']}", flush=True)
    if args.kind == "speed":
        def show(row):
            print(f"  {row.robot:6s} {row.path:44s} {row.step.median:7.2f} us  "
                  f"{row.ratio:5.2f} x floor  p90/median {row.step.jitter:4.2f}", flush=True)

        cold = speed_bench.cold_start("ur5", peers=args.peers)
        print("Cold start, fresh process (s): " + ", ".join(f"{k} {v:.3f}"
                                                          for k, v in cold.items()), flush=True)
        report = speed_bench.speed(steps=args.steps, peers=args.peers, progress=show)
        print(speed_bench.speed_table(report))
        for robot, ratio in sorted(speed_bench.peer_ratios(report).items()):
            print(f"pink / SJT with a target velocity on {robot}: {ratio:.1f}x")
        _write_json(args.json, report.to_dict() | {"cold_start": cold})
    elif args.kind == "accuracy":
        from .bench import accuracy

        def show(row):
            what = getattr(row, "path", None) or getattr(row, "saddle", None) or row.robot
            print(f"  {what}, {row.variant}, dt = {1e3 * row.dt:g} ms", flush=True)

        tracking = accuracy.tracking(progress=show)
        rest = accuracy.rest(progress=show)
        saddles = accuracy.saddles(progress=show)
        units = accuracy.units(progress=show)
        print("\nMax task error (m and rad) along the paths:\n" + accuracy.tracking_table(tracking))
        print("\nRMS joint speed (rad/s) over the last second at a target 0.3 m beyond reach:\n"
              + accuracy.rest_table(rest))
        print("\nSteps to 1 % of the start error from an exact saddle (peak joint speed / URDF "
              "limit):\n" + accuracy.saddle_table(saddles))
        print("\nThe same runs in mm and in m (URDF and paths x 1000): max |q_mm - q_m| (rad) "
              "(max position error mm/1000 over m, max orientation error mm over m):\n"
              + accuracy.unit_table(units))
        from .bench import limits

        def shown(row):
            print(f"  {row.path}, {row.method}", flush=True)

        saturating = limits.saturating(progress=shown)
        franka = limits.franka(progress=shown)
        print("\nOne joint saturates (TIAGo's torso lift, 0.07 m/s), every limit on:\n"
              + limits.saturating_table(saturating))
        print("\nFranka's conditions (Panda, 1 kHz, its acceleration and jerk limits, targets "
              "jumping every 0.5 s, then held):\n" + limits.franka_table(franka))
        _write_json(args.json, {"machine": machine,
                                "tracking": [asdict(r) for r in tracking],
                                "rest": [asdict(r) for r in rest],
                                "saddles": [asdict(r) for r in saddles],
                                "units": [asdict(r) for r in units],
                                "saturating": [asdict(r) for r in saturating],
                                "franka": [asdict(r) for r in franka]})
    else:
        from .bench.ik import ik_benchmark, ik_table, many_throughput

        rows = ik_benchmark(poses=args.poses, peers=not args.no_peers,
                            progress=lambda r: print(f"  {r.robot} {r.method}: "
                                                     f"{100 * r.success:.1f} %", flush=True))
        print(ik_table(rows))
        many = [many_throughput(name, poses=20 * args.poses) for name in ("ur5", "panda")]
        for m in many:
            print(f"solve_many on {m.robot}, {m.poses} poses: {m.single:.0f} poses/s in 1 "
                  f"process, {m.parallel:.0f} in {m.processes} ({m.speedup:.2f}x)")
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows],
                                "solve_many": [asdict(m) for m in many]})
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sjt-pin", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    about = ("track a circle on the planar arm, UR5 and Panda with each method; print a table "
             "and write a self-contained animated page")
    p = sub.add_parser("demo", help=about, description=about[0].upper() + about[1:] + ".")
    p.add_argument("--robot", nargs="+", choices=scenarios.ROBOTS, default=list(scenarios.ROBOTS),
                   help="robots to track (default: all)")
    p.add_argument("--method", nargs="+", choices=sorted(SOLVERS),
                   default=["sjt", "jt", "dls", "jp"], help="methods to compare "
                   "(default: sjt jt dls jp)")
    p.add_argument("--out", default="demo.html", metavar="PATH",
                   help="where to write the page (default: ./demo.html)")
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument("--no-viewer", action="store_true", help="print the table only, no page")
    p.add_argument("--keep", type=float, default=0.0, metavar="SECONDS",
                   help="also serve the live meshcat viewer on 127.0.0.1 for SECONDS before "
                   "exiting (default 0: no live viewer)")
    p.set_defaults(func=demo)
    p = sub.add_parser("reproduce", help="the paper's simulations: figures and results.md")
    p.add_argument("--out", default="results", help="output folder (default: results)")
    p.add_argument("--processes", type=int, default=None,
                   help="worker processes for the sweeps (default: one per core)")
    p.add_argument("--grid", type=int, default=30, help="gains per sweep (default: 30)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=reproduce)
    p = sub.add_parser("bench", help="benchmarks: step speed, accuracy, solve to a pose",
                       description="The benchmarks of the README: speed (every step path "
                       "against its Pinocchio floor), accuracy (tracking near singularities, "
                       "rest at unreachable targets, exits from saddles), ik (TRAC-IK's "
                       "protocol on five arms).")
    p.add_argument("kind", choices=["speed", "accuracy", "ik"], help="which benchmark")
    p.add_argument("--peers", action="store_true",
                   help="speed: add pink's solve_ik (pip install -e '.[bench]')")
    p.add_argument("--steps", type=int, default=5000, help="speed: timed steps per path "
                   "(default: 5000)")
    p.add_argument("--poses", type=int, default=1000, help="ik: random poses per robot "
                   "(default: 1000)")
    p.add_argument("--no-peers", action="store_true",
                   help="ik: skip TRAC-IK and robotics-toolbox's ik_LM")
    p.add_argument("--json", default=None, metavar="PATH", help="also write the results as JSON")
    p.set_defaults(func=bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
