"""The command line's argument types: each ``type=`` of :mod:`sjt_pin.cli` refuses bad input
with a message naming the argument, and :class:`Parser` makes that message one line on stderr
(``sjt-pin demo: error: argument --keep: ...``) with exit code 2, before any work.

Numbers are checked by their value (:func:`positive_int`, :func:`at_least`,
:func:`non_negative_float`, :func:`grid_step`); output paths by :func:`output_file` and
:func:`output_folder`, which try to write there.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``prog: error: message``), exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_int(text: str) -> int:
    """``type=`` for counts: an integer >= 1."""
    return _integer_at_least(text, 1, "a positive integer")


def _integer_at_least(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def at_least(low: int) -> Callable[[str], int]:
    """``type=`` for counts of at least ``low``."""
    def parse(text: str) -> int:
        return _integer_at_least(text, low, f"an integer >= {low}")

    parse.__name__ = f"integer >= {low}"
    return parse


def non_negative_float(text: str) -> float:
    """``type=`` for durations: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return value


def _can_write_in(folder: Path) -> None:
    """Raise ArgumentTypeError unless a file can be created in the existing ``folder``."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise argparse.ArgumentTypeError(
            f"cannot write in {str(folder)!r}: {error.strerror or error}") from None


def _existing_ancestor(path: Path) -> Path:
    """The nearest of ``path``'s parents that exists; it must be a folder."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise argparse.ArgumentTypeError(f"{str(parent)!r} is a file, not a folder")
            return parent
    return Path(path.absolute().anchor)


def output_file(parents: bool) -> Callable[[str], Path]:
    """``type=`` for a file to write: not '', not a folder, in a folder where one can write.

    With ``parents``, missing folders on the way are fine (the command creates them); without,
    the file's folder must exist. An existing file must be writable (it is not changed here).
    """
    def parse(text: str) -> Path:
        if not text.strip():
            raise argparse.ArgumentTypeError("expected a file path, got ''")
        path = Path(text).expanduser()
        if path.is_dir():
            raise argparse.ArgumentTypeError(f"{text!r} is a folder; give a file path")
        if path.exists():
            if not os.access(path, os.W_OK):
                raise argparse.ArgumentTypeError(f"cannot write {text!r}: permission denied")
            folder = path.absolute().parent
        elif parents:
            folder = _existing_ancestor(path)
        else:
            folder = path.absolute().parent
            if not folder.is_dir():
                what = "is a file" if folder.exists() else "does not exist"
                raise argparse.ArgumentTypeError(f"the folder of {text!r} {what}")
        _can_write_in(folder)
        return path

    parse.__name__ = "output file"
    return parse


def output_folder(text: str) -> Path:
    """``type=`` for a folder to write into: not '', not a file; it may not exist yet."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder path, got ''")
    path = Path(text).expanduser()
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a file, not a folder")
    _can_write_in(path if path.is_dir() else _existing_ancestor(path))
    return path


output_folder.__name__ = "output folder"


def grid_step(text: str) -> float:
    """``type=`` for reach's grid spacing: a finite number of metres > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length in m > 0, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a length in m > 0, got {text}")
    return value
