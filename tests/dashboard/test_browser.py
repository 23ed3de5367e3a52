"""The dashboard's page in headless Chromium (issue 40): ``servobus dashboard --sim 4`` as a user sees it.

The read-only tests share one dashboard and one browser (module-scoped); the test that stops motors has
its own dashboard, as has the trio one. Every wait is bounded (WebDriverWait); every dashboard is killed
on the way out.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import pytest

from dashboard._browser import chromium, script, wait_for
from dashboard._serving import Served, dashboard

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

KEYS = [f"sim/{n}" for n in range(1, 5)]
LISTEN = ("--listen", "127.0.0.1:0")

# Every motor row's cells, read at once (the page redraws them on every update).
ROWS = """
const out = {};
for (const row of document.querySelectorAll('#motors tbody tr')) {
  const cells = {};
  for (const td of row.querySelectorAll('td[data-col]')) cells[td.dataset.col] = td.textContent;
  out[row.dataset.key] = cells;
}
return out;
"""
FRAMES = """
return [...document.querySelectorAll('#frames tbody tr')].map((row) => {
  const cells = {};
  for (const td of row.querySelectorAll('td[data-col]')) cells[td.dataset.col] = td.textContent;
  return cells;
});
"""


@pytest.fixture(scope="module")
def browser() -> Iterator[WebDriver]:
    with chromium() as driver:
        yield driver


@pytest.fixture(scope="module")
def sim4(browser: WebDriver) -> Iterator[Served]:
    """A read-only dashboard of 4 moving simulated motors (nothing here stops them)."""
    with dashboard("--sim", "4", *LISTEN) as served:
        yield served
        assert "Traceback" not in served.stderr(), served.stderr()


def rows(driver: WebDriver) -> dict[str, dict[str, str]]:
    found: dict[str, dict[str, str]] = script(driver, ROWS)
    return found


def field(row: dict[str, str], name: str) -> float:
    """A field's number in a row's ``fields`` cell (``speed_dps -114  angle_deg -41.5``)."""
    found = re.search(rf"\b{name}\s(-?\d+(?:\.\d+)?)\b", row["fields"])
    assert found, f"no {name} in {row['fields']!r}"
    return float(found.group(1))


# Over a second: a stopped motor's angle stays within a rounding step or two of the replies' whole
# degrees (the simulated motor settles); a moving one, on the demo's sine (90 degrees, 4 s), sweeps at
# least 90 x (1 - cos 45 degrees) = 26 degrees in any quarter period.
STILL_DEG, MOVING_DEG = 2.0, 10.0


def sweeps(driver: WebDriver, keys: list[str], seconds: float = 1.0) -> dict[str, float]:
    """How far each motor's angle ranged over ``seconds`` (sampled each 0.1 s)."""
    seen: dict[str, list[float]] = {k: [] for k in keys}
    for _ in range(round(seconds / 0.1)):
        now = rows(driver)
        for key in keys:
            seen[key].append(field(now[key], "angle_deg"))
        time.sleep(0.1)
    return {k: max(v) - min(v) for k, v in seen.items()}


def frames(driver: WebDriver) -> list[dict[str, str]]:
    found: list[dict[str, str]] = script(driver, FRAMES)
    return found


def open_page(driver: WebDriver, served: Served, motors: int = 4) -> None:
    """Load the page and wait until it is live with ``motors`` rows."""
    from selenium.common.exceptions import TimeoutException

    driver.get(served.url)
    try:
        wait_for(driver, lambda d: d.find_element("id", "conn").text == "live", "#conn never said live")
    except TimeoutException as exc:
        raise AssertionError(f"{exc.msg}; the dashboard's stderr: {served.stderr()!r}") from None
    wait_for(driver, lambda d: len(rows(d)) == motors, f"never {motors} motor rows")


def test_page_names_every_motor(browser: WebDriver, sim4: Served) -> None:
    open_page(browser, sim4)
    seen = rows(browser)
    assert sorted(seen) == KEYS
    for n, key in enumerate(KEYS, 1):
        row = seen[key]
        assert (row["bus"], row["id"], row["family"]) == ("sim", str(n), "myactuator"), row
        assert row["status"] == "online", row
    assert browser.title == "servobus dashboard"
    assert browser.find_element("id", "mode").text == "read-only"


# How many pixels of a plot's canvas are about ``rgb`` (a line's colour, anti-aliased at its edges).
INKED = """
const [id, rgb] = arguments;
const canvas = document.querySelector('#' + id + ' .uplot canvas');
const px = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
let n = 0;
for (let i = 0; i < px.length; i += 4) {
  if (px[i + 3] > 200 && [0, 1, 2].every((c) => Math.abs(px[i + c] - rgb[c]) < 24)) n++;
}
return n;
"""
SIM1_BLUE = (0x1F, 0x77, 0xB4)  # the page's first colour: sim/1's line, the bus's load, the loop's lateness
MIN_INK = 200  # pixels: a line across the plot, not a legend's swatch


def test_numbers_and_plot_change_over_3_s(browser: WebDriver, sim4: Served) -> None:
    open_page(browser, sim4)
    canvas = "return document.querySelector('#plot .uplot canvas').toDataURL();"
    # (the plot drawn once with its lines: a legend entry per motor's field)
    wait_for(browser, lambda d: "sim/1 speed_dps" in d.find_element("id", "plot").text, "no sim/1 line")
    before, picture = rows(browser), script(browser, canvas)
    swept = sweeps(browser, KEYS, 3.0)
    after, later = rows(browser), script(browser, canvas)
    for key in KEYS:
        assert before[key]["fields"] != after[key]["fields"], (key, before[key], after[key])
        assert swept[key] > MOVING_DEG, swept
    assert picture != later, "the plot's canvas did not change in 3 s"
    # its lines are drawn (not only axes that follow the time): sim/1's colour across the canvas, and
    # the buses' and the loop's plots have lines too
    assert script(browser, INKED, "plot", SIM1_BLUE) > MIN_INK, "no sim/1 line in the plot"
    assert script(browser, INKED, "plot-bus", SIM1_BLUE) > MIN_INK, "no line in the bus plot"
    assert script(browser, INKED, "plot-loop", SIM1_BLUE) > MIN_INK, "no line in the loop plot"


LEGEND = "return [...document.querySelectorAll('#plot .u-legend .u-label')].map((l) => l.textContent);"


def test_plot_shows_a_chosen_field_of_chosen_motors_beside_its_set_point(
    browser: WebDriver, sim4: Served
) -> None:
    from selenium.webdriver.support.ui import Select

    open_page(browser, sim4)
    wait_for(
        browser, lambda d: d.find_elements("css selector", '#field option[value="angle_deg"]'), "no field"
    )
    Select(browser.find_element("id", "field")).select_by_value("angle_deg")

    def legend(driver: WebDriver) -> list[str] | None:
        found: list[str] = script(driver, LEGEND)
        return found if "sim/4 set-point" in found else None

    labels = wait_for(browser, legend, "no set-point in the legend")
    assert labels == ["t (s)"] + [
        f"sim/{n} {what}" for n in range(1, 5) for what in ("angle_deg", "set-point")
    ]

    motors = Select(browser.find_element("id", "plot-motors"))
    motors.deselect_all()
    motors.select_by_value("sim/2")
    wait_for(
        browser, lambda d: script(d, LEGEND) == ["t (s)", "sim/2 angle_deg", "sim/2 set-point"], "sim/2 only"
    )
    browser.find_element("id", "show-setpoints").click()
    wait_for(browser, lambda d: script(d, LEGEND) == ["t (s)", "sim/2 angle_deg"], "set-points hidden")


def test_frame_view_shows_decoded_frames_and_filters(browser: WebDriver, sim4: Served) -> None:
    open_page(browser, sim4)

    def decoded(driver: WebDriver) -> dict[str, str] | None:
        """The frames' decoded names and directions, once motor 1's set-point is among them."""
        found = {f["name"]: f["dir"] for f in frames(driver)}
        return found if "AbsolutePositionControl (motor 1)" in found else None

    def shown(count: int) -> Callable[[WebDriver], list[dict[str, str]] | None]:
        return lambda driver: found if len(found := frames(driver)) == count else None

    seen = wait_for(browser, decoded, "no decoded frames")
    assert seen["StatusReply (motor 1)"] == "rx"
    assert seen["AbsolutePositionControl (motor 1)"] == "tx"
    assert {f"StatusReply (motor {n})" for n in range(1, 5)} <= set(seen)

    box = browser.find_element("id", "frame-filter")
    box.send_keys("0x241")
    narrowed = wait_for(browser, shown(1), "filter 0x241")
    assert narrowed[0]["name"] == "StatusReply (motor 1)" and narrowed[0]["id"] == "0x241"
    box.clear()
    box.send_keys("tx")
    tx = wait_for(browser, shown(4), "filter tx")
    assert {f["dir"] for f in tx} == {"tx"}
    assert "4 of 8" in browser.find_element("id", "frame-count").text
    box.clear()
    wait_for(browser, shown(8), "filter cleared")


POST_STOP = """
const done = arguments[arguments.length - 1];
fetch('api/stop', {method: 'POST', headers: {'content-type': 'application/json'},
                   body: JSON.stringify({motors: arguments[0], kind: 'stop'})})
  .then(async (r) => done([r.status, await r.text()]), (e) => done([0, String(e)]));
"""


def test_read_only_page_cannot_stop(browser: WebDriver, sim4: Served) -> None:
    open_page(browser, sim4)
    buttons = browser.find_elements("css selector", "button.stop, button.off, #stop-all, #off-all")
    assert len(buttons) == 2 * 4 + 2
    assert all(not b.is_enabled() for b in buttons)

    # the page's own origin asks anyway: refused, and the motor goes on
    status, body = browser.execute_async_script(POST_STOP, ["sim/1"])
    assert status == 403, body
    assert "read-only" in body
    status, body = browser.execute_async_script(POST_STOP, "all")
    assert status == 403, body
    swept = sweeps(browser, ["sim/1"])
    assert swept["sim/1"] > MOVING_DEG, swept


def stopped(driver: WebDriver, keys: list[str]) -> bool:
    """Each motor's latest reply says speed 0 (the stop's own reply, which has no fields, does not)."""
    now = rows(driver)
    return all("speed_dps" in now[k]["fields"] and field(now[k], "speed_dps") == 0 for k in keys)


def test_stop_buttons_stop_motors(browser: WebDriver) -> None:
    with dashboard("--sim", "4", "--allow-commands", *LISTEN) as served:
        open_page(browser, served)
        assert browser.find_element("id", "mode").text == "commands allowed"
        buttons = browser.find_elements("css selector", "button.stop, button.off, #stop-all, #off-all")
        assert buttons and all(b.is_enabled() for b in buttons)

        # one motor's stop: it stops and stays stopped, the others go on
        browser.find_element("css selector", 'button.stop[data-key="sim/2"]').click()
        wait_for(browser, lambda d: "acknowledged by sim/2" in d.find_element("id", "message").text, "no ack")
        assert "not acknowledged" not in browser.find_element("id", "message").text
        wait_for(browser, lambda d: stopped(d, ["sim/2"]), "sim/2 never stopped")
        swept = sweeps(browser, KEYS)
        assert stopped(browser, ["sim/2"]), rows(browser)["sim/2"]
        assert swept["sim/2"] <= STILL_DEG, swept
        assert all(swept[k] > MOVING_DEG for k in ("sim/1", "sim/3", "sim/4")), swept

        # stop all: every one
        browser.find_element("id", "stop-all").click()
        wait_for(
            browser,
            lambda d: "acknowledged by sim/1, sim/2, sim/3, sim/4" in d.find_element("id", "message").text,
            "stop all not acknowledged",
        )
        wait_for(browser, lambda d: stopped(d, KEYS), "not all stopped")
        swept = sweeps(browser, KEYS)
        assert stopped(browser, KEYS), rows(browser)
        assert all(swept[k] <= STILL_DEG for k in KEYS), swept

        # a motor's off is sent and acknowledged too
        browser.find_element("css selector", 'button.off[data-key="sim/3"]').click()
        wait_for(browser, lambda d: d.find_element("id", "message").text.startswith("off: "), "no off")
        assert browser.find_element("id", "message").text == "off: acknowledged by sim/3"
        assert "Traceback" not in served.stderr(), served.stderr()


def test_page_works_on_trio(browser: WebDriver) -> None:
    with dashboard("--sim", "4", "--backend", "trio", *LISTEN) as served:
        open_page(browser, served)
        assert sorted(rows(browser)) == KEYS
        before = rows(browser)["sim/1"]["fields"]
        wait_for(browser, lambda d: rows(d)["sim/1"]["fields"] != before, "no update on trio")
        assert "Traceback" not in served.stderr(), served.stderr()
