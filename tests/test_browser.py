"""Real-browser tests: headless Chromium renders the viewer's static HTML and its live page."""

import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin import scenarios
from sjt_pin.cli import main
from sjt_pin.viewer import Viewer

from .browser import Page, changed_fraction, require_chromium


@pytest.fixture(scope="module", autouse=True)
def chromium():
    return require_chromium()


@pytest.fixture(scope="module")
def panda_html(tmp_path_factory):
    sc = scenarios.scenario("panda")
    log = sjt.track(sjt.SJTSolver(sc.robot, dt=1e-3, task=sc.task), sc.trajectory, sc.q0)
    path = tmp_path_factory.mktemp("html") / "panda.html"
    with Viewer(sc.robot, name="panda") as viewer:
        viewer.animate(log)
        viewer.save_html(path)
    return path, len(sc.robot.visual_model.geometryObjects)


def test_static_panda_animation_draws_the_robot_and_moves(panda_html):
    path, geometries = panda_html
    assert path.stat().st_size > 5e6  # the Panda meshes are embedded
    page = Page(path.as_uri(), meshes=geometries)
    try:
        start = page.screenshot(time=0.0)
        empty = page.screenshot(time=0.0, hide="panda")
        later = page.screenshot(time=1.0)
    finally:
        page.close()
    assert changed_fraction(start, empty) > 0.01  # the robot covers over 1 % of the canvas
    assert changed_fraction(start, later) > 0.002  # and it moved between t = 0 and t = 1 s


def test_live_viewer_page_shows_the_robot():
    robot = sjt.Robot.from_example("ur5")
    with Viewer(robot, name="ur5") as viewer:
        viewer.show(np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2]))
        viewer.set_camera([1.0, 0.6, 0.5])
        page = Page(viewer.url, meshes=len(robot.visual_model.geometryObjects))
        try:
            shown = page.screenshot()
            empty = page.screenshot(hide="ur5")
        finally:
            page.close()
    assert changed_fraction(shown, empty) > 0.01


def test_demo_writes_an_animation_that_renders(tmp_path, capsys):
    out = tmp_path / "demo.html"
    assert main(["demo", "--robot", "planar3", "--method", "sjt", "jt", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "http://127.0.0.1:" in printed and str(out.resolve()) in printed
    page = Page(out.as_uri(), meshes=8)
    try:
        first, second = page.screenshot(time=0.5), page.screenshot(time=6.0)  # SJT run, JT run
        empty = page.screenshot(time=0.5, hide="planar3")
    finally:
        page.close()
    assert changed_fraction(first, empty) > 0.005
    assert changed_fraction(first, second) > 0.001
