"""The benchmark tables, generated at build time from ``sjt-pin bench KIND --json FILE`` output
committed under ``docs/bench/`` (never typed by hand).

In a page::

    ```{bench-table} ik.json rows
    :where: method != "SJT, timeout=5 ms"
    robot | {robot}
    method | {method}
    success | {success:.1%}
    ```

takes the list ``rows`` of ``docs/bench/ik.json`` and makes one table row per entry: each line
of the body is a column, its header before ``|`` and after it a ``str.format`` template filled
from the entry (a dotted key such as ``step.median`` reads a nested value: write it as
``{step[median]}``). ``:where:`` keeps the entries for which a Python expression over the
entry's keys is true. ``:pivot: KEY`` with ``:value: TEMPLATE`` makes a wide table: a column
per distinct value of ``KEY`` (a method, say), one row per distinct row of the body's columns.
A section that is a record (``cold_start``) gives one entry per key, as ``{key}`` and
``{value}``. A field that is NaN in the file (a quantity a row does not have: a ratio to a limit
the run had not, the time a run that never failed failed at) shows as "–", whatever its
format. The caption names the machine and the versions the file records.
"""

from __future__ import annotations

import json
import math
import string
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from sphinx.util import logging

logger = logging.getLogger(__name__)


class _Missing(dict):
    def __missing__(self, key):
        raise KeyError(key)


class _Formatter(string.Formatter):
    """``str.format_map``, with "–" for a NaN field."""

    def format_field(self, value, format_spec):
        if isinstance(value, float) and math.isnan(value):
            return "–"
        return super().format_field(value, format_spec)


def fill(template: str, entry: dict) -> str:
    """``template`` filled from ``entry`` (a missing key raises ``KeyError``)."""
    return _Formatter().vformat(template, (), _Missing(entry))


def load(path: Path, section: str) -> tuple[list[dict], dict]:
    """The entries of ``section`` (dots walk into nested dicts) of the JSON file, and the
    file's ``machine`` record."""
    data = json.loads(path.read_text())
    entries = data
    for key in section.split("."):
        entries = entries[key]
    if isinstance(entries, dict):  # a record: one entry per key
        return [{"key": k, "value": v} for k, v in entries.items()], data.get("machine", {})
    return list(entries), data.get("machine", {})


def columns(lines: list[str]) -> list[tuple[str, str]]:
    """``(header, template)`` of each ``header | template`` line."""
    out = []
    for line in lines:
        if not line.strip():
            continue
        header, sep, template = line.partition("|")
        if not sep:
            raise ValueError(f"a column is 'header | template', got {line!r}")
        out.append((header.strip(), template.strip()))
    return out


def cells(entries: list[dict], spec: list[tuple[str, str]], where: str | None) -> list[list[str]]:
    """The table's body: one row of formatted cells per entry kept by ``where``."""
    rows = []
    for entry in entries:
        if where and not eval(where, {"__builtins__": {}}, dict(entry)):  # noqa: S307
            continue
        rows.append([fill(template, entry) for _, template in spec])
    return rows


def pivot(entries: list[dict], spec: list[tuple[str, str]], where: str | None, by: str,
          value: str) -> tuple[list[str], list[list[str]]]:
    """A wide table: one row per distinct value of the ``spec`` columns, one column per
    distinct ``entry[by]`` (in the order they first appear), cells from ``value``."""
    kept = [e for e in entries
            if not where or eval(where, {"__builtins__": {}}, dict(e))]  # noqa: S307
    headers = list(dict.fromkeys(str(e[by]) for e in kept))
    rows: dict[tuple, dict[str, str]] = {}
    for e in kept:
        key = tuple(fill(t, e) for _, t in spec)
        rows.setdefault(key, {})[str(e[by])] = fill(value, e)
    body = [[*key, *(cells.get(h, "–") for h in headers)] for key, cells in rows.items()]
    return headers, body


def caption(machine: dict, filename: str) -> str:
    parts = [machine.get("cpu") or machine.get("machine", "")]
    for key, label in (("python", "Python"), ("pinocchio", "Pinocchio"), ("numpy", "NumPy")):
        if key in machine:
            parts.append(f"{label} {machine[key]}")
    return f"From docs/bench/{filename} ({', '.join(p for p in parts if p)})."


class BenchTable(Directive):
    required_arguments = 2
    has_content = True
    option_spec = {"where": directives.unchanged, "caption": directives.unchanged,
                   "pivot": directives.unchanged, "value": directives.unchanged}

    def run(self):
        env = self.state.document.settings.env
        filename, section = self.arguments
        path = Path(env.srcdir) / "bench" / filename
        env.note_dependency(str(path))
        try:
            entries, machine = load(path, section)
            spec = columns(list(self.content))
            headers = [h for h, _ in spec]
            if "pivot" in self.options:
                extra, body = pivot(entries, spec, self.options.get("where"),
                                    self.options["pivot"], self.options.get("value", "{value}"))
                headers += extra
            else:
                body = cells(entries, spec, self.options.get("where"))
        except (OSError, KeyError, ValueError, SyntaxError, TypeError) as exc:
            raise self.error(f"bench-table {filename} {section}: {exc!r}") from exc
        if not body:
            raise self.error(f"bench-table {filename} {section}: no entries")
        table = nodes.table(classes=["bench-table"])
        title = self.options.get("caption")
        text = (title + " " if title else "") + caption(machine, filename)
        table += nodes.title(text=text)
        group = nodes.tgroup(cols=len(headers))
        table += group
        for _ in headers:
            group += nodes.colspec(colwidth=1)
        head = nodes.thead()
        group += head
        head += self._row(headers)
        tbody = nodes.tbody()
        group += tbody
        for row in body:
            tbody += self._row(row)
        return [table]

    @staticmethod
    def _row(texts):
        row = nodes.row()
        for text in texts:
            entry = nodes.entry()
            entry += nodes.paragraph(text=text)
            row += entry
        return row


def setup(app):
    app.add_directive("bench-table", BenchTable)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
