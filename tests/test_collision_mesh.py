"""CollisionLimit beside a mesh obstacle: kept as its convex hull by default, as the robot's own
meshes are, so that its closest points move continuously and the acceleration and jerk limits
hold beside it as beside a primitive (a mesh's closest points jump from triangle to
triangle); ``convex=False`` keeps it as given."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from sjt_pin.bench import collision_mesh as bench
from sjt_pin.limits import CollisionLimit
from sjt_pin.limits.collision import CollisionError
from sjt_pin.limits.collision_geometry import coal_mesh

MARGIN = 0.01


def test_a_mesh_obstacle_is_kept_as_its_hull_and_copied_as_given(panda):
    plate = bench.bumpy_plate()
    pose = pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.1]))
    for convex in (True, False):
        limit = CollisionLimit(panda, [(plate, pose)], convex=convex)
        assert limit.obstacles[0][0] is plate  # (what was given, for copies and the user)
        kept = limit.geometry.geometryObjects[limit.n_robot].geometry
        assert isinstance(kept, coal.ConvexBase) == convex
    hull = CollisionLimit(panda, [(plate, pose)])
    mesh = CollisionLimit(panda, [(plate, pose)], convex=False)
    # the hull contains the mesh: never farther from the robot than the mesh
    q = panda.q0.copy()
    for a, b in zip(hull.distances(q), mesh.distances(q), strict=True):
        assert a.distance <= b.distance + 1e-9


def test_a_flat_mesh_obstacle_is_refused_a_hull_by_name(panda):
    """A mesh whose points span no volume (a flat sheet) has no convex hull; coal's qhull of it
    crashes the process, so the limit refuses it first, naming it and the way out."""
    vertices, triangles = bench.plate_grid()
    vertices[:, 2] = 0.0
    sheet = coal_mesh(vertices, triangles)
    pose = pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.1]))
    with pytest.raises(CollisionError, match=r"obstacle 0.*span no volume.*convex=False"):
        CollisionLimit(panda, [(sheet, pose)])
    CollisionLimit(panda, [(sheet, pose)], convex=False)  # (kept as given: no hull needed)


def test_convex_robot_keeps_the_mesh_obstacles_as_given(panda):
    """``convex="robot"``: the robot's meshes are hulls (as with ``True``), a mesh obstacle is
    kept as given (as with ``False``), a primitive obstacle as it is; each link's distance to
    the mesh lies between the hulls' and the meshes'. Anything else is refused."""
    plate = bench.bumpy_plate()
    pose = pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.1]))
    box = coal.Box(0.1, 0.1, 0.1)
    both = CollisionLimit(panda, [(plate, pose), (box, pose)])
    robot = CollisionLimit(panda, [(plate, pose), (box, pose)], convex="robot")
    none = CollisionLimit(panda, [(plate, pose), (box, pose)], convex=False)
    geometry = robot.geometry.geometryObjects
    for g in range(robot.n_robot):
        assert type(geometry[g].geometry) is type(both.geometry.geometryObjects[g].geometry)
    assert not isinstance(geometry[robot.n_robot].geometry, coal.ConvexBase)
    assert isinstance(geometry[robot.n_robot + 1].geometry, coal.Box)
    q = panda.q0.copy()
    # each link's distance to the plate: hull to hull <= hull to mesh <= mesh to mesh
    hulls, meshes = ({(p.a, p.b): p.distance for p in limit.distances(q)}
                     for limit in (both, none))
    checked = 0
    for p in robot.distances(q):
        if p.b == "obstacle_0":
            assert hulls[(p.a, p.b)] - 1e-9 <= p.distance <= meshes[(p.a, p.b)] + 1e-9
            checked += 1
    assert checked > 5
    for bad in ("mesh", None, 1, "Robot"):
        with pytest.raises(ValueError, match="convex must be"):
            CollisionLimit(panda, [(plate, pose)], convex=bad)


@pytest.mark.parametrize("shape, error", [
    (coal.Sphere(0.0), "zero or non-finite size"), (coal.Box(0.0, 0.0, 0.0), "zero"),
    (coal.Sphere(np.inf), "non-finite")])
def test_degenerate_obstacles_are_refused(panda, shape, error):
    with pytest.raises(CollisionError, match=error):
        CollisionLimit(panda, [(shape, pin.SE3(np.eye(3), np.ones(3)))])


@pytest.mark.parametrize("pose, error", [
    (pin.SE3(np.eye(3), np.array([np.nan, 0.0, 0.0])), "not finite"),
    (pin.SE3(2.0 * np.eye(3), np.ones(3)), "not a rigid motion"),
    (pin.SE3(np.diag([1.0, 1.0, -1.0]), np.ones(3)), "not a rigid motion")])
def test_bad_obstacle_poses_are_refused(panda, pose, error):
    with pytest.raises(ValueError, match=error):
        CollisionLimit(panda, [(coal.Sphere(0.05), pose)])
    limit = CollisionLimit(panda, [(coal.Sphere(0.05), pin.SE3(np.eye(3), np.ones(3)))])
    with pytest.raises(ValueError, match=error):
        limit.move(0, pose)


def test_a_pull_over_a_bumpy_mesh_keeps_the_margin_and_the_smoothness_limits():
    """Panda's hand pulled over a plate of bumps with Franka-like acceleration and jerk
    limits (``sjt_pin.bench.collision_mesh``): with the default hull the margin holds on the
    mesh itself and no step goes above a limit. (Where the hand met the hull while still
    speeding up toward it, the rows once asked 1.01-1.10x the acceleration and 1.05-1.26x the
    jerk limit of one step, depending on coal's state; kept as a mesh, ``convex=False``, the
    same pull breaks them, every such step named in ``limit_conflicts``.)"""
    hull = bench.pull(convex=True)
    assert hull.closest >= MARGIN - 1e-3
    assert hull.unreported == 0
    assert max(hull.acceleration_ratio, hull.jerk_ratio) <= 1.01
    assert hull.conflicts == 0


def _ball_at(robot, q, gap: float):
    """A 5 cm ball beside the hand, ``gap`` (m) from the robot (bisection on its offset)."""
    hand = robot.fk(q).translation
    lo, hi = 0.0, 0.5
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        ball = (coal.Sphere(0.05), pin.SE3(np.eye(3), hand + np.array([0.0, mid, 0.0])))
        try:
            d = min(p.distance for p in CollisionLimit(robot, [ball]).distances(q))
        except CollisionError:
            d = -1.0
        lo, hi = (mid, hi) if d < gap else (lo, mid)
    return ball


@pytest.mark.parametrize("smooth", [False, True])
def test_a_start_inside_the_margin_is_said_and_left_within_the_limits(panda, smooth):
    """A start 4 mm from a ball (margin 10 mm): one warning naming the pair and the distance,
    then the arm moves out, every speed (and acceleration and jerk) within 1.01x its limit,
    and ends outside margin - 1 mm."""
    import warnings

    import sjt_pin as sjt
    from sjt_pin.bench.collision_moving import franka_like

    q = panda.q0.copy()
    ball = _ball_at(panda, q, 0.004)
    limit = CollisionLimit(panda, [ball], margin=MARGIN)
    options = {}
    if smooth:
        accelerations, jerks = franka_like(panda.nv)
        options = dict(acceleration_limits=accelerations, jerk_limits=jerks)
    solver = sjt.make_solver("sjt", panda, dt=1e-3, limits=[limit], **options)
    start = panda.fk(q)
    qs = [q]
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for _ in range(1500):
            q = solver.step(q, start)
            qs.append(q)
    inside = [w for w in said if "inside the 10 mm margin" in str(w.message)]
    assert len(inside) == 1 and "obstacle_0 at 4.0 mm" in str(inside[0].message)
    assert min(p.distance for p in limit.distances(q)) >= MARGIN - 1e-3
    v = np.diff(np.array(qs), axis=0) / 1e-3
    assert np.max(np.abs(v) / panda.velocity_limits) <= 1.01
    if smooth:
        a = np.diff(np.vstack([np.zeros((1, panda.nv)), v]), axis=0) / 1e-3
        j = np.diff(np.vstack([np.zeros((1, panda.nv)), a]), axis=0) / 1e-3
        assert np.max(np.abs(a) / options["acceleration_limits"]) <= 1.01
        assert np.max(np.abs(j) / options["jerk_limits"]) <= 1.01


@pytest.mark.parametrize("options, error, match", [
    ({"margin": "1cm"}, TypeError, "margin must be a number"),
    ({"gain": None}, TypeError, "gain must be a number"),
    ({"influence": True}, TypeError, "influence must be a number"),
    ({"margin": -0.01}, ValueError, "margin must be a finite distance"),
    ({"margin": np.nan}, ValueError, "margin must be a finite distance"),
    ({"influence": np.inf}, ValueError, "influence must be finite"),
    ({"gain": 0.0}, ValueError, r"gain must be in \(0, 1\]"),
    ({"witnesses": -1}, ValueError, "witnesses must be an int in"),
    ({"witnesses": 10**9}, ValueError, "witnesses must be an int in"),
    ({"witnesses": 2.0}, ValueError, "witnesses must be an int in")])
def test_options_are_checked_by_name(panda, options, error, match):
    with pytest.raises(error, match=match):
        CollisionLimit(panda, **options)
