"""The ``sjt-pin`` command: ``demo``, ``reproduce`` (the paper's simulations), ``bench``,
``robots`` (the names ``Robot.from_example`` takes).

Every argument is checked while the command line is parsed, before any work: numbers by their
``type=`` (:func:`positive_int`, :func:`non_negative_float`), output paths by
:func:`output_file` and :func:`output_folder`, which try to write there. A bad argument is one
line on stderr (``sjt-pin demo: error: ...``) and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
import time
import webbrowser
from collections.abc import Callable, Sequence
from pathlib import Path

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


def _write_json(path: str | None, payload) -> None:
    if path:
        import json

        with open(path, "w") as f:
            json.dump(payload, f, indent=1, default=float)
        print(f"wrote {path}")


def bench(args: argparse.Namespace) -> int:
    """``sjt-pin bench speed|accuracy|reach|ik|collision``: the tables of the documentation's
    Benchmarks page (docs/benchmarks.md)."""
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
    elif args.kind == "collision":
        from .bench import collision, collision_peers

        peer = None if args.no_peers else collision_peers.pink_scene
        rows = collision.collision(peer=peer, progress=lambda r: print(
            f"  {r.scene}, {r.method}, limit {'on' if r.limit else 'off'}", flush=True))
        print("\nCollision avoidance (margin 10 mm; distances checked with coal on the meshes):\n"
              + collision.collision_table(rows))
        plain, idle = collision.idle()
        print(f"\nSJT on Panda, self-collision, nothing within influence: {idle:.1f} us/step "
              f"against {plain:.1f} without the limit ({idle / plain:.1f}x)")
        crowd = collision.crowded()
        print(f"SJT on Panda passing the ball among 19 more obstacles, self-collision "
              f"({crowd.pairs} pairs): "
              f"{crowd.median_us:.1f} us/step median (p99 {crowd.p99_us:.1f}) against "
              f"{crowd.plain_us:.1f} without the limit ({crowd.median_us / crowd.plain_us:.1f}x), "
              f"closest {crowd.min_distance * 1e3:.1f} mm")
        from .bench import collision_stream

        stream = collision_stream.stream()
        print("\nxArm7 with self-collision beside 10 rad/s^2 and 5,000 rad/s^3, targets jumping "
              "every 0.5 s:\n" + collision_stream.stream_table(stream))
        from .bench import collision_mesh, collision_mink, collision_moving, collision_peers

        moving = collision_moving.moving()
        mesh = [collision_mesh.pull(convex) for convex in (True, False)]
        if not args.no_peers:  # (pink's and mink's rows, where they are installed)
            def said(row):
                print(f"  {row.method}, {row.robot}, ball {row.speed:g} m/s, {row.rate:g} Hz",
                      flush=True)

            moving += collision_peers.pink_moving(progress=said)
            moving += collision_mink.mink_moving(progress=said)
            mesh += collision_peers.pink_mesh() + collision_mink.mink_mesh()
        print("\nA 5 cm ball driven at the hand (margin 10 mm; distances on the meshes):\n"
              + collision_moving.moving_table(moving))
        print("\nPanda's hand pulled over a plate of bumps (a mesh) with Franka-like limits:\n"
              + collision_mesh.mesh_table(mesh))
        from .bench import collision_blocked

        blocked = collision_blocked.blocked(progress=lambda r: print(
            f"  blocked: {r.robot}, seed {r.seed}, {r.method}, jerk limit "
            f"{collision.dash(r.jerk, '.0f')}", flush=True))
        print("\nTargets behind an obstacle, 15 rad/s^2 (and 7,500 rad/s^3), 8 s:\n"
              + collision_blocked.blocked_table(blocked))
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows],
                                "idle_us": {"plain": plain, "limit": idle},
                                "crowded": asdict(crowd),
                                "stream": [asdict(r) for r in stream],
                                "moving": [asdict(r) for r in moving],
                                "mesh": [asdict(r) for r in mesh],
                                "blocked": [asdict(r) for r in blocked]})
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
        print("\nTargets jumping every 0.5 s for 20 s, then one held 8 s, at 1 kHz: Panda with "
              "Franka's acceleration and jerk limits, three more arms with limits of their "
              "class:\n" + limits.franka_table(franka))
        from .bench import whole_body

        posture = whole_body.posture_rows(progress=lambda r: print(
            f"  {r.robot}, {r.method}, posture", flush=True))
        body = whole_body.whole_body_rows(peers=not args.no_peers, progress=lambda r: print(
            f"  TALOS, {r.solver}", flush=True))
        print("\nPosture at the lowest level: max error on an 8 cm pose circle (m and rad), and "
              "the joints' drift over 60 s of a periodic circle (rad):\n"
              + whole_body.posture_table(posture))
        print("\nTALOS reaching with both hands over its held soles, beside pink's weighted "
              "solution of the same tasks:\n" + whole_body.whole_body_table(body))
        _write_json(args.json, {"machine": machine,
                                "tracking": [asdict(r) for r in tracking],
                                "rest": [asdict(r) for r in rest],
                                "saddles": [asdict(r) for r in saddles],
                                "units": [asdict(r) for r in units],
                                "saturating": [asdict(r) for r in saturating],
                                "franka": [asdict(r) for r in franka],
                                "posture": [asdict(r) for r in posture],
                                "whole_body": [asdict(r) for r in body]})
    elif args.kind == "reach":
        from .bench import reach

        def told(row):
            print(f"  {row.robot}, {getattr(row, 'method', 'SJT')}", flush=True)

        random_rows = reach.random_reaches(pairs=args.pairs, peers=not args.no_peers,
                                           progress=told)
        print(f"\nRandom full-range reaches ({args.pairs} pairs a robot, 5 s at 1 kHz):\n"
              + reach.reach_table(random_rows))
        jerk_rows = reach.jerk_grid(trials=args.trials, progress=told)
        print("\nThe jerk grid (SJT; at rest on the target, beside Ruckig's time-optimal "
              "duration):\n" + reach.jerk_table(jerk_rows))
        _write_json(args.json, {"machine": machine,
                                "random": [asdict(r) for r in random_rows],
                                "jerk": [asdict(r) for r in jerk_rows]})
    else:
        from .bench.ik import ik_benchmark, ik_table, many_line, many_throughput

        rows = ik_benchmark(poses=args.poses, peers=not args.no_peers,
                            progress=lambda r: print(f"  {r.robot} {r.method}: "
                                                     f"{100 * r.success:.1f} %", flush=True))
        print(ik_table(rows))
        many = [many_throughput(name, poses=20 * args.poses) for name in ("ur5", "panda")]
        for m in many:
            print(many_line(m), flush=True)
        from .bench.random_robots import random_robots, random_table

        random_rows = random_robots()
        print("\nsolve() with defaults on 200 seeded random robots (1-40 joints, every joint "
              "type), 5 poses each:\n" + random_table(random_rows))
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows],
                                "solve_many": [asdict(m) for m in many],
                                "random_robots": [asdict(r) for r in random_rows]})
    return 0


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``prog: error: message``), exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_int(text: str) -> int:
    """``type=`` for counts: an integer >= 1."""
    return _integer_at_least(text, 1, "a positive integer")


def _integer_at_least(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def at_least(low: int) -> Callable[[str], int]:
    """``type=`` for counts of at least ``low``."""
    def parse(text: str) -> int:
        return _integer_at_least(text, low, f"an integer >= {low}")

    parse.__name__ = f"integer >= {low}"
    return parse


def non_negative_float(text: str) -> float:
    """``type=`` for durations: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return value


def _can_write_in(folder: Path) -> None:
    """Raise ArgumentTypeError unless a file can be created in the existing ``folder``."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise argparse.ArgumentTypeError(
            f"cannot write in {str(folder)!r}: {error.strerror or error}") from None


def _existing_ancestor(path: Path) -> Path:
    """The nearest of ``path``'s parents that exists; it must be a folder."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise argparse.ArgumentTypeError(f"{str(parent)!r} is a file, not a folder")
            return parent
    return Path(path.absolute().anchor)


def output_file(parents: bool) -> Callable[[str], Path]:
    """``type=`` for a file to write: not '', not a folder, in a folder where one can write.

    With ``parents``, missing folders on the way are fine (the command creates them); without,
    the file's folder must exist. An existing file must be writable (it is not changed here).
    """
    def parse(text: str) -> Path:
        if not text.strip():
            raise argparse.ArgumentTypeError("expected a file path, got ''")
        path = Path(text).expanduser()
        if path.is_dir():
            raise argparse.ArgumentTypeError(f"{text!r} is a folder; give a file path")
        if path.exists():
            if not os.access(path, os.W_OK):
                raise argparse.ArgumentTypeError(f"cannot write {text!r}: permission denied")
            folder = path.absolute().parent
        elif parents:
            folder = _existing_ancestor(path)
        else:
            folder = path.absolute().parent
            if not folder.is_dir():
                what = "is a file" if folder.exists() else "does not exist"
                raise argparse.ArgumentTypeError(f"the folder of {text!r} {what}")
        _can_write_in(folder)
        return path

    parse.__name__ = "output file"
    return parse


def output_folder(text: str) -> Path:
    """``type=`` for a folder to write into: not '', not a file; it may not exist yet."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder path, got ''")
    path = Path(text).expanduser()
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a file, not a folder")
    _can_write_in(path if path.is_dir() else _existing_ancestor(path))
    return path


output_folder.__name__ = "output folder"


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


def _grid_step(text: str) -> float:
    """``type=`` for reach's grid spacing: a finite number of metres > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length in m > 0, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a length in m > 0, got {text}")
    return value


def _reach_parser(sub) -> None:
    about = ("reachability map: solve() on a grid of positions x orientations over the "
             "robot's workspace; writes an .npz and a self-contained page")
    p = sub.add_parser("reach", help=about, description=about[0].upper() + about[1:] + ".")
    p.add_argument("robot", help="an example-robot-data robot, e.g. panda, ur5")
    p.add_argument("--frame", default=None, help="the frame placed (default: the robot's "
                   "end effector; needed for robots without one, e.g. baxter)")
    p.add_argument("--step", type=_grid_step, default=0.05,
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
                       "Ruckig), ik (TRAC-IK's "
                       "protocol on five arms), collision (three scenes with and without "
                       "CollisionLimit, and pink's barrier; a moving ball and a mesh, beside "
                       "pink and mink; targets behind an obstacle under acceleration limits).")
    p.add_argument("kind", choices=["speed", "accuracy", "reach", "ik", "collision"],
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
