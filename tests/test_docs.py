"""The documentation site: every public name has its API page, every topic is one click from the
front page, every internal link and anchor resolves, nothing is loaded from the network, and the
benchmark tables come from the committed JSON files.

The site is ``docs/_build/html`` when it is newer than the sources (``.ci/run`` builds it just
before the tests), else it is built here, with warnings as errors.
"""

from __future__ import annotations

import html
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BUILT = DOCS / "_build" / "html"
TOPICS = sorted(p.stem for p in DOCS.glob("*.md") if p.stem != "index")

sys.path.insert(0, str(DOCS / "_ext"))
from api_pages import public_names  # noqa: E402


def _newest_source() -> float:
    sources = [*DOCS.rglob("*.md"), *DOCS.glob("*.py"), *DOCS.glob("_ext/*.py"),
               *DOCS.glob("bench/*.json"), *(ROOT / "sjt_pin").rglob("*.py")]
    return max(p.stat().st_mtime for p in sources if "_build" not in p.parts)


def build(out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sphinx", "-W", "-n", "--keep-going", "-q",
                           "-b", "html", str(DOCS), str(out)],
                          capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="session")
def site(tmp_path_factory) -> Path:
    index = BUILT / "index.html"
    if index.exists() and index.stat().st_mtime >= _newest_source():
        return BUILT
    out = tmp_path_factory.mktemp("site")
    result = build(out)
    assert result.returncode == 0, f"the site does not build cleanly:\n{result.stderr}"
    return out


class Links(HTMLParser):
    """The ``href``/``src`` of every tag, the ids of every element, and where ``<article>``s
    (the page's own content, not the sidebar) begin and end."""

    def __init__(self):
        super().__init__()
        self.refs: list[tuple[str, str, bool]] = []  # (tag, url, inside the article)
        self.ids: set[str] = set()
        self._article = 0

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "article":
            self._article += 1
        if "id" in attrs:
            self.ids.add(attrs["id"])
        for key in ("href", "src"):
            if attrs.get(key):
                self.refs.append((tag, html.unescape(attrs[key]), self._article > 0))

    def handle_endtag(self, tag):
        if tag == "article":
            self._article -= 1


def parse(path: Path) -> Links:
    links = Links()
    links.feed(path.read_text(encoding="utf-8"))
    return links


def test_every_public_name_has_an_api_page_that_the_index_links(site):
    """100 % of ``sjt_pin.__all__`` (and of the limits, methods and viewer packages) in the API
    reference: a page each, listed in docs/api/index.md, describing the object by its name."""
    import sjt_pin

    names = {f"{package}.{name}" for package, name in public_names()}
    assert {f"sjt_pin.{n}" for n in sjt_pin.__all__} <= names
    listed = set(re.findall(r"^generated/(\S+)$", (DOCS / "api" / "index.md").read_text(), re.M))
    assert listed == names, (names - listed, listed - names)
    for full in names:
        page = site / "api" / "generated" / f"{full}.html"
        assert page.exists(), full
        assert full in parse(page).ids or full.rsplit(".", 1)[0] + "." in page.read_text(), full
    genindex = (site / "genindex.html").read_text()
    assert "StepInfo" in genindex and "add_obstacle" in genindex


#: classes a public signature names that are no part of the API a user holds: the solver's
#: internal table of its user limits (``Solver.user_limits``, what ``solve()`` reads) and the
#: compiled kernels' parameter records
NOT_IN_THE_REFERENCE = {"sjt_pin.constraints.UserLimits"}


def _classes_in(annotation) -> set[type]:
    import inspect
    import typing

    found = set()
    if inspect.isclass(annotation) and annotation.__module__.startswith("sjt_pin"):
        found.add(annotation)
    for argument in typing.get_args(annotation):
        found |= _classes_in(argument)
    return found


def test_every_class_a_public_signature_names_has_an_api_page():
    """What a public method returns or takes (``Robot.frames``' ``FrameInfo``,
    ``CollisionLimit.distances``' ``PairDistance``, ``StepInfo.levels``' ``LevelInfo``, ...) has
    its page too, not only the names of ``__all__``."""
    import importlib
    import inspect
    import typing

    documented = {id(getattr(importlib.import_module(package), name))
                  for package, name in public_names()}
    missing: dict[str, set[str]] = {}
    for package, name in public_names():
        obj = getattr(importlib.import_module(package), name)
        members = [(name, obj)]
        if inspect.isclass(obj):
            for m in dir(obj):  # its own members and those of its bases
                if m.startswith("_") and m not in ("__init__", "__call__"):
                    continue
                value = inspect.getattr_static(obj, m)
                value = getattr(value, "fget", None) or getattr(value, "__func__", value)
                members.append((f"{name}.{m}", value))
        for where, member in members:
            if not callable(member):
                continue
            try:
                hints = typing.get_type_hints(member)
            except (NameError, TypeError):
                continue
            for hint in hints.values():
                for cls in _classes_in(hint):
                    full = f"{cls.__module__}.{cls.__qualname__}"
                    if (id(cls) not in documented and full not in NOT_IN_THE_REFERENCE
                            and not cls.__module__.startswith("sjt_pin.kernels")):
                        missing.setdefault(full, set()).add(where)
    assert not missing, missing


def test_each_topic_is_one_click_from_the_front_page(site):
    """The front page's own content links every topic page (and the API reference)."""
    front = parse(site / "index.html")
    linked = {urlsplit(url).path for tag, url, inside in front.refs if tag == "a" and inside}
    for topic in [*TOPICS, "api/index"]:
        assert f"{topic}.html" in linked, topic
        assert (site / f"{topic}.html").exists()


def test_every_internal_link_and_anchor_resolves(site):
    """Every link between the site's pages points at a file that exists, and its #anchor at an
    element of that page (what a link checker does, without the network)."""
    pages = sorted(site.rglob("*.html"))
    assert len(pages) > len(TOPICS) + 40
    ids = {page: parse(page).ids for page in pages}
    broken = []
    for page in pages:
        for _tag, url, _ in parse(page).refs:
            parts = urlsplit(url)
            if parts.scheme or url.startswith(("mailto:", "javascript:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if not target.exists():
                broken.append(f"{page.relative_to(site)}: {url}")
            elif parts.fragment and target.suffix == ".html":
                known = ids.get(target) if target in ids else parse(target).ids
                if unquote(parts.fragment) not in known:
                    broken.append(f"{page.relative_to(site)}: {url} (no such anchor)")
    assert not broken, broken[:20]


def test_the_site_loads_nothing_from_the_network(site):
    """Scripts, styles, fonts and images are the site's own files; MathJax is among them."""
    for page in site.rglob("*.html"):
        for tag, url, _ in parse(page).refs:
            if tag in ("script", "link", "img", "iframe", "source"):
                assert not urlsplit(url).scheme, f"{page.name} loads {url}"
    math_page = (site / "index.html").read_text()
    script = re.search(r'<script[^>]*src="([^"]*mathjax[^"]*)"', math_page)
    assert script and (site / urlsplit(script.group(1)).path).exists()  # (a ?v= checksum)
    assert list((site / "_static" / "mathjax").rglob("*.woff"))  # its fonts too


def test_the_search_index_knows_what_a_reader_looks_for(site):
    """The names the issue looked for by hand are in the site's search index."""
    text = (site / "searchindex.js").read_text()
    index = json.loads(text[text.index("(") + 1:text.rindex(")")])
    objects = {f"{prefix}.{entry[4]}" if prefix else entry[4]
               for prefix, entries in index["objects"].items() for entry in entries}
    for name in ("sjt_pin.CollisionLimit", "sjt_pin.StepInfo.stalled",
                 "sjt_pin.viewer.Viewer.add_obstacle", "sjt_pin.SJTSolver"):
        assert name in objects, name
    # words are stemmed, the query as well as the pages: acceleration_limits -> acceleration_limit
    docs = index["terms"]["acceleration_limit"]
    docs = docs if isinstance(docs, list) else [docs]
    assert index["docnames"].index("limits") in docs


def test_the_benchmark_tables_are_made_from_the_json_files(site):
    """Values of each committed bench file appear, formatted, in the benchmarks page."""
    page = (site / "benchmarks.html").read_text()
    speed = json.loads((DOCS / "bench" / "speed.json").read_text())
    row = speed["rows"][0]
    assert f"{row['step']['median']:.2f}" in page and html.escape(row["path"]) in page
    ik = json.loads((DOCS / "bench" / "ik.json").read_text())
    assert f"{ik['rows'][0]['median_ms']:.3f}" in page
    collision = json.loads((DOCS / "bench" / "collision.json").read_text())
    assert f"{collision['rows'][0]['us_per_step']:.1f}" in page
    for section, digits in (("stream", 4), ("moving", 5), ("mesh", 5)):  # every section shown
        assert f"{collision[section][-1]['closest']:.{digits}f}" in page, section
    assert "From docs/bench/speed.json" in page


def test_the_bench_generator_pivots_and_filters():
    from bench_tables import cells, columns, pivot

    entries = [{"path": "a", "variant": "SJT", "e": 0.5}, {"path": "a", "variant": "DLS", "e": 2},
               {"path": "b", "variant": "SJT", "e": 1}]
    spec = columns(["path | {path}"])
    headers, body = pivot(entries, spec, None, "variant", "{e}")
    assert headers == ["SJT", "DLS"] and body == [["a", "0.5", "2"], ["b", "1", "–"]]
    assert cells(entries, columns(["e | {e:.1f}"]), "variant == 'DLS'") == [["2.0"]]
    assert cells([{"e": float("nan")}], columns(["e | {e:.1f}"]), None) == [["–"]]  # none
    with pytest.raises(KeyError):
        cells(entries, columns(["x | {missing}"]), None)
