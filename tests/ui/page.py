"""What a test reads off the labeler's page."""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image
from playwright.sync_api import Browser, Page

VIEWPORT = {"width": 1024, "height": 640}
TIMEOUT_S = 90.0  # generous: a shared 2-core machine runs software WebGL many times slower when busy

_SEGMENT_ID = """() => {
  const p = [...document.querySelectorAll("p")].find((e) => e.textContent.startsWith("Segment "));
  return p ? p.querySelector("code")?.textContent ?? null : null;
}"""


def open_labeler(browser: Browser, url: str) -> Page:
    context = browser.new_context(viewport=VIEWPORT)
    context.set_default_timeout(TIMEOUT_S * 1000)
    page = context.new_page()
    page.goto(url)
    return page


def segment_id(page: Page) -> str | None:
    return page.evaluate(_SEGMENT_ID)


def wait_segment(page: Page, not_id: str | None = None, timeout_s: float = TIMEOUT_S) -> str:
    """The id of the segment on screen, once it differs from `not_id`."""
    page.wait_for_function(
        f"(old) => {{ const id = ({_SEGMENT_ID})(); return id !== null && id !== old; }}",
        arg=not_id,
        timeout=timeout_s * 1000,
    )
    found = segment_id(page)
    assert found is not None
    return found


def wait_text(page: Page, text: str, timeout_s: float = TIMEOUT_S) -> None:
    page.get_by_text(text).first.wait_for(timeout=timeout_s * 1000)


def canvas_until(
    page: Page, save_as: Path, ok: Callable[[np.ndarray], bool], timeout_s: float = TIMEOUT_S
) -> np.ndarray:
    """The 3D canvas as an (H, W, 3) array, re-taken until `ok(pixels)` holds or `timeout_s` runs
    out: the last one taken, for the test to assert on. Software WebGL on a busy machine may draw the
    scene seconds after the page shows it. The last canvas is saved as `save_as`, the page beside it."""
    canvas = page.locator("canvas").first
    deadline = time.monotonic() + timeout_s
    while True:
        png = canvas.screenshot(path=str(save_as))
        pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
        if ok(pixels) or time.monotonic() >= deadline:
            break
        time.sleep(0.5)
    page.screenshot(path=str(save_as.with_name(save_as.stem + "-page.png")))
    return pixels
