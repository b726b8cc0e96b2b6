"""Pinocchio's URDF parser run on a :class:`~sjt_pin.urdf_source.URDFSource`, with what it
prints to stderr captured: urdfdom prints the reason a document is broken (or a part it skipped)
to file descriptor 2, and :func:`build_model` puts it into the :class:`URDFError`."""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

import pinocchio as pin

from .urdf_source import URDFSource


def build_model(source: URDFSource) -> pin.Model:
    """Pinocchio's model of ``source``. If Pinocchio fails, or its parser prints an error and
    carries on without the part it could not read, the :class:`URDFError` carries what the
    parser printed to stderr (the real reason); other output (warnings) is passed on."""
    try:
        with captured_stderr() as printed:
            if source.path is None:
                model = pin.buildModelFromXML(source.text)
            else:
                model = pin.buildModelFromUrdf(str(source.path))
    except (ValueError, RuntimeError) as exc:
        reason = _parser_messages(printed.getvalue()) or str(exc)
        raise source.error(f"Pinocchio cannot parse it: {reason}") from exc
    if any(line.startswith("Error:") for line in printed.getvalue().splitlines()):
        # urdfdom skips what it cannot read (a <visual>, say) and only prints why
        raise source.error(f"Pinocchio's parser reports: {_parser_messages(printed.getvalue())}")
    sys.stderr.write(printed.getvalue())
    return model


#: one capture of fd 2 at a time: two threads that swapped fd 2 in turn would each restore the
#: other's temporary file, and the process would lose its stderr for good
_FD2 = threading.Lock()


@contextlib.contextmanager
def captured_stderr() -> Iterator[io.StringIO]:
    """Redirect file descriptor 2, where C++ libraries print, into the yielded buffer (filled
    on exit). Process-wide while it lasts (other threads' stderr lands there too), and one
    capture at a time (a module lock): fd 2 is always given back as it was."""
    printed = io.StringIO()
    with _FD2, tempfile.TemporaryFile() as log:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(log.fileno(), 2)
        try:
            yield printed
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            log.seek(0)
            printed.write(log.read().decode("utf-8", errors="replace"))


def _parser_messages(printed: str) -> str:
    """urdfdom's error lines, without its "Error:" tags and source locations ("at line 586 in
    joint.cpp")."""
    lines = (" ".join(line.split()).removeprefix("Error: ") for line in printed.splitlines())
    return "; ".join(line for line in lines if line and not line.startswith("at line "))
