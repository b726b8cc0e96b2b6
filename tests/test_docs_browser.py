"""The documentation site in headless Chromium, opened from its files as a reader opens it
offline: every topic page renders its content and its math, the search finds what a reader
looks for, and the API page of SJTSolver lists its options."""

from __future__ import annotations

import io

import numpy as np
import pytest

from .test_docs import TOPICS, site  # noqa: F401  (the built site, a fixture)

pytestmark = pytest.mark.slow  # (Chromium pages: minutes; CI runs them with -m slow)

LOOKED_FOR = {  # query -> the page the first results must include
    "CollisionLimit": "api/generated/sjt_pin.CollisionLimit.html",
    "StepInfo.stalled": "api/generated/sjt_pin.StepInfo.html",
    "acceleration_limits": "limits.html",
    "Viewer.add_obstacle": "api/generated/sjt_pin.viewer.Viewer.html",
}


@pytest.fixture(scope="module")
def browse(chromium, site):  # noqa: F811
    """A function that opens a page of the site and returns it, recording what it requested
    and its script errors."""
    opened = []

    def open_page(path: str, width: int = 1200, height: int = 900):
        page = chromium.browser.new_page(viewport={"width": width, "height": height})
        page.requests, page.errors = [], []
        page.on("request", lambda request: page.requests.append(request.url))
        page.on("pageerror", lambda error: page.errors.append(str(error)))
        file, _, query = path.partition("?")
        url = (site / file).as_uri() + (f"?{query}" if query else "")
        page.goto(url, wait_until="load", timeout=60_000)
        opened.append(page)
        return page

    yield open_page
    for page in opened:
        page.close()


def _picture(page) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("L"), dtype=float)


@pytest.mark.parametrize("topic", ["index", *TOPICS])
def test_each_topic_page_renders_offline(browse, topic):
    """The page shows its title and text (not a blank or unstyled page), asks for nothing
    beyond its own files, and runs without a script error."""
    page = browse(f"{topic}.html")
    title = page.locator("article h1").first
    assert title.is_visible() and title.inner_text().strip()
    assert len(page.locator("article").inner_text()) > 400
    assert page.evaluate("() => getComputedStyle(document.body).fontFamily") != "Times New Roman"
    assert page.locator(".sidebar-drawer").first.is_visible()  # the theme's navigation
    picture = _picture(page)
    assert picture.std() > 20  # text on a background, not an empty page
    assert all(url.startswith("file://") for url in page.requests), page.requests
    assert not page.errors, page.errors


def test_math_renders_with_the_sites_own_mathjax(browse):
    """The front page's equation is typeset by the MathJax copied into the site."""
    page = browse("index.html")
    page.wait_for_selector("mjx-container", timeout=30_000)
    assert page.locator("mjx-container").first.bounding_box()["width"] > 200
    assert any("_static/mathjax" in url for url in page.requests)
    assert all(url.startswith("file://") for url in page.requests)


@pytest.mark.parametrize("query", sorted(LOOKED_FOR))
def test_search_finds_what_a_reader_looks_for(browse, query):
    """The site's own search box, offline: the page that documents the name is among the
    first results."""
    page = browse(f"search.html?q={query}")
    page.wait_for_selector("#search-results ul li a", timeout=30_000)
    links = page.locator("#search-results ul li a").evaluate_all(
        "(nodes) => nodes.slice(0, 8).map(a => a.href)")
    assert any(LOOKED_FOR[query] in link for link in links), links


def test_the_sjtsolver_page_lists_its_options(browse):
    """Every option of SJTSolver, its own and the ones all solvers share, with its meaning:
    the options are read from the signatures, so a new one without its description fails."""
    import dataclasses
    import inspect

    import sjt_pin as sjt

    own = [name for name, p in inspect.signature(sjt.SJTSolver).parameters.items()
           if p.kind is p.KEYWORD_ONLY]
    shared = [f.name for f in dataclasses.fields(sjt.SolverOptions)]
    assert {"feedback", "column_tol"} <= set(own) and {"gain", "escape"} <= set(shared)
    page = browse("api/generated/sjt_pin.SJTSolver.html")
    text = page.locator("article").inner_text()
    for option in [*own, *shared]:
        assert f"{option} –" in text or f"{option} (" in text, option
    assert "rad/s^2" in text
