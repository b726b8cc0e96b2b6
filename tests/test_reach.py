"""The reachability map: its sampling (the reach bound, the grid, the rotations), that every
pose it calls reached is reached within the limits, that it repeats however it runs and resumes
from a partial file, the command, and its page in a real browser (robot, cloud, legend)."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import reach
from sjt_pin.cli import main
from sjt_pin.limits import Limit
from sjt_pin.viewer import reachmap

from .browser import changed_fraction, color_pixels

STEP, ORIENTATIONS = 0.25, 3  # a coarse map: 171 points x 3 orientations on Panda
POINTS = 171


@pytest.fixture(scope="module")
def small_map(panda):
    return reach.reachability(panda, STEP, ORIENTATIONS, processes=1, progress=False)


@pytest.mark.parametrize("name", ["panda", "ur5", "kinova"])
def test_the_reach_bound_holds_for_random_configurations(name):
    robot = sjt.Robot.from_example(name)
    centre, radius = reach.reach_sphere(robot)
    rng = np.random.default_rng(0)
    distances = [np.linalg.norm(robot.fk(robot.random_configuration(rng)).translation - centre)
                 for _ in range(2000)]
    assert max(distances) <= radius
    assert max(distances) > 0.97 * radius  # a bound, and a tight one


def test_the_grid_and_the_rotations():
    centre = np.array([0.1, -0.2, 0.3])
    points = reach.grid(centre, 0.5, 0.1)
    assert np.all(np.linalg.norm(points - centre, axis=1) <= 0.5 + 1e-12)
    assert any(np.allclose(p, centre) for p in points)
    steps = np.abs(np.diff(points, axis=0))
    assert np.allclose(np.min(steps[steps > 1e-9]), 0.1)
    assert len(points) == sum(1 for i in range(-5, 6) for j in range(-5, 6) for k in range(-5, 6)
                              if i * i + j * j + k * k <= 25)
    q = reach.spread_rotations(20)
    np.testing.assert_array_equal(q, reach.spread_rotations(20))  # the same on every run
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    angles = 2 * np.arccos(np.clip(np.abs(q @ q.T), 0, 1)) + 10 * np.eye(20)
    assert np.degrees(angles.min()) > 40  # evenly spread: 20 random ones come far closer
    with pytest.raises(ValueError, match="orientations must be an integer >= 1"):
        reach.spread_rotations(0)
    with pytest.raises(ValueError, match="step must be"):
        reach.grid(centre, 0.5, -0.1)


def test_a_reached_pose_is_reached_within_the_limits(panda, small_map):
    m = small_map
    assert m.complete and m.positions.shape == (POINTS, 3)
    assert m.reached.shape == (POINTS, ORIENTATIONS)
    assert 0.2 < m.reached.mean() < 0.8  # the sphere's rim is out of reach, its middle not
    for i, o in zip(*np.nonzero(m.reached), strict=True):
        x, y, z, w = m.orientations[o]
        target = pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), m.positions[i])
        q = m.q[i, o]
        assert np.linalg.norm(pin.log6(panda.fk(q).actInv(target)).vector) < 1e-6
        assert np.all(q >= panda.lower_limits) and np.all(q <= panda.upper_limits)


def test_the_map_is_the_same_in_a_pool_and_after_an_interruption(panda, small_map, tmp_path):
    pooled = reach.reachability(panda, STEP, ORIENTATIONS, processes=2, progress=False)
    np.testing.assert_array_equal(pooled.reached, small_map.reached)
    np.testing.assert_array_equal(pooled.q, small_map.q)
    # a partial file, as an interrupted run leaves it, resumes to the same map
    half = reach.ReachMap.load(small_map.save(tmp_path / "map.npz"))
    half.done = 200
    flat = half.reached.reshape(-1)
    flat[200:] = False
    half.q.reshape(-1, panda.nq)[200:] = np.nan
    half.save(tmp_path / "map.npz")
    resumed = reach.reachability(panda, STEP, ORIENTATIONS, out=tmp_path / "map.npz",
                                 progress=False)
    assert resumed.complete
    np.testing.assert_array_equal(resumed.reached, small_map.reached)
    np.testing.assert_array_equal(resumed.q, small_map.q)
    assert reach.ReachMap.load(tmp_path / "map.npz").complete
    with pytest.raises(ValueError, match="holds a map with other settings"):
        reach.reachability(panda, STEP, ORIENTATIONS + 1, out=tmp_path / "map.npz",
                           progress=False)


class Floor(Limit):
    """The hand's origin stays above z_min (m)."""

    name = "floor"

    def __init__(self, robot, z_min):
        self.frame_id, self.z_min = robot.frame_id(robot.ee_frame), z_min

    def rows(self, kinematics, motion):
        z = kinematics.placement(self.frame_id).translation[2]
        J_z = kinematics.world_aligned_jacobian(self.frame_id)[2]
        return -J_z[None, :], np.array([0.5 * (z - self.z_min) / motion.dt])


def test_the_map_honours_limits(panda):
    m = reach.reachability(panda, 0.4, 2, limits=[Floor(panda, 0.3)], processes=1,
                           progress=False, budget=200)
    low = m.positions[:, 2] < 0.3 - 1e-9
    assert low.any() and not m.reached[low].any()
    assert m.reached[~low].any()
    free = reach.reachability(panda, 0.4, 2, processes=1, progress=False, budget=200)
    assert free.reached[low].any()  # the floor, not the grid, keeps them out


def test_the_command_and_its_page(chromium, tmp_path, capsys):
    out, html = tmp_path / "panda.npz", tmp_path / "panda.html"
    assert main(["reach", "panda", "--step", str(STEP), "--orientations", str(ORIENTATIONS),
                 "--processes", "1", "--out", str(out), "--html", str(html), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert f"{POINTS} grid points" in printed and f"{POINTS * ORIENTATIONS} poses" in printed
    assert " s of solving" in printed
    saved = reach.ReachMap.load(out)
    assert saved.complete and saved.reached.shape == (POINTS, ORIENTATIONS)
    page = chromium.open(html.as_uri(), meshes=10, width=1400, height=940)
    try:
        assert page.errors == []
        assert all(u.startswith(("file:", "data:")) for u in page.requests)
        shown = page.screenshot()
        assert changed_fraction(shown, page.screenshot(hide="robot")) > 0.01  # the robot
        cloud = sum(color_pixels(shown, int(c), tol=30) for c in
                    ((reachmap.SCALE * 255).round().astype(int) @ [1 << 16, 1 << 8, 1]))
        page.evaluate("() => { viewer.scene_tree.find(['meshcat', 'reach']).object.visible = "
                      "false; viewer.render(); }")
        hidden = page.screenshot()
        assert changed_fraction(shown, hidden) > 0.01  # the cloud
        assert cloud > 2000  # ... in the scale's colours
        legend = page.page.locator(f".{reachmap.LEGEND_CLASS}")
        assert legend.is_visible()
        box, view = legend.bounding_box(), page.page.viewport_size
        assert box["y"] + box["height"] <= view["height"] and box["width"] > 200
        bar = page.image(legend.locator(".bar"))
        assert color_pixels(bar, 0x440154, 20) > 20 and color_pixels(bar, 0xfde725, 20) > 20
        assert "Fraction of orientations reached" in legend.inner_text()
    finally:
        page.close()


def test_the_command_names_an_unknown_frame(tmp_path, capsys):
    """A frame the robot does not have: one line and exit code 2, before any work (Baxter,
    which names no end effector, now gets the tip of its longest chain by default)."""
    out = tmp_path / "baxter.npz"
    assert main(["reach", "baxter", "--frame", "left_hnad", "--step", "0.4", "--orientations",
                 "1", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "frame 'left_hnad' not found in baxter" in err and "'left_hand_link'" in err
    assert not out.exists()
