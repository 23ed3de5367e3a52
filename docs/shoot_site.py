"""Full-page screenshots of the built site in headless Chromium: home, tutorial and the Bus's API page.

    python docs/shoot_site.py OUT_DIR [--page PATH ...] [--dark] [--width 1400]

Builds the site as CI does (``mkdocs build --strict``) into a temporary folder, serves it on loopback
(http.server in a thread) and writes one PNG per page into OUT_DIR (``home.png``, ``tutorial.png``,
``api-servobus.png``; a ``--page`` path is named after its path). Needs the docs and test extras and
Debian's chromium and chromium-driver (the page tests' browser: tests/dashboard/_browser.py).
"""

from __future__ import annotations

import argparse
import base64
import functools
import http.server
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from dashboard._browser import chromium, wait_for  # noqa: E402

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

#: The pages shot by default: (site path, image name).
PAGES = [("", "home"), ("tutorial/", "tutorial"), ("api/servobus/", "api-servobus")]
#: Material hides the header's tabs once the page is scrolled, which a full-page capture does: shown.
_SHOWN_TABS = """
const style = document.createElement('style');
style.textContent = '.md-tabs[hidden] .md-tabs__link {opacity: 1 !important; transform: none !important;'
    + ' transition: none !important}';
document.head.appendChild(style);
"""
#: Chromium draws no taller image than this (and a viewer shows none usefully).
MAX_HEIGHT = 16000


def build(site: Path) -> None:
    """The site built as CI builds it (a warning fails it)."""
    subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(site)], cwd=ROOT, check=True
    )


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@contextmanager
def served(site: Path) -> Iterator[str]:
    """``site`` served on loopback; yields its base URL."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        thread.join()


def shoot(browser: WebDriver, url: str, out: Path, width: int, dark: bool) -> None:
    """One full-page PNG of ``url`` (its whole height, up to MAX_HEIGHT)."""
    browser.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})  # (the last page's height)
    browser.get(url)
    wait_for(browser, lambda d: d.execute_script("return document.readyState") == "complete", url)
    if dark:  # (the scheme material's toggle would set on the page)
        browser.execute_script("document.body.setAttribute('data-md-color-scheme', 'slate')")
    height = min(int(browser.execute_script("return document.documentElement.scrollHeight")), MAX_HEIGHT)
    browser.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride",
        {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
    )
    browser.execute_script(_SHOWN_TABS)
    time.sleep(0.5)  # (the layout settles at the new height)
    shot = browser.execute_cdp_cmd(
        "Page.captureScreenshot",
        {
            "format": "png",
            "captureBeyondViewport": True,
            "clip": {"x": 0, "y": 0, "width": width, "height": height, "scale": 1},
        },
    )
    out.write_bytes(base64.b64decode(shot["data"]))
    print(out, f"{width}x{height}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the folder the images go to")
    parser.add_argument("--page", action="append", default=[], help="another page's site path (api/loop/)")
    parser.add_argument("--dark", action="store_true", help="the dark scheme")
    parser.add_argument("--width", type=int, default=1400)
    args = parser.parse_args()
    pages = PAGES + [(p, p.strip("/").replace("/", "-") or "home") for p in args.page]
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        site = Path(tmp) / "site"
        build(site)
        with served(site) as base, chromium(args.width) as browser:
            for path, name in pages:
                suffix = "-dark" if args.dark else ""
                shoot(browser, base + path, args.out / f"{name}{suffix}.png", args.width, args.dark)


if __name__ == "__main__":
    main()
