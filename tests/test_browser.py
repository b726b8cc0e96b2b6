"""Real-browser tests: headless Chromium renders the viewer's pages, the demo's and the live one.

They check what a person would see: that each robot is drawn (hiding it changes the picture)
inside the view and big enough, that the legend, the plots and the controls are on screen with
the methods' colours, that the animation plays on its own, and that the page asks for nothing
outside itself.
"""

import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin.cli import main
from sjt_pin.paper import scenarios
from sjt_pin.viewer import METHOD_COLORS, Viewer
from sjt_pin.viewer.style import DESIRED_COLOR

from .browser import changed_fraction, color_pixels

pytestmark = pytest.mark.slow  # (Chromium pages: minutes; CI runs them with -m slow)

ROBOTS = ("planar3", "ur5", "panda")
WHOLE_BODY = ("talos", "solo12")  # (the demo's whole-body scenes: one SJT run each)
METHODS = ("sjt", "jt", "dls", "jp")
RUN = 4.0  # s, each demo run (the scenarios' circles)


@pytest.fixture(scope="module")
def demo_page(chromium, tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo.html"
    assert main(["demo", "--out", str(out)]) == 0
    page = chromium.open(out.as_uri(), meshes=20, width=1400, height=940)
    yield page
    page.close()


def test_demo_page_loads_nothing_from_outside_and_has_no_script_error(demo_page):
    assert demo_page.errors == []
    assert demo_page.requests and all(u.startswith(("file:", "data:"))
                                      for u in demo_page.requests), demo_page.requests


def test_demo_page_shows_every_robot_inside_the_view_at_a_readable_size(demo_page):
    shown = demo_page.screenshot(time=0.5)
    for robot in ROBOTS + WHOLE_BODY:
        hidden = demo_page.screenshot(time=0.5, hide=robot)
        assert changed_fraction(shown, hidden) > 0.008, f"{robot} is not drawn"
        low, high = projected_box(demo_page, robot)  # canvas from -1 to 1 both ways
        assert np.all(low >= -1.0) and np.all(high <= 1.0), f"{robot} is cut off"
        assert high[1] - low[1] > 0.3, f"{robot} is under 15 % of the view's height"


def projected_box(page, node: str) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest (x, y) of robot ``node``'s vertices on the canvas (-1 to 1 both ways)
    as the page's camera sees them now."""
    low, high = page.evaluate("""(node) => {
        const THREE = MeshCat.THREE;
        const low = [Infinity, Infinity], high = [-Infinity, -Infinity];
        const v = new THREE.Vector3();
        viewer.scene.updateMatrixWorld(true);
        viewer.camera.updateMatrixWorld();
        viewer.scene_tree.find(["meshcat", node, "visuals"]).object.traverse((o) => {
          if (!o.isMesh) return;
          const position = o.geometry.attributes.position;
          for (let i = 0; i < position.count; i++) {
            v.fromBufferAttribute(position, i).applyMatrix4(o.matrixWorld).project(viewer.camera);
            for (const k of [0, 1]) {
              low[k] = Math.min(low[k], v.getComponent(k));
              high[k] = Math.max(high[k], v.getComponent(k));
            }
          }
        });
        return [low, high]; }""", node)
    return np.array(low), np.array(high)


def test_demo_page_tags_name_each_robot_and_the_method_on_screen(demo_page):
    demo_page.pose(time=RUN + 0.5)  # the second run: JT
    view = demo_page.page.locator("#view").bounding_box()
    for robot in ROBOTS:
        tag = demo_page.page.locator(f'.tag[data-robot="{robot}"]')
        assert tag.is_visible()
        box = tag.bounding_box()
        assert view["x"] <= box["x"] and box["x"] + box["width"] <= view["x"] + view["width"]
        assert view["y"] <= box["y"] and box["y"] + box["height"] <= view["y"] + view["height"]
        assert tag.inner_text().split()[-1] == "JT"


def test_demo_page_legend_and_error_plots_are_visible_in_the_methods_colours(demo_page):
    page = demo_page.page
    assert page.locator("h1").inner_text().startswith("sjt-pin demo")
    names = page.locator("ul.methods li").all_inner_texts()
    assert [n.split()[0] for n in names] == [m.upper() for m in METHODS]
    for robot in ROBOTS:
        section = page.locator(f'section.robot[data-robot="{robot}"]')
        section.scroll_into_view_if_needed()
        assert section.locator("h2").inner_text()
        items = section.locator("ul.legend li")
        assert [t.split()[0] for t in items.all_inner_texts()] == [m.upper() for m in METHODS]
        for k, method in enumerate(METHODS):
            swatch = items.nth(k).locator(".swatch")
            assert swatch.is_visible()
            r, g, b = (int(v) for v in swatch.evaluate(
                "e => getComputedStyle(e).backgroundColor").strip("rgb()").split(","))
            assert (r << 16 | g << 8 | b) == METHOD_COLORS[method]
        plot = section.locator("svg.error-plot")
        assert plot.is_visible()
        lines = plot.locator("polyline")
        assert lines.count() == len(METHODS)
        assert all(len(p.split()) >= 100 for p in
                   lines.evaluate_all("ls => ls.map(l => l.getAttribute('points'))"))
        picture = demo_page.image(plot)  # each method's line is drawn, in its colour
        for method in METHODS:
            assert color_pixels(picture, METHOD_COLORS[method]) > 40, (robot, method)


def test_demo_page_panel_fits_a_900_px_window_and_says_why_sjt_is_the_default(demo_page):
    """Everything down to the collision scene's plots fits a 900 px window; the whole-body
    scenes' blocks follow under it (the panel scrolls to them)."""
    page = demo_page.page
    page.set_viewport_size({"width": 1400, "height": 900})
    try:
        page.wait_for_function("() => document.getElementById('panel').clientHeight === 900")
        height, seen = page.evaluate("""() => {
            const panel = document.getElementById("panel");
            const ball = panel.querySelector('section.robot[data-robot="panda_ball"]');
            return [ball.getBoundingClientRect().bottom, panel.clientHeight]; }""")
        assert height <= seen, f"the panel scrolls: {height} px of content in {seen} px"
        text = page.locator("#panel h1 + p").inner_text()
        assert "JP tracks these circles best" in text and "SJT is the default because" in text
        for robot in ROBOTS:  # every robot's plot is on screen without scrolling
            box = page.locator(f'section.robot[data-robot="{robot}"] svg').bounding_box()
            assert box["y"] + box["height"] <= 900, robot
    finally:
        page.set_viewport_size({"width": 1400, "height": 940})


def test_demo_page_plays_on_open_and_its_controls_work(demo_page):
    page = demo_page.page
    page.reload()  # as opened, before other tests paused it
    page.wait_for_function("() => viewer.animator.actions.length > 0")
    time_now = "() => viewer.animator.actions.reduce((m, a) => Math.max(m, a.time), 0)"
    first = page.evaluate(time_now)
    # it plays without a click (waited for, not timed: a loaded machine draws fewer frames)
    page.wait_for_function(f"() => ({time_now})() > {first} + 0.2", timeout=15_000)
    play = page.locator("#play")
    assert play.is_visible() and play.inner_text() == "Pause"
    play.click()
    assert play.inner_text() == "Play" and not page.evaluate("() => viewer.animator.playing")
    paused = page.evaluate(time_now)
    page.wait_for_timeout(300)
    assert page.evaluate(time_now) == paused
    page.locator("#time").fill(str(2 * RUN + 1.0))  # the third run: DLS
    assert abs(page.evaluate(time_now) - (2 * RUN + 1.0)) < 0.05
    for robot in ROBOTS:  # highlighted in each robot's legend by the next frame
        page.wait_for_function(f"""() => {{
            const on = document.querySelectorAll('[data-robot="{robot}"] li.playing');
            return on.length === 1 && on[0].dataset.method === "dls"; }}""", timeout=5000)


@pytest.fixture(scope="module")
def panda_html(tmp_path_factory):
    sc = scenarios.scenario("panda")
    log = sjt.track(sjt.SJTSolver(sc.robot, dt=1e-3, task=sc.task), sc.trajectory, sc.q0)
    path = tmp_path_factory.mktemp("html") / "panda.html"
    with Viewer(sc.robot, name="panda", live=False) as viewer:
        viewer.animate(log)
        viewer.save_html(path)
    return path, len(sc.robot.visual_model.geometryObjects)


def test_static_panda_animation_draws_the_robot_and_moves(chromium, panda_html):
    path, geometries = panda_html
    page = chromium.open(path.as_uri(), meshes=geometries)
    try:
        start = page.screenshot(time=0.0)
        empty = page.screenshot(time=0.0, hide="panda")
        later = page.screenshot(time=1.0)
    finally:
        page.close()
    assert changed_fraction(start, empty) > 0.01  # the robot covers over 1 % of the canvas
    assert changed_fraction(start, later) > 0.002  # and it moved between t = 0 and t = 1 s


def test_live_viewer_page_shows_the_robot(chromium):
    robot = sjt.Robot.from_example("ur5")
    with Viewer(robot, name="ur5") as viewer:
        viewer.show(np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2]))
        viewer.set_camera([1.0, 0.6, 0.5])
        page = chromium.open(viewer.url, meshes=len(robot.visual_model.geometryObjects))
        try:
            shown = page.screenshot()
            empty = page.screenshot(hide="ur5")
        finally:
            page.close()
    assert changed_fraction(shown, empty) > 0.01


README_VIEWER = """
import numpy as np
import sjt_pin as sjt
from sjt_pin.viewer import Viewer

robot = sjt.Robot.from_example("ur5")
q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
start = robot.fk(q)
circle = sjt.Circle(start.translation - [0.1, 0, 0], 0.1, duration=2.0, rotation=start.rotation)
logs = {name: sjt.track(sjt.make_solver(name, robot), circle, q) for name in ["sjt", "jt"]}

with Viewer(robot, live=False, label="UR5") as viewer:  # live=True: also a meshcat server
    viewer.compare(logs)                                # one run after the other, in colour
    viewer.draw_frame(start, "start")
    viewer.save_html("ur5_circle.html", title="UR5 on a 10 cm circle")
"""


def test_readme_viewer_snippet_is_the_docs():
    """The viewer page of the site shows this snippet (it was the README's)."""
    from pathlib import Path

    page = (Path(__file__).parents[1] / "docs" / "viewer.md").read_text(encoding="utf-8")
    assert README_VIEWER.strip() in page


@pytest.mark.parametrize("source, size", [("readme", (1400, 900)), ("readme", (800, 600)),
                                          ("demo ur5", (1400, 900))])
def test_one_robot_page_keeps_the_robot_inside_the_view_for_the_whole_animation(
        chromium, tmp_path, monkeypatch, source, size):
    monkeypatch.chdir(tmp_path)
    if source == "readme":  # the README's Viewer snippet, as written
        exec(compile(README_VIEWER, "README", "exec"), {})
        path, node, end = tmp_path / "ur5_circle.html", "robot", 4.0
    else:
        path, node, end = tmp_path / "demo.html", "ur5", 4 * RUN
        assert main(["demo", "--robot", "ur5", "--out", str(path)]) == 0
    page = chromium.open(path.as_uri(), meshes=10, width=size[0], height=size[1])
    try:
        assert page.errors == []
        for time in np.linspace(0.0, end, 9):
            page.pose(time)
            low, high = projected_box(page, node)
            assert np.all(low >= -0.98) and np.all(high <= 0.98), (time, low, high)
            assert high[1] - low[1] > 0.5, "the robot is under a quarter of the view's height"
        gui = page.page.locator(".dg.main").first.bounding_box()  # meshcat's "Open Controls"
        view = page.page.locator("#meshcat-pane canvas").bounding_box()
        assert gui["x"] >= view["x"] + view["width"] or gui["y"] >= view["y"] + view["height"]
    finally:
        page.close()


def test_desired_dots_leave_the_path_followed_visible_on_a_short_line(chromium, tmp_path):
    robot = sjt.Robot.from_example("ur5")
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    start = robot.fk(q)
    line = sjt.Line(start.translation, start.translation + [0.0, 0.2, 0.0], duration=1.0,
                    rotation=start.rotation)  # a 20 cm line
    log = sjt.track(sjt.make_solver("sjt", robot), line, q)
    with Viewer(robot, live=False) as viewer:
        viewer.animate(log)
        viewer.save_html(tmp_path / "line.html")
    page = chromium.open((tmp_path / "line.html").as_uri(), meshes=10, width=1000, height=700)
    try:
        show = """([node, on]) => {
            viewer.scene_tree.find(["meshcat", "robot", node]).object.visible = on; }"""
        page.evaluate(show, ["visuals", False])  # the robot would hide part of the line
        seen, dark = {}, {}
        for dots in (True, False):
            page.evaluate(show, ["paths", dots])
            image = page.screenshot(time=0.5)
            seen[dots] = color_pixels(image, METHOD_COLORS["sjt"])
            dark[dots] = color_pixels(image, DESIRED_COLOR)
    finally:
        page.close()
    assert seen[False] > 80  # the path followed: a line of that many pixels
    assert seen[True] >= 0.6 * seen[False], seen  # the dots hide at most 40 % of it
    # dots, not a bar: they cover less than 3 pixels per pixel of the line's length
    assert dark[True] - dark[False] < 3 * seen[False], (dark, seen)


EVIL = "<!--<script>"  # opens an HTML comment, then a script, inside a <script> element


def test_page_of_names_that_open_comments_and_scripts_still_shows_its_view(chromium, tmp_path):
    x = EVIL.replace("<", "&lt;").replace(">", "&gt;")  # the same names, written in XML
    robot = sjt.Robot.from_urdf(f"""<robot name="{x}">
      <link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
      <link name="{x}"><visual><origin xyz="0.25 0 0"/>
        <geometry><box size="0.5 0.05 0.05"/></geometry></visual></link>
      <link name="tip"/>
      <joint name="j{x}" type="revolute"><parent link="base"/><child link="{x}"/>
        <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="2" effort="1"/></joint>
      <joint name="fixed" type="fixed"><parent link="{x}"/><child link="tip"/>
        <origin xyz="0.5 0 0"/></joint>
    </robot>""", ee_frame="tip")
    assert robot.name == EVIL
    start = robot.fk(np.zeros(1)).translation
    circle = sjt.Circle(start - [0.1, 0, 0], 0.1, duration=1.0)
    log = sjt.track(sjt.SJTSolver(robot, task=sjt.PositionTask(axes="xy")), circle, np.zeros(1))
    with Viewer(robot, live=False, name=EVIL, label=EVIL + "</script>") as viewer:
        viewer.compare({EVIL + '"</script>': log})
        path = viewer.save_html(tmp_path / "evil.html", title=EVIL, description=EVIL)
    page = chromium.open(path.as_uri(), meshes=2)  # waits for the robot's two meshes
    try:
        assert page.errors == []
        assert page.page.locator("h1").inner_text() == EVIL
        assert page.page.locator("section.robot h2").inner_text() == EVIL + "</script>"
        assert page.page.locator(".tag b").inner_text() == EVIL + "</script>"
        assert page.page.locator("section.robot li b").inner_text() == (EVIL + '"</script>').upper()
        shown = page.screenshot(time=0.2)
        hidden = page.screenshot(time=0.2, hide=EVIL)
        assert changed_fraction(shown, hidden) > 0.002  # the robot is drawn
    finally:
        page.close()


def test_static_cell_shows_the_scene_in_its_sandboxed_iframe(chromium, tmp_path):
    """What a notebook keeps: the page in an iframe's srcdoc, scripts only, no server."""
    robot = sjt.Robot.from_example("ur5")
    with Viewer(robot, live=False) as viewer:
        viewer.show(np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2]))
        cell = viewer.static_cell(height=420)
    (tmp_path / "notebook.html").write_text(f"<!DOCTYPE html><body>{cell.data}</body>",
                                            encoding="utf-8")
    page = chromium.browser.new_page(viewport={"width": 900, "height": 600})
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        page.goto((tmp_path / "notebook.html").as_uri(), wait_until="load", timeout=120_000)
        frame = page.frames[1]
        frame.wait_for_function(
            "() => { let n = 0; viewer.scene.traverse(o => { if (o.isMesh) n++; }); "
            f"return n >= {len(robot.visual_model.geometryObjects)}; }}", timeout=120_000)
        assert errors == []
        assert frame.locator("canvas").first.bounding_box()["height"] > 300
    finally:
        page.close()
