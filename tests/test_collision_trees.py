"""CollisionLimit on random trees (floating, planar, prismatic, continuous and mimic joints,
spheres and boxes on their links), with self-collision, a ball and acceleration and jerk
limits: where the rows and the smoothness limits cannot all hold, the rows do - every pair
stays at least margin - 1 mm apart (distances by coal, on a limit of the test's own)."""

from __future__ import annotations

import re

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .test_random_urdfs import random_urdf_semantics

MARGIN = 0.01


def _with_geometry(xml: str, rng: np.random.Generator) -> str:
    """The tree of ``xml`` with a sphere or a box on each of its links ``l<k>``."""
    def shape(match):
        if rng.random() < 0.5:
            geometry = f'<sphere radius="{rng.uniform(0.02, 0.06):.4f}"/>'
        else:
            geometry = '<box size="{:.3f} {:.3f} {:.3f}"/>'.format(*rng.uniform(0.03, 0.12, 3))
        return (f'<link name="{match.group(1)}"><collision><geometry>{geometry}</geometry>'
                '</collision></link>')

    return re.sub(r'<link name="(l\d+)"/>', shape, xml)


def _closest_over_a_run(seed: int, method: str) -> float | None:
    """The least distance of any pair over 1 s of targets changing every 0.25 s, at 1 kHz
    with 8 rad/s^2 and 4,000 rad/s^3 on every joint; None where the tree is refused, has no
    moving joint or starts within 15 mm of a pair."""
    rng = np.random.default_rng(seed)
    xml, leaf = random_urdf_semantics(seed, 3 + seed % 8)
    try:
        robot = sjt.Robot.from_urdf(_with_geometry(xml, rng), ee_frame=leaf,
                                    load_visuals=False)
    except sjt.URDFError:  # (mimic limits with no common range: the documented refusal)
        return None
    if robot.nv == 0:
        return None
    q = robot.q0.copy()
    ball = (coal.Sphere(0.03), pin.SE3(np.eye(3), robot.fk(q).translation
                                       + rng.normal(size=3) * 0.1))
    check = sjt.CollisionLimit(robot, [ball], self_collision=True, margin=MARGIN)
    try:
        if min(p.distance for p in check.distances(q)) < 0.015:
            return None
    except ValueError:  # (no pair to check)
        return None
    limit = sjt.CollisionLimit(robot, [ball], self_collision=True, margin=MARGIN)
    solver = sjt.make_solver(method, robot, dt=1e-3, limits=[limit],
                             acceleration_limits=np.full(robot.nv, 8.0),
                             jerk_limits=np.full(robot.nv, 4000.0))
    closest = np.inf
    for k in range(1000):
        if k % 250 == 0:
            target = robot.fk(robot.random_configuration(rng))
        q = solver.step(q, target)
        if k % 5 == 0:
            closest = min(closest, min(p.distance for p in check.distances(q)))
    return closest


@pytest.mark.slow
@pytest.mark.parametrize("method", ["jt", "sjt", "dls"])
def test_the_margin_wins_on_random_trees(method):
    closest = {}
    for seed in range(12):
        d = _closest_over_a_run(seed, method)
        if d is not None:
            closest[seed] = d
    assert len(closest) >= 6
    crossed = {seed: round(1e3 * d, 2) for seed, d in closest.items() if d < MARGIN - 1e-3}
    assert not crossed, f"mm, by seed: {crossed}"
