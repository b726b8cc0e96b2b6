"""Headless Chromium (Debian's /usr/bin/chromium, driven by Playwright) for the page tests."""

from __future__ import annotations

import io
import os
import shutil

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


class Page:
    """One page in headless Chromium, with the meshcat viewer's scene loaded."""

    def __init__(self, url: str, meshes: int, width: int = 640, height: int = 480):
        from playwright.sync_api import sync_playwright

        self._playwright = sync_playwright().start()
        self._browser = self._playwright.chromium.launch(
            executable_path=require_chromium(), args=ARGS, headless=True)
        self.page = self._browser.new_page(viewport={"width": width, "height": height})
        self.page.goto(url, wait_until="load", timeout=120_000)
        # meshes arrive over the websocket after load on the live page: wait for all of them
        self.page.wait_for_function(f"() => ({COUNT_MESHES})() >= {meshes}", timeout=120_000)

    def meshes(self) -> int:
        return self.page.evaluate(COUNT_MESHES)

    def screenshot(self, time: float | None = None, hide: str | None = None) -> np.ndarray:
        """RGB image of the canvas, at animation ``time`` (s), with robot ``hide`` hidden."""
        from PIL import Image

        node = f"viewer.scene_tree.find(['meshcat', '{hide}']).object"  # the viewer's root
        script = "viewer.animator.pause();"
        if time is not None:
            script += f"viewer.animator.seek({time});"
        if hide is not None:
            script += f"{node}.visible = false;"
        script += "viewer.render();"
        self.page.evaluate(f"() => {{ {script} }}")
        png = self.page.locator("canvas").first.screenshot()
        if hide is not None:
            self.page.evaluate(f"() => {{ {node}.visible = true; }}")
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)

    def close(self) -> None:
        self._browser.close()
        self._playwright.stop()


def changed_fraction(a: np.ndarray, b: np.ndarray, tol: int = 30) -> float:
    """Fraction of pixels whose colour differs by more than ``tol`` in some channel."""
    return float(np.mean(np.abs(a - b).max(axis=2) > tol))
