"""Make docs/images/dashboard.png: ``servobus dashboard --sim 4`` in headless Chromium, 1400x1000, after
its motors have moved a few seconds.

    python docs/screenshot.py [OUT.png] [--after SECONDS] [--field NAME]

Needs the test extra and Debian's chromium and chromium-driver (the page tests' browser:
tests/dashboard/_browser.py, whose helpers this uses).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from selenium.webdriver.support.ui import Select

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from dashboard._browser import HEIGHT, WIDTH, chromium, wait_for  # noqa: E402
from dashboard._serving import dashboard  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=ROOT / "docs" / "images" / "dashboard.png")
    parser.add_argument("--after", type=float, default=4.0, help="seconds of motion before the picture")
    parser.add_argument("--field", default="angle_deg", help="the field plotted (with its set-point)")
    args = parser.parse_args()
    with chromium() as browser, dashboard("--sim", "4", "--listen", "127.0.0.1:0") as served:
        # (the page itself WIDTH x HEIGHT, whatever the window's frame takes)
        browser.execute_cdp_cmd(
            "Emulation.setDeviceMetricsOverride",
            {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False},
        )
        browser.get(served.url)
        wait_for(browser, lambda d: d.find_element("id", "conn").text == "live", "the page never went live")
        field = f'#field option[value="{args.field}"]'
        wait_for(browser, lambda d: d.find_elements("css selector", field), f"no field {args.field}")
        Select(browser.find_element("id", "field")).select_by_value(args.field)
        browser.execute_script("document.activeElement.blur();")  # (no focus ring in the picture)
        time.sleep(args.after)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        if not browser.save_screenshot(str(args.out)):
            raise SystemExit(f"no screenshot written to {args.out}")
    print(args.out)


if __name__ == "__main__":
    main()
