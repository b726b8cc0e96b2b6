"""``sjt-pin bench KIND``: runs one benchmark of :mod:`sjt_pin.bench`, prints its tables and
writes its JSON.

:mod:`sjt_pin.cli` parses the command line and imports this module only when the command runs;
each benchmark's module is imported here only when its ``KIND`` is asked for (:mod:`.speed`
always: it says which machine ran).
"""

from __future__ import annotations

import argparse


def _write_json(path: str | None, payload) -> None:
    if path:
        import json

        with open(path, "w") as f:
            json.dump(payload, f, indent=1, default=float)
        print(f"wrote {path}")


def bench(args: argparse.Namespace) -> int:
    """``sjt-pin bench speed|accuracy|reach|settle|ik|collision``: the tables of the documentation's
    Benchmarks page (docs/benchmarks.md)."""
    from dataclasses import asdict

    from . import speed as speed_bench

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
        from . import collision, collision_peers

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
        from . import collision_stream

        stream = collision_stream.stream()
        print("\nxArm7 with self-collision beside 10 rad/s^2 and 5,000 rad/s^3, targets jumping "
              "every 0.5 s:\n" + collision_stream.stream_table(stream))
        from . import collision_mesh, collision_mink, collision_moving, collision_peers

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
        ring = [collision_mesh.through_ring(kept) for kept in ("hull", "parts", "mesh")]
        print("\nPanda's hand sent through a ring (a mesh), each way of keeping it:\n"
              + collision_mesh.mesh_table(ring))
        from . import collision_blocked

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
                                "ring": [asdict(r) for r in ring],
                                "blocked": [asdict(r) for r in blocked]})
    elif args.kind == "accuracy":
        from . import accuracy

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
        from . import limits

        def shown(row):
            print(f"  {row.path}, {row.method}", flush=True)

        saturating = limits.saturating(progress=shown)
        franka = limits.franka(progress=shown)
        print("\nOne joint saturates (TIAGo's torso lift, 0.07 m/s), every limit on:\n"
              + limits.saturating_table(saturating))
        print("\nTargets jumping every 0.5 s for 20 s, then one held 8 s, at 1 kHz: Panda with "
              "Franka's acceleration and jerk limits, three more arms with limits of their "
              "class:\n" + limits.franka_table(franka))
        from . import whole_body

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
        from . import reach

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
    elif args.kind == "settle":
        from . import settle

        rows = settle.settle(seeds=args.seeds, progress=lambda r: print(
            f"  {r.robot}, seed {r.seed}, {r.method}: {r.state}", flush=True))
        print(f"\nRest and swing ({args.seeds} draws an arm, four methods; random starts against "
              "the ranges, random acceleration and jerk limits):\n" + settle.settle_table(rows))
        _write_json(args.json, {"machine": machine, "arms": settle.settle_summary(rows),
                                "unsettled": [asdict(r) | {"state": r.state} for r in rows
                                              if r.state != "rest"]})
    else:
        from .ik import ik_benchmark, ik_table, many_line, many_throughput

        rows = ik_benchmark(poses=args.poses, peers=not args.no_peers,
                            progress=lambda r: print(f"  {r.robot} {r.method}: "
                                                     f"{100 * r.success:.1f} %", flush=True))
        print(ik_table(rows))
        many = [many_throughput(name, poses=20 * args.poses) for name in ("ur5", "panda")]
        for m in many:
            print(many_line(m), flush=True)
        from .random_robots import random_robots, random_table

        random_rows = random_robots()
        print("\nsolve() with defaults on 200 seeded random robots (1-40 joints, every joint "
              "type), 5 poses each:\n" + random_table(random_rows))
        _write_json(args.json, {"machine": machine, "rows": [asdict(r) for r in rows],
                                "solve_many": [asdict(m) for m in many],
                                "random_robots": [asdict(r) for r in random_rows]})
    return 0
