"""A meshcat server bound to 127.0.0.1 that dies with the process that started it.

meshcat's own ``meshcat-server`` binds its web port to all interfaces whatever URL it prints,
and starts in a session of its own, so it outlives a killed parent and keeps its ports.
:class:`LoopbackServer` runs the same bridge with the web port on 127.0.0.1 (the ZMQ port is
already on 127.0.0.1), and the child leaves when the process that started it does, whichever of
its threads started it: the child watches a pipe whose other end only that process holds, and
the pipe reads end-of-file when the process exits or is killed (a parent-death signal would
fire when the starting *thread* ends). A watchdog also exits when the parent id changes.

:class:`LiveWindow` is what the viewer sends commands through: every request has a timeout
(ZMQ's ``RCVTIMEO``/``SNDTIMEO``), so a dead or stuck server raises :class:`ServerTimeout`
instead of blocking forever.

Run as ``python -m sjt_pin.viewer.server --parent PID``; it prints ``zmq_url=`` and ``web_url=``
lines like meshcat's server.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import os
import re
import select
import signal
import subprocess
import sys
import threading
import time

import umsgpack
import zmq

LOOPBACK = "127.0.0.1"


class LoopbackServer:
    """Start the server in a child process; ``close()`` (or leaving ``with``) stops it."""

    def __init__(self, timeout: float = 30.0):
        self.process = subprocess.Popen(
            [sys.executable, "-u", "-m", __name__, "--parent", str(os.getpid())],
            stdin=subprocess.PIPE,  # the lifeline: end-of-file when this process is gone
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, start_new_session=True,
            bufsize=0,  # unbuffered: select() then sees every line that has not been read
        )
        atexit.register(self.close)
        deadline = time.monotonic() + timeout
        urls: dict[str, str] = {}
        while len(urls) < 2:
            remaining = deadline - time.monotonic()
            ready = remaining > 0 and select.select([self.process.stdout], [], [], remaining)[0]
            line = self.process.stdout.readline().decode() if ready else ""
            if not line:  # the deadline passed, or the child exited
                self.close()
                raise RuntimeError(f"the meshcat server did not start within {timeout:g} s")
            match = re.match(r"(zmq_url|web_url)=(\S+)", line.strip())
            if match:
                urls[match.group(1)] = match.group(2)
        self.zmq_url, self.web_url = urls["zmq_url"], urls["web_url"]

    @property
    def pid(self) -> int:
        return self.process.pid

    def close(self) -> None:
        """Stop the server (idempotent)."""
        atexit.unregister(self.close)
        if self.process.poll() is None:
            self.process.terminate()
            with contextlib.suppress(ProcessLookupError):  # a stopped server gets it too
                os.kill(self.process.pid, signal.SIGCONT)
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe:
                pipe.close()

    @property
    def running(self) -> bool:
        """Whether the server process is still there."""
        return self.process.poll() is None

    def __enter__(self) -> LoopbackServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ServerTimeout(RuntimeError):
    """The meshcat server did not answer in time: it died, or it is stuck."""


class LiveWindow:
    """Sends meshcat commands to the server at ``zmq_url``, waiting at most ``timeout`` s each.

    Like meshcat's ``ViewerWindow`` (``send``, ``web_url``), but a request that gets no answer in
    time raises :class:`ServerTimeout`, and so does every later one, at once: a ZMQ request
    socket left without its answer cannot be used again.
    """

    def __init__(self, zmq_url: str, web_url: str, timeout: float, alive=None):
        self.zmq_url, self.web_url, self.timeout = zmq_url, web_url, float(timeout)
        self._alive = alive
        self._broken: str | None = None
        milliseconds = max(1, int(round(1e3 * self.timeout)))
        self._socket = zmq.Context.instance().socket(zmq.REQ)
        for option, value in ((zmq.RCVTIMEO, milliseconds), (zmq.SNDTIMEO, milliseconds),
                              (zmq.LINGER, 0)):
            self._socket.setsockopt(option, value)
        self._socket.connect(zmq_url)

    def send(self, command) -> None:
        """Send a meshcat command (``SetObject``, ...) and wait for the server's answer."""
        self.send_lowered(command.lower())

    def send_lowered(self, lowered: dict) -> None:
        """Send a command already lowered to a dict (what ``command.lower()`` returns)."""
        if self._broken is None and self._alive is not None and not self._alive():
            self._fail("has exited")
        if self._broken is not None:
            raise ServerTimeout(self._broken)
        try:
            self._socket.send_multipart([lowered["type"].encode(), lowered["path"].encode(),
                                         umsgpack.packb(lowered)])
            self._socket.recv()
        except zmq.Again:
            self._fail(f"did not answer within {self.timeout:g} s (it died or is stuck)")

    def _fail(self, what: str) -> None:
        self._broken = (f"the meshcat server at {self.zmq_url} {what}; call the viewer's "
                        "restart() to start a new server with the scene so far, or make the "
                        "viewer with live=False")
        self.close()
        raise ServerTimeout(self._broken)

    def close(self) -> None:
        """Close the socket (idempotent)."""
        self._socket.close(linger=0)


def _die_with_parent(parent: int) -> None:
    """Exit when the parent process is gone: its end of our stdin closes, or its id changes."""

    def lifeline() -> None:
        try:
            while sys.stdin.buffer.read(4096):
                pass
        finally:
            os._exit(0)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(0)

    if os.getppid() != parent:
        os._exit(0)
    threading.Thread(target=lifeline, daemon=True).start()
    threading.Thread(target=watch, daemon=True).start()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--parent", type=int, required=True, help="exit when this process does")
    args = parser.parse_args()
    _die_with_parent(args.parent)
    signal.signal(signal.SIGTERM, lambda *_: os._exit(0))

    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class LoopbackBridge(ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen
            app.listen = lambda port, **kw: listen(port, address=LOOPBACK, **kw)
            return app

    bridge = LoopbackBridge(host=LOOPBACK)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    bridge.run()


if __name__ == "__main__":
    main()
