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
entry's keys is true. The caption names the machine and the versions the file records.
"""

from __future__ import annotations

import json
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from sphinx.util import logging

logger = logging.getLogger(__name__)


class _Missing(dict):
    def __missing__(self, key):
        raise KeyError(key)


def load(path: Path, section: str) -> tuple[list[dict], dict]:
    """The entries of ``section`` (dots walk into nested dicts) of the JSON file, and the
    file's ``machine`` record."""
    data = json.loads(path.read_text())
    entries = data
    for key in section.split("."):
        entries = entries[key]
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
        rows.append([template.format_map(_Missing(entry)) for _, template in spec])
    return rows


def caption(machine: dict, filename: str) -> str:
    parts = [machine.get("cpu") or machine.get("machine", "")]
    for key, label in (("python", "Python"), ("pinocchio", "Pinocchio"), ("numpy", "NumPy")):
        if key in machine:
            parts.append(f"{label} {machine[key]}")
    return f"From docs/bench/{filename} ({', '.join(p for p in parts if p)})."


class BenchTable(Directive):
    required_arguments = 2
    has_content = True
    option_spec = {"where": directives.unchanged, "caption": directives.unchanged}

    def run(self):
        env = self.state.document.settings.env
        filename, section = self.arguments
        path = Path(env.srcdir) / "bench" / filename
        env.note_dependency(str(path))
        try:
            entries, machine = load(path, section)
            spec = columns(list(self.content))
            body = cells(entries, spec, self.options.get("where"))
        except (OSError, KeyError, ValueError, SyntaxError, TypeError) as exc:
            raise self.error(f"bench-table {filename} {section}: {exc!r}") from exc
        if not body:
            raise self.error(f"bench-table {filename} {section}: no entries")
        table = nodes.table(classes=["bench-table"])
        title = self.options.get("caption")
        text = (title + " " if title else "") + caption(machine, filename)
        table += nodes.title(text=text)
        group = nodes.tgroup(cols=len(spec))
        table += group
        for _ in spec:
            group += nodes.colspec(colwidth=1)
        head = nodes.thead()
        group += head
        head += self._row([h for h, _ in spec])
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
