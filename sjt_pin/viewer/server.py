"""A meshcat server bound to 127.0.0.1 that dies with the process that started it.

meshcat's own ``meshcat-server`` binds its web port to all interfaces whatever URL it prints,
and starts in a session of its own, so it outlives a killed parent and keeps its ports.
:class:`LoopbackServer` runs the same bridge with the web port on 127.0.0.1 (the ZMQ port is
already on 127.0.0.1), and the child leaves when its parent does: Linux delivers SIGTERM on the
parent's death (``PR_SET_PDEATHSIG``), and a watchdog thread exits when the parent id changes
(other platforms, or a parent that died before the child set that up).

Run as ``python -m sjt_pin.viewer.server --parent PID``; it prints ``zmq_url=`` and ``web_url=``
lines like meshcat's server.
"""

from __future__ import annotations

import argparse
import atexit
import ctypes
import os
import re
import select
import signal
import subprocess
import sys
import threading
import time

LOOPBACK = "127.0.0.1"


class LoopbackServer:
    """Start the server in a child process; ``close()`` (or leaving ``with``) stops it."""

    def __init__(self, timeout: float = 30.0):
        self.process = subprocess.Popen(
            [sys.executable, "-u", "-m", __name__, "--parent", str(os.getpid())],
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
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout:
            self.process.stdout.close()

    def __enter__(self) -> LoopbackServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _die_with_parent(parent: int) -> None:
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(0)

    if os.getppid() != parent:
        os._exit(0)
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
