"""The ``sjt-pin`` command: ``demo``, ``reproduce`` (the paper's simulations), ``bench``."""

from __future__ import annotations

import argparse
import sys
import time
import webbrowser
from collections.abc import Sequence

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
    """Track each robot's demo trajectory with each method, print the table, write the HTML."""
    rows, runs = [], {}
    for name in args.robot:
        sc = scenarios.scenario(name)
        runs[name] = (sc.robot, {})
        for method in args.method:
            solver = make_solver(method, sc.robot, gain="auto", dt=DEMO_DT, task=sc.task)
            start = time.perf_counter()
            log = track(solver, sc.trajectory, sc.q0)
            rows.append((name, method, log, time.perf_counter() - start))
            runs[name][1][method] = log
    print(f"Tracking the demo trajectories (dt = {DEMO_DT:g} s, gain = auto; errors in m/rad, "
          "joint speeds in rad/s)")
    print(_table(rows))
    if args.no_viewer:
        return 0
    from .viewer import Viewer

    spacing = 2.0  # m between the robots' bases, along y, centred on the origin
    viewer = None
    try:
        for k, (name, (robot, logs)) in enumerate(runs.items()):
            offset = (0.0, spacing * (k - (len(runs) - 1) / 2), 0.0)
            if viewer is None:
                viewer = Viewer(robot, name=name, offset=offset)
            else:
                viewer.add_robot(robot, name, offset=offset)
            viewer.compare(logs, robot=name)
        viewer.set_camera([1.2 + 0.6 * len(runs), 0.4, 0.6 + 0.3 * len(runs)])
        path = viewer.save_html(args.out)
        print(f"\nLive viewer (while this command runs): {viewer.url}")
        print(f"Animation written to {path.resolve()} ({path.stat().st_size / 1e6:.1f} MB, "
              "self-contained; open it in a browser, the timeline is under Open Controls)")
        if args.open:
            webbrowser.open(path.resolve().as_uri(), new=2)
        if args.keep > 0:
            print(f"Serving the live viewer for {args.keep:g} s")
            time.sleep(args.keep)
    finally:
        if viewer is not None:
            viewer.close()
    return 0


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
    """``sjt-pin bench speed|scale|accuracy|ik``."""
    from dataclasses import asdict

    from .bench import speed as speed_bench

    def show(row):
        print(f"  {row.robot:16s} {row.method:18s} {row.step.median:8.2f} us "
              f"(floor {row.primitives.median:.2f}, ratio {row.ratio:.2f})", flush=True)

    machine = speed_bench.machine()
    print(f"{machine.get('cpu', machine['machine'])}; Python {machine['python']}, "
          f"Pinocchio {machine['pinocchio']}, NumPy {machine['numpy']}")
    if args.kind == "speed":
        report = speed_bench.speed(steps=args.steps, peers=args.peers, progress=show)
        print(speed_bench.speed_table(report))
        for robot, ratio in sorted(speed_bench.peer_ratios(report).items()):
            print(f"pink / sjt step time on {robot}: {ratio:.1f}x")
        print("\nWhere an SJT step's time goes (us):")
        for name in ("ur5", "panda"):
            for label, us in speed_bench.breakdown(name):
                print(f"  {name:6s} {us:6.2f}  {label}")
        _write_json(args.json, report.to_dict())
    elif args.kind == "scale":
        report = speed_bench.scale(steps=args.steps, progress=show)
        print(speed_bench.speed_table(report))
        if args.plot:
            from .paper.figures import save, scale_figure

            save(scale_figure(report), args.plot)
            print(f"wrote {args.plot}")
        _write_json(args.json, report.to_dict())
    elif args.kind == "accuracy":
        from .bench.accuracy import accuracy, accuracy_table

        rows = accuracy(progress=lambda r: print(f"  {r.path}: {r.method} done", flush=True))
        print(accuracy_table(rows))
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows]})
    else:
        from .bench.ik import ik_benchmark, ik_table

        rows = ik_benchmark(poses=args.poses, peers=not args.no_peers,
                            progress=lambda r: print(f"  {r.robot} {r.method}: "
                                                     f"{100 * r.success:.1f} %", flush=True))
        print(ik_table(rows))
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows]})
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sjt-pin", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="track a trajectory on the planar arm, UR5 and Panda")
    p.add_argument("--robot", nargs="+", choices=scenarios.ROBOTS, default=list(scenarios.ROBOTS))
    p.add_argument("--method", nargs="+", choices=sorted(SOLVERS),
                   default=["sjt", "jt", "dls", "jp"])
    p.add_argument("--out", default="demo.html", help="static HTML animation (demo.html)")
    p.add_argument("--open", action="store_true", help="open the HTML file in a web browser")
    p.add_argument("--no-viewer", action="store_true", help="print the table only")
    p.add_argument("--keep", type=float, default=0.0,
                   help="seconds to keep the live viewer up before exiting (default 0)")
    p.set_defaults(func=demo)
    p = sub.add_parser("reproduce", help="the paper's simulations: figures and results.md")
    p.add_argument("--out", default="results", help="output folder (default: results)")
    p.add_argument("--processes", type=int, default=None,
                   help="worker processes for the sweeps (default: one per core)")
    p.add_argument("--grid", type=int, default=30, help="gains per sweep (default: 30)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=reproduce)
    p = sub.add_parser("bench", help="benchmarks: speed, scale, accuracy, ik")
    p.add_argument("kind", choices=["speed", "scale", "accuracy", "ik"])
    p.add_argument("--peers", action="store_true", help="speed: add pink (the bench extra)")
    p.add_argument("--steps", type=int, default=5000, help="speed/scale: timed steps")
    p.add_argument("--poses", type=int, default=1000, help="ik: random poses per robot")
    p.add_argument("--no-peers", action="store_true", help="ik: skip pink and TRAC-IK")
    p.add_argument("--plot", default=None, help="scale: write the step-time plot (PNG)")
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.set_defaults(func=bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
