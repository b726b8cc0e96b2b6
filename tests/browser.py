"""Headless Chromium (Debian's /usr/bin/chromium, driven by Playwright) for the page tests.

``python -m tests.browser PAGE.html docs/viewer.png`` takes the README's picture of a page.
"""

from __future__ import annotations

import io
import os
import shutil
import sys

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = [
    "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--no-first-run", "--disable-quic",
]
COUNT_MESHES = "() => { let n = 0; viewer.scene.traverse(o => { if (o.isMesh) n++; }); return n; }"


def require_chromium() -> str:
    """The browser's path, or a loud skip when Chromium cannot be installed on this machine."""
    if not os.path.exists(CHROMIUM):
        pytest.skip("!!! CHROMIUM IS NOT INSTALLED: the real-browser tests did NOT run. "
                    "Install it with `apt-get install -y chromium` (.ci/run does). !!!")
    return CHROMIUM


class Chromium:
    """Headless Chromium driven by Playwright's sync API, which allows one at a time."""

    def __init__(self):
        from playwright.sync_api import sync_playwright

        self._playwright = sync_playwright().start()
        self.browser = self._playwright.chromium.launch(
            executable_path=require_chromium(), args=ARGS, headless=True)

    def open(self, url: str, meshes: int, width: int = 640, height: int = 480) -> Page:
        """A new :class:`Page` on ``url``."""
        return Page(self.browser, url, meshes, width, height)

    def close(self) -> None:
        self.browser.close()
        self._playwright.stop()


class Page:
    """One page in headless Chromium, with the meshcat viewer's scene loaded.

    ``requests`` lists every URL the page asked for, ``errors`` its uncaught script errors.
    """

    def __init__(self, browser, url: str, meshes: int, width: int = 640, height: int = 480):
        self.page = browser.new_page(viewport={"width": width, "height": height})
        self.requests: list[str] = []
        self.errors: list[str] = []
        self.page.on("request", lambda request: self.requests.append(request.url))
        self.page.on("pageerror", lambda error: self.errors.append(str(error)))
        self.page.goto(url, wait_until="load", timeout=120_000)
        # meshes arrive over the websocket after load on the live page: wait for all of them
        self.page.wait_for_function(f"() => ({COUNT_MESHES})() >= {meshes}", timeout=120_000)

    def meshes(self) -> int:
        return self.page.evaluate(COUNT_MESHES)

    def evaluate(self, script: str, arg=None):
        """The value of the JavaScript function ``script`` called with ``arg``."""
        return self.page.evaluate(script, arg)

    def pose(self, time: float | None = None, hide: str | None = None) -> None:
        """Pause the animation at ``time`` (s), with robot ``hide`` hidden, and draw it."""
        node = f"viewer.scene_tree.find(['meshcat', '{hide}']).object"  # the robot's root
        script = "viewer.animator.pause();"
        if time is not None:
            script += f"viewer.animator.seek({time});"
        script += f"{node}.visible = false;" if hide is not None else ""
        script += "viewer.render();"
        self.page.evaluate(f"() => {{ {script} }}")
        self.page.evaluate("() => new Promise(r => requestAnimationFrame(() => r()))")

    def screenshot(self, time: float | None = None, hide: str | None = None) -> np.ndarray:
        """RGB image of the canvas, at animation ``time`` (s), with robot ``hide`` hidden."""
        self.pose(time, hide)
        image = self.image(self.page.locator("canvas").first)
        if hide is not None:
            self.page.evaluate(
                f"() => {{ viewer.scene_tree.find(['meshcat', '{hide}']).object.visible = true; "
                "viewer.render(); }")
        return image

    def image(self, locator) -> np.ndarray:
        """RGB image of what the page shows in ``locator``'s box."""
        from PIL import Image

        png = locator.screenshot()
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)

    def close(self) -> None:
        self.page.close()


def changed_fraction(a: np.ndarray, b: np.ndarray, tol: int = 30) -> float:
    """Fraction of pixels whose colour differs by more than ``tol`` in some channel."""
    return float(np.mean(np.abs(a - b).max(axis=2) > tol))


def color_pixels(image: np.ndarray, color: int, tol: int = 40) -> int:
    """How many pixels of ``image`` are within ``tol`` of ``color`` (0xRRGGBB) per channel."""
    rgb = np.array([color >> 16 & 255, color >> 8 & 255, color & 255])
    return int(np.sum(np.abs(image - rgb).max(axis=2) <= tol))


def save_picture(page_path: str, out: str, width: int = 1400, height: int = 940,
                 time: float = 5.0) -> None:
    """A PNG of the page at ``page_path`` paused at ``time`` s, in 256 dithered colours."""
    from pathlib import Path

    from PIL import Image

    chromium = Chromium()
    try:
        page = chromium.open(Path(page_path).resolve().as_uri(), 1, width, height)
        page.pose(time)
        png = page.page.screenshot()
    finally:
        chromium.close()
    image = Image.open(io.BytesIO(png)).convert("RGB")
    palette = image.quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    image.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG).save(out, optimize=True)


if __name__ == "__main__":
    save_picture(sys.argv[1], sys.argv[2])
