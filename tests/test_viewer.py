"""The meshcat viewer: loopback-only server that dies with its parent, scene API, the page's
scene, meshes and plots."""

import base64
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import coal
import meshcat
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import pytest
import trimesh
import umsgpack

import sjt_pin as sjt
from sjt_pin.paper import scenarios
from sjt_pin.viewer import Viewer
from sjt_pin.viewer.meshes import visual_parts
from sjt_pin.viewer.plot import Series, error_plot
from sjt_pin.viewer.scene import SceneRecord
from sjt_pin.viewer.server import LoopbackServer


def listening_addresses(pid: int) -> list[tuple[str, int]]:
    """(address, port) of the TCP sockets process ``pid`` listens on, from /proc."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = []
    for table, size in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "0A" or fields[9] not in inodes:  # 0A: LISTEN
                continue
            address, port = fields[1].split(":")
            raw = bytes.fromhex(address)
            if size == 8:
                host = ".".join(str(b) for b in raw[::-1])
            else:
                words = [raw[i:i + 4][::-1] for i in range(0, 16, 4)]
                host = bytes(b"".join(words)).hex()
            found.append((host, int(port, 16)))
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "State:\tZ" not in state


def wait_until_gone(pid: int, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not alive(pid):
            return True
        time.sleep(0.1)
    return False


def test_server_listens_on_loopback_only_and_stops_on_close():
    server = LoopbackServer()
    sockets = listening_addresses(server.pid)
    assert len(sockets) == 2  # ZMQ and web ports
    assert all(host == "127.0.0.1" for host, _ in sockets), sockets
    assert str(sockets[0][1]) in server.zmq_url + server.web_url
    server.close()
    assert wait_until_gone(server.pid)


def test_server_dies_with_a_sigkilled_parent():
    code = ("from sjt_pin.viewer.server import LoopbackServer; import time; "
            "s = LoopbackServer(); print(s.pid, flush=True); time.sleep(60)")
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    server_pid = int(parent.stdout.readline())
    assert alive(server_pid)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    assert wait_until_gone(server_pid), "the meshcat server outlived its killed parent"


@pytest.fixture(scope="module")
def planar_viewer():
    robot = sjt.Robot.planar3()
    with Viewer(robot) as viewer:
        yield viewer, robot


def test_scene_api_and_static_html(planar_viewer, tmp_path):
    viewer, robot = planar_viewer
    assert viewer.url.startswith("http://127.0.0.1:")
    viewer.show(np.deg2rad([60.0, 45.0, 30.0]))
    viewer.draw_path(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.0]]), "red", "line")
    viewer.draw_points(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.0]]), "black", "dots")
    viewer.draw_frame(robot.fk(robot.q0), "ee")
    J = robot.jacobian(robot.q0, reference=pin.LOCAL_WORLD_ALIGNED)[:2]
    viewer.draw_ellipsoid([1.18, 0, 0], J.T[:2], "jt", color=(0.8, 0.1, 0.1))
    path = viewer.save_html(tmp_path / "scene.html", title="A <planar> arm")
    html = path.read_text()
    assert path.stat().st_size > 300_000  # meshcat's viewer code is embedded: works offline
    assert "new MeshCat.Viewer" in html and "<h1>A &lt;planar&gt; arm</h1>" in html
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", html)  # nothing to fetch


def test_bad_drawing_arguments(planar_viewer):
    viewer, _ = planar_viewer
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        viewer.draw_path(np.zeros((3, 5)))  # (3, N) is the wrong way round
    with pytest.raises(ValueError, match="contains NaN"):
        viewer.draw_path(np.full((4, 3), np.nan))
    with pytest.raises(ValueError, match="contains NaN"):
        viewer.draw_points(np.full((4, 3), np.inf))
    with pytest.raises(ValueError, match="robot must be one of"):
        viewer.show(np.zeros(3), robot="panda")
    with pytest.raises(ValueError, match=r"q must have shape \(3,\)"):
        viewer.show(np.zeros(4))
    with pytest.raises(ValueError, match="2 or 3 rows"):
        viewer.draw_ellipsoid([0, 0, 0], np.eye(4))
    with pytest.raises(ValueError, match="color must be one of"):
        viewer.draw_path(np.zeros((2, 3)), color="mauve")
    with pytest.raises(ValueError, match="offset must be"):
        viewer.add_robot(sjt.Robot.planar3(), "other", offset=np.zeros(2))


def children() -> set[int]:
    """Process ids of this process' children, from /proc."""
    return {int(pid) for task in Path("/proc/self/task").iterdir()
            for pid in (task / "children").read_text().split()}


def scene_of(page: str) -> list[dict]:
    """The meshcat commands a page replays, unpacked."""
    blob = re.search(r'id="sjt-scene">(.*?)</script>', page, re.S).group(1)
    return [umsgpack.unpackb(base64.b64decode(c)) for c in json.loads(blob)]


@pytest.fixture(scope="module")
def two_runs():
    """The planar arm's demo circle tracked by SJT and JT, and the 1 s start of a JP run."""
    sc = scenarios.scenario("planar3")
    logs = {m: sjt.track(sjt.make_solver(m, sc.robot, dt=1e-3, task=sc.task), sc.trajectory,
                         sc.q0) for m in ("sjt", "jt")}
    short = sjt.track(sjt.make_solver("jp", sc.robot, dt=1e-3, task=sc.task), sc.trajectory,
                      sc.q0, duration=1.0)
    return sc.robot, logs, short


def test_a_page_needs_no_server_and_replays_every_run_on_one_timeline(two_runs):
    robot, logs, short = two_runs
    before = children()
    with Viewer(robot, name="arm", label="Paper arm", live=False) as viewer:
        assert children() == before  # no server process
        with pytest.raises(RuntimeError, match="no live server"):
            viewer.url  # noqa: B018
        viewer.compare(logs, robot="arm")
        viewer.add_robot(robot, "other", offset=pin.SE3(pin.utils.rotate("z", 1.0), np.ones(3)))
        viewer.animate(short, robot="other")
        page = viewer.static_html("Two arms", "What the page shows.")
    commands = scene_of(page)
    kinds = [c["type"] for c in commands]
    assert kinds.index("set_animation") == len(kinds) - 1  # after the objects it moves
    clips = commands[-1]["animations"]
    ends = {clip["clip"]["tracks"][0]["keys"][-1]["time"] for clip in clips}
    assert ends == {242}  # 2 runs x 121 frames: the 1 s run is held to the end, not looped
    runs = {c["path"] for c in clips if c["path"].endswith(("/runs/sjt", "/runs/jt"))}
    assert runs == {"/meshcat/arm/runs/sjt", "/meshcat/arm/runs/jt"}  # shown in turn
    assert "<h1>Two arms</h1>" in page and "<p>What the page shows.</p>" in page
    assert '<h2>Paper arm</h2>' in page and "<h2>other</h2>" in page
    assert page.count('<li data-method="') == 3 and page.count('class="error-plot"') == 2
    max_error = f"{logs['jt'].max_error:.1e}".replace("e-0", "e-")
    assert max_error in page  # the legend gives each run's largest error


def test_scene_record_keeps_the_last_state_of_each_node():
    record = SceneRecord()
    scene = meshcat.Visualizer(window=record)
    scene["a/b"].set_object(mg.Box([1, 1, 1]))
    scene["a/b"].set_property("visible", False)
    scene["a/b"].set_transform(np.diag([1.0, 1.0, 1.0, 1.0]) + 1e-3)
    scene["a/b"].set_object(mg.Sphere(1.0))  # replaces the box, drops its property
    scene["a/c"].set_object(mg.Sphere(2.0))
    scene["a/c"].delete()
    commands = [umsgpack.unpackb(c) for c in record.commands()]
    assert [(c["type"], c["path"]) for c in commands] == [("set_object", "/meshcat/a/b"),
                                                          ("set_transform", "/meshcat/a/b")]
    assert commands[0]["object"]["geometries"][0]["type"] == "SphereGeometry"
    assert commands[1]["matrix"][0] == pytest.approx(1.001, rel=1e-6)  # single precision


def test_ur5_meshes_are_decimated_and_keep_their_shape_and_coloured_parts(ur5):
    kept = total = 0
    for geometry in ur5.visual_model.geometryObjects:
        parts = visual_parts(geometry)
        full = trimesh.load(geometry.meshPath, force="mesh")
        kept += sum(len(p.faces) for p in parts)
        total += len(full.faces)
        assert all(p.faces.max() < len(p.vertices) for p in parts)
        vertices = np.concatenate([p.vertices for p in parts])
        _, off, _ = trimesh.proximity.closest_point(full, vertices)
        assert off.max() < 0.01, geometry.name  # every vertex within 1 cm of the link's surface
        # and the link keeps its size
        assert np.allclose(vertices.min(0), full.vertices.min(0), atol=0.01), geometry.name
        assert np.allclose(vertices.max(0), full.vertices.max(0), atol=0.01), geometry.name
    assert kept < total / 3  # 96 k faces in the files
    # the joint housings, drawn in their own colours (meshcat's Collada loader lost them)
    colors = {p.rgba for g in ur5.visual_model.geometryObjects for p in visual_parts(g)}
    assert len(colors) >= 3


def test_mesh_scale_is_baked_into_the_vertices_and_files_are_read_once(panda):
    left, right = panda.visual_model.geometryObjects[-2:]
    assert visual_parts(left)[0].vertices is visual_parts(right)[0].vertices  # one finger file
    doubled = pin.GeometryObject(left)
    doubled.meshScale = np.array([2.0, 2.0, 3.0])
    for part, big in zip(visual_parts(left), visual_parts(doubled), strict=True):
        extent = np.ptp(part.vertices, axis=0)
        assert np.allclose(np.ptp(big.vertices, axis=0), [2, 2, 3] * extent, rtol=0.05)


def test_primitives_have_their_sizes(planar3):
    for geometry in planar3.visual_model.geometryObjects:
        (part,) = visual_parts(geometry)
        extent = np.ptp(part.vertices, axis=0)
        shape = geometry.geometry
        if isinstance(shape, coal.Box):
            expected = 2 * np.asarray(shape.halfSide)
        else:
            expected = [2 * shape.radius, 2 * shape.radius, 2 * shape.halfLength]
        assert np.allclose(extent, expected, rtol=1e-3, atol=1e-4), geometry.name
        assert part.rgba == pytest.approx(tuple(geometry.meshColor))


def test_error_plot_draws_each_series_peak_on_a_log_axis():
    t = np.linspace(0.0, 4.0, 4001)
    smooth = 1e-6 * (1 + t)
    spiky = smooth.copy()
    spiky[1234] = 3e-3  # one sample: it must survive the decimation to 100 points
    spiky[0], spiky[10] = 0.0, np.inf  # drawn at the ends of the axis
    svg = error_plot([Series("sjt", 0x1F77B4, t, smooth), Series("jt", 0xD62728, t, spiky)],
                     width=300, height=150, points=100)
    lines = re.findall(r'<polyline points="([^"]+)" stroke="(#[0-9a-f]{6})"', svg)
    assert [color for _, color in lines] == ["#1f77b4", "#d62728"]
    ys = [np.array([float(p.split(",")[1]) for p in points.split()]) for points, _ in lines]
    assert [len(y) for y in ys] == [100, 100] and "nan" not in svg
    # the axis spans the decades 1e-6 (the smooth data) to 1e-2 (above the spike)
    assert "10⁻⁶" in svg and "10⁻²" in svg and "10⁻⁷" not in svg
    top, height = (float(v) for v in re.search(
        r'<rect x="[\d.]+" y="([\d.]+)" width="[\d.]+" height="([\d.]+)"', svg).groups())
    spike = top + height - height * (np.log10(3e-3) + 6) / 4
    assert np.min(np.abs(ys[1] - spike)) < 0.1 and np.min(ys[1]) == pytest.approx(top)
    assert 'data-t1="4"' in svg


def test_compare_labels_runs_by_their_keys_in_distinct_colours(tmp_path):
    """Two runs of the same method (the paper's SJT and the default) stay apart on the page."""
    robot = sjt.Robot.planar3()
    q0 = np.deg2rad([60.0, 45.0, 30.0])
    start = robot.fk(q0).translation
    line = sjt.Line(start, start + [0.1, 0.0, 0.0], 0.2)
    logs = {name: sjt.track(sjt.SJTSolver(robot, task=sjt.PositionTask(axes="xy"), **options), line,
                            q0)
            for name, options in (("paper", {"feedback": "transpose",
                                             "feedforward": "transpose"}), ("sjt", {}))}
    viewer = Viewer(robot, live=False)
    viewer.compare(logs)
    path = viewer.save_html(tmp_path / "two.html")
    html = path.read_text()
    assert "PAPER" in html and "SJT" in html
    with pytest.raises(ValueError, match="already has a run labelled 'sjt'"):
        viewer.animate(logs["sjt"])


# -- the demo's whole-body scenes ---------------------------------------------------------
@pytest.fixture(scope="module")
def humanoid():
    from sjt_pin.viewer.demo import humanoid_scene

    return humanoid_scene(1e-3)


@pytest.fixture(scope="module")
def quadruped():
    from sjt_pin.viewer.demo import quadruped_scene

    return quadruped_scene(1e-3)


def inside(point, polygon) -> float:
    """Least signed distance (m, positive inside) of ``point`` (2,) to the edges of the
    counter-clockwise convex ``polygon`` (k, 2)."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    normals = np.column_stack([-edges[:, 1], edges[:, 0]]) / np.linalg.norm(edges, axis=1)[:, None]
    return float(np.min(np.einsum("ij,ij->i", normals, np.asarray(point)[:2] - polygon)))


def ground_points(robot, qs) -> np.ndarray:
    """The centre of mass's ground projection (N, 2) at each of ``qs``."""
    data = robot.model.createData()
    return np.array([pin.centerOfMass(robot.model, data, q)[:2] for q in qs])


def test_demo_humanoid_reaches_out_and_back_on_held_soles_over_its_support(humanoid):
    """TALOS' soles do not move (pose, 1e-6) over the whole recording, its centre of mass's
    projection stays the margin inside the soles' polygon at every step, and both hands follow
    their targets, 10 cm out and back."""
    from sjt_pin.viewer.demo import HANDS, REACH, SOLES

    robot, log, support = humanoid.robot, humanoid.log, humanoid.support
    assert log.t[-1] == pytest.approx(4.0) and not log.diverged
    for sole in SOLES:
        held = robot.fk(log.q[0], sole)
        slip = max(np.linalg.norm(pin.log6(robot.fk(q, sole).actInv(held)).vector)
                   for q in log.q)
        assert slip < 1e-6, (sole, slip)
    # the polygon: the two 20 x 10 cm soles' outline (they stand side by side, axis-aligned)
    soles = np.array([robot.fk(log.q[0], s).translation[:2] for s in SOLES])
    np.testing.assert_allclose(support.polygon.min(axis=0), soles.min(axis=0) - [0.1, 0.05],
                               atol=1e-6)
    np.testing.assert_allclose(support.polygon.max(axis=0), soles.max(axis=0) + [0.1, 0.05],
                               atol=1e-6)
    distances = [inside(c, support.polygon) for c in ground_points(robot, log.q)]
    assert min(distances) >= support.margin
    # both hands 10 cm out and back, followed within 10 um (their velocities fed forward)
    right = humanoid.targets[HANDS[1]]
    for hand, targets in ((HANDS[0], log.target), (HANDS[1], right)):
        np.testing.assert_allclose(targets[len(log) // 2] - targets[0], REACH[hand], atol=1e-9)
        np.testing.assert_allclose(targets[-1], targets[0], atol=1e-9)
        reached = np.array([robot.fk(q, hand).translation for q in log.q[::50]])
        assert np.abs(reached - targets[::50]).max() < 1e-5, hand
    assert log.max_error < 1e-5


def test_demo_quadruped_moves_its_body_in_a_circle_over_held_feet(quadruped):
    """Solo-12's centre of mass goes round a 4 cm circle about its start, 3 cm lower, and
    back; its point feet stay put (1e-5 m) and the projection the margin inside them."""
    from sjt_pin.viewer.demo import CIRCLE_RADIUS, CROUCH, FEET

    robot, log, support = quadruped.robot, quadruped.log, quadruped.support
    assert not log.diverged and log.max_error < 1e-5  # the centre of mass on its circle
    offsets = log.target - log.target[0]
    full = (log.t >= 1.0) & (log.t <= 3.0)  # ramped in, not yet out
    np.testing.assert_allclose(np.linalg.norm(offsets[full, :2], axis=1), CIRCLE_RADIUS)
    np.testing.assert_allclose(offsets[full, 2], -CROUCH)
    np.testing.assert_allclose(offsets[-1], 0.0, atol=1e-12)
    for foot in FEET:
        start = robot.fk(log.q[0], foot).translation
        slip = max(np.linalg.norm(robot.fk(q, foot).translation - start) for q in log.q)
        assert slip < 1e-5, (foot, slip)
    feet = np.array([robot.fk(log.q[0], f).translation[:2] for f in FEET])
    np.testing.assert_allclose(support.polygon.min(axis=0), feet.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(support.polygon.max(axis=0), feet.max(axis=0), atol=1e-9)
    assert min(inside(c, support.polygon) for c in ground_points(robot, log.q)) >= support.margin


def floats(ext) -> np.ndarray:
    """A packed Float32Array of a meshcat command (an msgpack extension) as an array."""
    return np.frombuffer(ext.data, dtype=np.float32).astype(float)


def test_demo_page_draws_each_support_polygon_and_the_centre_of_mass_over_it(humanoid,
                                                                              quadruped):
    """The page's scene holds, for each whole-body robot, its support polygon as a closed loop
    on the ground (the limit's polygon), and a disc keyed at every frame on the centre of
    mass's ground projection, inside the polygon; TALOS' two hand targets move with the run."""
    from sjt_pin.viewer.demo import HANDS, demo_viewer

    viewer = demo_viewer({}, whole_body=[humanoid, quadruped])
    page = viewer.static_html("demo")
    for label in ("TALOS reaching over its soles", "Solo-12 moving its body"):
        assert f"<h2>{label}</h2>" in page
    assert page.count('<p class="guide">Green: the support polygon and the centre of '
                      "mass&#x27;s ground projection, held 20 mm inside it.</p>") == 2
    commands = scene_of(page)
    objects = {c["path"]: c for c in commands if c["type"] == "set_object"}
    clips = {c["path"]: c["clip"] for c in commands[-1]["animations"]}
    for scene in (humanoid, quadruped):
        node, polygon, margin = f"/meshcat/{scene.node}", scene.support.polygon, \
            scene.support.margin
        loop = objects[f"{node}/paths/support"]["object"]
        assert loop["object"]["type"] == "Line"
        points = floats(loop["geometries"][0]["data"]["attributes"]["position"]["array"])
        points = points.reshape(-1, 3)
        np.testing.assert_allclose(points[:-1, :2], polygon, atol=1e-6)
        np.testing.assert_allclose(points[-1], points[0])  # closed
        contacts = [scene.robot.fk(scene.log.q[0], c).translation[2]
                    for c in scene.support.contacts]
        assert np.ptp(points[:, 2]) == 0 and 0 < points[0, 2] - min(contacts) < 0.005
        assert f"{node}/paths/support_area" in objects
        # the disc: one key per frame (30 fps, 4 s) plus the track's end, on the ground
        assert f"{node}/markers/com" in objects
        track = next(t for t in clips[f"{node}/markers/com"]["tracks"]
                     if t["name"] == ".position")
        keyed = np.array([k["value"] for k in track["keys"]])
        assert len(keyed) == 122 and np.allclose(keyed[:, 2], points[0, 2])
        rows = np.minimum(np.searchsorted(scene.log.t, np.arange(121) / 30), len(scene.log) - 1)
        np.testing.assert_allclose(keyed[:121, :2], ground_points(scene.robot,
                                                                  scene.log.q[rows]),
                                   atol=1e-6)
        assert min(inside(p, polygon) for p in keyed) >= margin - 1e-6
    targets = {path: clips[path] for path in clips
               if path.startswith("/meshcat/talos/markers/target")}
    assert set(targets) == {"/meshcat/talos/markers/target",
                            f"/meshcat/talos/markers/target-{HANDS[1]}"}
    right = next(t for t in targets[f"/meshcat/talos/markers/target-{HANDS[1]}"]["tracks"]
                 if t["name"] == ".position")
    np.testing.assert_allclose(right["keys"][60]["value"], humanoid.targets[HANDS[1]][2000],
                               atol=1e-6)
    assert f"/meshcat/talos/runs/sjt/ee-{HANDS[1]}" in clips


def test_animate_refuses_a_support_without_polygon_and_targets_of_another_length(two_runs):
    robot, logs, _ = two_runs
    viewer = Viewer(robot, live=False)
    with pytest.raises(ValueError, match="support has no polygon"):
        viewer.animate(logs["sjt"], support=sjt.SupportLimit(["ee"]))
    with pytest.raises(ValueError, match=r"targets\['ee'\] must have one row per row"):
        viewer.animate(logs["sjt"], targets={"ee": np.zeros((3, 3))})
    viewer.animate(logs["sjt"])  # nothing was half added
