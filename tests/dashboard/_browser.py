"""Headless Chromium through selenium for the dashboard's page tests: the system's chromium and
chromedriver (Debian's ``chromium`` and ``chromium-driver``), never a browser downloaded at run time.

Where they are missing the tests skip with one line, unless ``SERVOBUS_REQUIRE_BROWSER=1`` (CI: .ci/run
installs them), where that fails instead.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, TypeVar

import pytest

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

T = TypeVar("T")

WIDTH, HEIGHT = 1400, 1000
INSTALL = "apt-get install chromium chromium-driver"


def _found(*names: str) -> str | None:
    for name in names:
        path = shutil.which(name) or (f"/usr/bin/{name}" if os.access(f"/usr/bin/{name}", os.X_OK) else None)
        if path:
            return path
    return None


def browser_paths() -> tuple[str, str]:
    """(chromium, chromedriver); a skip, or where the browser is required a failure, without them."""
    missing, hints = [], []
    try:
        import selenium  # noqa: F401
    except ModuleNotFoundError:
        missing.append("selenium")
        hints.append("pip install 'servobus[test]'")
    chromium = _found("chromium", "chromium-browser")
    driver = _found("chromedriver")
    if chromium is None or driver is None:
        missing += [name for name, path in (("chromium", chromium), ("chromedriver", driver)) if not path]
        hints.append(INSTALL)
    if missing:
        why = f"no headless Chromium for the page tests: {', '.join(missing)} not found ({'; '.join(hints)})"
        if os.environ.get("SERVOBUS_REQUIRE_BROWSER") == "1":
            pytest.fail(why + " (SERVOBUS_REQUIRE_BROWSER=1)", pytrace=False)
        pytest.skip(why)
    assert chromium is not None and driver is not None
    return chromium, driver


@contextlib.contextmanager
def chromium(width: int = WIDTH, height: int = HEIGHT) -> Iterator[WebDriver]:
    """A headless Chromium whose page is ``width`` x ``height``, quit on the way out."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary, driver_path = browser_paths()
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(arg)
    options.add_argument(f"--window-size={width},{height}")
    # (the driver's path given: selenium-manager, which would download one, is never run)
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    try:
        driver.set_script_timeout(10)
        driver.set_page_load_timeout(20)
        yield driver
    finally:
        driver.quit()


def wait_for(
    driver: WebDriver, what: Callable[[WebDriver], T | None], message: str, timeout_s: float = 10.0
) -> T:
    """``what(driver)`` once it is truthy, waited for at most ``timeout_s``."""
    from selenium.webdriver.support.ui import WebDriverWait

    result = WebDriverWait(driver, timeout_s, poll_frequency=0.05).until(what, message)
    assert result is not None  # (until returns only a truthy value)
    return result


def script(driver: WebDriver, text: str, *args: Any) -> Any:
    """``text`` run in the page (read the DOM in one go: the page redraws its tables every update)."""
    return driver.execute_script(text, *args)
