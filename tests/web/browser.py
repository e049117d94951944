"""Headless Chromium for the page tests (Debian's chromium and chromium-driver, driven by
Selenium 4): start one, wait on the page's own state, read its console, and save
screenshots checked not to be blank."""

from __future__ import annotations

import base64
import os
import shutil
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from selenium import webdriver
from selenium.webdriver.common.by import By
from selenium.webdriver.remote.webelement import WebElement
from selenium.webdriver.support.ui import WebDriverWait

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WAIT_S = 10.0            # generous: a busy 2-core machine
SIZE = (1280, 900)       # the window, unless a test asks for another
SCREENSHOTS = "SONIBUS_SCREENSHOTS"  # a folder the screenshots are also written to (docs/img for the README)

# The screenshot, decoded by Chromium itself (no PIL here): how many colours, and the
# share of pixels unlike the most common one, over every 3rd pixel.
_PIXELS = """
const [data, done] = [arguments[0], arguments[arguments.length - 1]];
const image = new Image();
image.onerror = () => done(null);
image.onload = () => {
  const canvas = document.createElement("canvas");
  canvas.width = image.width; canvas.height = image.height;
  const g = canvas.getContext("2d");
  g.drawImage(image, 0, 0);
  const d = g.getImageData(0, 0, canvas.width, canvas.height).data;
  const counts = new Map();
  let n = 0;
  for (let i = 0; i < d.length; i += 12) {
    const colour = (d[i] << 16) | (d[i + 1] << 8) | d[i + 2];
    counts.set(colour, (counts.get(colour) || 0) + 1);
    n += 1;
  }
  done({colours: counts.size, other: 1 - Math.max(...counts.values()) / n});
};
image.src = "data:image/png;base64," + data;
"""


@dataclass(frozen=True)
class Shot:
    """A screenshot: where it was saved, its size, and how much is on it."""

    path: Path
    width: int
    height: int
    colours: int     # distinct colours (sampled)
    other: float     # share of pixels unlike the background

    @property
    def blank(self) -> bool:
        return self.colours < 16 or self.other < 0.02


class Browser:
    """A headless Chromium with its own profile in ``profile``; ``quit()`` always."""

    def __init__(self, profile: Path) -> None:
        for path, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
            if not shutil.which(path):
                pytest.fail(f"{path} is not installed: apt-get install {package} (scripts/test-tools.sh does)")
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={SIZE[0]},{SIZE[1]}",
                         f"--user-data-dir={profile}", "--disable-dev-shm-usage", "--no-first-run",
                         "--disable-background-networking", "--disable-extensions"):
            options.add_argument(argument)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        service = webdriver.ChromeService(executable_path=CHROMEDRIVER)
        self.driver = webdriver.Chrome(service=service, options=options)
        self.console: list[dict[str, Any]] = []

    def quit(self) -> None:
        self.driver.quit()

    def open(self, url: str, size: tuple[int, int] = SIZE) -> None:
        """Open ``url`` in a window of ``size`` (width, height of the page's viewport, CSS px)."""
        self.driver.get("about:blank")  # the previous page is gone (its server too, maybe: it would retry) ...
        self.driver.get_log("browser")  # ... and what it said stays with it
        self.console.clear()
        shown = tuple(self.js("return [innerWidth, innerHeight]"))
        if shown != size:  # (tests share one browser) the window's outer size: its frame, if any, added
            outer = self.driver.get_window_size()
            self.driver.set_window_size(outer["width"] + size[0] - shown[0], outer["height"] + size[1] - shown[1])
            shown = tuple(self.js("return [innerWidth, innerHeight]"))
            assert shown == size, f"asked for a {size} viewport, Chromium shows {shown}"
        self.driver.get(url)

    def wait(self, condition: Callable[[], Any], what: str, timeout: float = WAIT_S) -> Any:
        """``condition()``'s first truthy value, polled; a timeout names ``what`` and the status line."""
        try:
            return WebDriverWait(self.driver, timeout, poll_frequency=0.02).until(lambda _: condition())
        except Exception as exc:  # TimeoutException, or the condition's own error after the deadline
            pytest.fail(f"timed out after {timeout} s waiting for {what} ({type(exc).__name__}); "
                        f"page status: {self.text('#status')!r}; console: {self.errors()}")

    def js(self, script: str, *args: Any) -> Any:
        return self.driver.execute_script(script, *args)

    def find(self, css: str) -> WebElement:
        return self.driver.find_element(By.CSS_SELECTOR, css)

    def all(self, css: str) -> list[WebElement]:
        return self.driver.find_elements(By.CSS_SELECTOR, css)

    # Read in one script: the page may replace an element between a find and a read (the nodes table).
    def text(self, css: str) -> str | None:
        """The shown text of the first element matching ``css`` (None: there is none)."""
        return self.js("const e = document.querySelector(arguments[0]); return e ? e.innerText.trim() : null", css)

    def attribute(self, css: str, name: str) -> str | None:
        return self.js("const e = document.querySelector(arguments[0]); return e ? e.getAttribute(arguments[1]) : null",
                       css, name)

    def attributes(self, css: str, name: str) -> list[str | None]:
        """Attribute ``name`` of every element matching ``css``, in document order."""
        return self.js("return [...document.querySelectorAll(arguments[0])].map((e) => e.getAttribute(arguments[1]))",
                       css, name)

    def read_console(self) -> list[dict[str, Any]]:
        self.console.extend(self.driver.get_log("browser"))
        return self.console

    def errors(self) -> list[str]:
        """The page's console errors (script errors, failed loads) so far."""
        return [entry["message"] for entry in self.read_console() if entry["level"] == "SEVERE"]

    def screenshot(self, name: str, folder: Path, publish: bool = False) -> Shot:
        """Save the window as ``folder/name`` (and, if ``publish``, in $SONIBUS_SCREENSHOTS when set)."""
        png = self.driver.get_screenshot_as_png()
        assert png[:8] == b"\x89PNG\r\n\x1a\n", "the screenshot is not a PNG"
        width, height = struct.unpack(">II", png[16:24])  # the IHDR chunk comes first
        paths = [folder / name]
        if publish and os.environ.get(SCREENSHOTS):
            paths.append(Path(os.environ[SCREENSHOTS]) / name)
        for path in paths:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(png)
        seen = self.driver.execute_async_script(_PIXELS, base64.b64encode(png).decode("ascii"))
        assert seen is not None, f"Chromium could not decode its own screenshot {paths[0]}"
        return Shot(paths[0], width, height, seen["colours"], seen["other"])

