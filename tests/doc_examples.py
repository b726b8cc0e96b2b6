"""The code examples of the README and of the site's pages, run and compared with what they show.

A page's examples are its fenced ``python`` blocks; the ``text`` block right after one (only
blank lines between) is the output it shows. ``run_page`` runs a page's blocks in order in one
fresh interpreter (a page builds on its earlier blocks, as a reader does), in an empty folder,
and returns what each printed; ``outputs_match`` compares a shown output with a printed one:

- the text must be the same but for trailing spaces and blank lines at the end;
- ``...`` in the shown output stands for any text (doctest's ELLIPSIS);
- each number is compared to the precision it is written with (pytest's doctest NUMBER):
  ``0.087`` matches 0.0868 or 0.0874, ``2.5e-16`` any value within one unit of its last digit.

A block that prints must show its output, and a shown output must be printed.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Example:
    """One ``python`` block of a page, its first line's number and the output it shows."""

    code: str
    line: int
    shown: str | None


def examples(text: str) -> list[Example]:
    """The page's ``python`` blocks, each with the ``text`` block that follows it."""
    found: list[Example] = []
    blocks = list(FENCE.finditer(text))
    for i, block in enumerate(blocks):
        if block.group(1) != "python":
            continue
        shown = None
        if i + 1 < len(blocks):
            after = blocks[i + 1]
            if after.group(1) == "text" and not text[block.end():after.start()].strip():
                shown = after.group(2)
        found.append(Example(block.group(2), text.count("\n", 0, block.start()) + 2, shown))
    return found


RUNNER = r"""
import contextlib, io, json, sys, traceback
blocks = json.load(open(sys.argv[1]))
namespace = {"__name__": "__main__"}
printed = []
for code in blocks:
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, "<example>", "exec"), namespace)
    except BaseException:
        printed.append({"out": out.getvalue(), "error": traceback.format_exc()})
        break
    printed.append({"out": out.getvalue(), "error": None})
json.dump(printed, open(sys.argv[2], "w"))
"""


def run_page(page: list[Example], folder: Path, timeout: float = 900) -> list[dict]:
    """Run the examples in order in one new interpreter in ``folder``: for each, what it
    printed and the traceback where it raised (the run stops there)."""
    (folder / "blocks.json").write_text(json.dumps([e.code for e in page]))
    (folder / "runner.py").write_text(RUNNER)
    result = subprocess.run([sys.executable, "runner.py", "blocks.json", "printed.json"],
                            cwd=folder, capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0 or not (folder / "printed.json").exists():
        raise RuntimeError(f"the examples' interpreter failed:\n{result.stderr}")
    return json.loads((folder / "printed.json").read_text())


def _number_matches(expected: str, got: str) -> bool:
    """``got`` equals ``expected`` to the precision ``expected`` is written with."""
    try:
        e, g = float(expected), float(got)
    except ValueError:
        return expected == got
    if math.isnan(e) or math.isinf(e):
        return expected == got
    mantissa, _, exponent = expected.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    unit = 10.0 ** (-decimals + (int(exponent) if exponent else 0))
    return abs(e - g) <= unit * (1 + 1e-9)


def _pattern(expected: str) -> tuple[re.Pattern, list[str]]:
    """A regex of the shown output: its numbers and ``...`` as groups, the rest literal."""
    pieces, numbers = [], []
    position = 0
    token = re.compile(r"\.\.\.|" + NUMBER.pattern)
    for m in token.finditer(expected):
        if m.group() != "..." and m.start() > 0 and (expected[m.start() - 1].isalpha()
                                                     or expected[m.start() - 1] == "_"):
            continue  # a digit inside a word (ur5, q0): literal text
        pieces.append(re.escape(expected[position:m.start()]))
        if m.group() == "...":
            pieces.append(r"(?:.*?)")
        else:
            pieces.append(r"(" + NUMBER.pattern + r")")
            numbers.append(m.group())
        position = m.end()
    pieces.append(re.escape(expected[position:]))
    return re.compile("".join(pieces), re.S), numbers


def _clean(text: str) -> str:
    return "\n".join(line.rstrip() for line in text.strip("\n").splitlines())


def outputs_match(expected: str, got: str) -> bool:
    """Whether ``got`` is the shown output ``expected`` (see the module)."""
    expected, got = _clean(expected), _clean(got)
    pattern, numbers = _pattern(expected)
    match = pattern.fullmatch(got)
    if match is None:
        return False
    return all(_number_matches(e, g) for e, g in zip(numbers, match.groups(), strict=True))
