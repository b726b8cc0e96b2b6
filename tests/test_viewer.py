"""The meshcat viewer: loopback-only server that dies with its parent, scene API, static HTML."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.viewer.server import LoopbackServer
from sjt_pin.viewer import Viewer


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
    viewer.draw_frame(robot.fk(robot.q0), "ee")
    J = robot.jacobian(robot.q0, reference=pin.LOCAL_WORLD_ALIGNED)[:2]
    viewer.draw_ellipsoid([1.18, 0, 0], J.T[:2], "jt", color=(0.8, 0.1, 0.1))
    path = viewer.save_html(tmp_path / "scene.html")
    html = path.read_text()
    assert path.stat().st_size > 300_000  # meshcat's viewer code is embedded: works offline
    assert "new MeshCat.Viewer" in html and "http" not in html.split("<script>")[0]


def test_bad_drawing_arguments(planar_viewer):
    viewer, _ = planar_viewer
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        viewer.draw_path(np.zeros((3, 5)))  # (3, N) is the wrong way round
    with pytest.raises(ValueError, match="contains NaN"):
        viewer.draw_path(np.full((4, 3), np.nan))
    with pytest.raises(ValueError, match="robot must be one of"):
        viewer.show(np.zeros(3), robot="panda")
    with pytest.raises(ValueError, match=r"q must have shape \(3,\)"):
        viewer.show(np.zeros(4))
    with pytest.raises(ValueError, match="2 or 3 rows"):
        viewer.draw_ellipsoid([0, 0, 0], np.eye(4))
    with pytest.raises(ValueError, match="color must be one of"):
        viewer.draw_path(np.zeros((2, 3)), color="mauve")
