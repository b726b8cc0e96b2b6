"""The live viewer never blocks forever, and its server lives as long as the process.

Each viewer call that would hang runs in a helper thread joined with a generous bound, so a
regression fails the test instead of hanging the suite.
"""

import os
import signal
import threading
import urllib.request

import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin.viewer import ServerTimeout, Viewer

from .test_viewer import alive, wait_until_gone

HANG = 60.0  # s: a call still running after this long is taken to block forever
Q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])


@pytest.fixture(scope="module")
def ur5():
    return sjt.Robot.from_example("ur5")


def returns(call, *args):
    """What ``call(*args)`` returns or raises, run in a thread; fails if it blocks."""
    outcome = {}

    def run():
        try:
            outcome["value"] = call(*args)
        except BaseException as error:  # noqa: BLE001 - handed back to the test
            outcome["error"] = error

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(HANG)
    assert not thread.is_alive(), f"{call.__name__} blocked for {HANG:g} s"
    return outcome


def test_a_viewer_made_in_a_thread_that_ended_still_has_its_server(ur5):
    made = {}
    thread = threading.Thread(target=lambda: made.setdefault("viewer", Viewer(ur5)))
    thread.start()
    thread.join()
    viewer = made["viewer"]
    try:
        server = viewer._server.pid  # noqa: SLF001 - the test looks at the child process
        assert not wait_until_gone(server, timeout=2.0), "the server died with its thread"
        outcome = returns(viewer.show, Q)
        assert "error" not in outcome, outcome
        with urllib.request.urlopen(viewer.url, timeout=10) as page:
            assert page.status == 200
    finally:
        viewer.close()
    assert wait_until_gone(server)


@pytest.mark.parametrize("fault", ["killed", "stopped"])
def test_a_dead_or_stuck_server_raises_then_restart_brings_the_scene_back(ur5, fault):
    viewer = Viewer(ur5, timeout=1.0)
    server = viewer._server.pid  # noqa: SLF001
    try:
        os.kill(server, signal.SIGKILL if fault == "killed" else signal.SIGSTOP)
        if fault == "killed":
            wait_until_gone(server)
        outcome = returns(viewer.show, Q)
        assert isinstance(outcome.get("error"), ServerTimeout), outcome
        message = str(outcome["error"])
        assert "restart()" in message and "meshcat server" in message
        again = returns(viewer.show, Q)  # at once, not after another timeout
        assert isinstance(again.get("error"), ServerTimeout), again
        url = viewer.restart()
        assert not alive(server) or fault == "stopped" and wait_until_gone(server)
        assert "error" not in returns(viewer.show, Q)
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200
        assert viewer.url == url
    finally:
        if fault == "stopped" and alive(server):
            os.kill(server, signal.SIGKILL)
        viewer.close()


def test_close_then_calls_keep_the_scene_and_restart_goes_live_again(ur5, tmp_path):
    viewer = Viewer(ur5)
    viewer.close()
    viewer.show(Q)  # no server, no hang: the scene is kept
    with pytest.raises(RuntimeError, match="no live server"):
        _ = viewer.url
    viewer.restart()
    try:
        assert "error" not in returns(viewer.show, Q)
        assert viewer.save_html(tmp_path / "page.html").stat().st_size > 0
    finally:
        viewer.close()


def test_timeout_must_be_a_positive_number(ur5):
    for bad in (0, -1.0, float("nan"), float("inf"), "1"):
        with pytest.raises(ValueError, match="timeout must be a positive number"):
            Viewer(ur5, live=False, timeout=bad)
