"""What the tutorial and the hardware guide claim beyond their blocks (which tests/test_docs_pages.py
runs): the real-adapter script is the simulated one with another transport, and the figures they
quote from the benchmarks are bench/results.json's (a rerun of the benchmarks that changes one fails
here until the page says the new figure)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIAL = ROOT / "docs" / "tutorial.md"
HARDWARE = ROOT / "docs" / "guides" / "hardware.md"
RESULTS = json.loads((ROOT / "bench" / "results.json").read_text(encoding="utf-8"))


def _python_blocks(page: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), re.S | re.M)


def _code_lines(block: str) -> list[str]:
    """The block's lines without comments and blank lines (what runs)."""
    lines = (line.split("  #")[0].rstrip() for line in block.splitlines())
    return [line for line in lines if line.strip() and not line.lstrip().startswith("#")]


def test_the_real_adapter_script_is_the_simulated_one_with_another_transport() -> None:
    simulated, real = _python_blocks(TUTORIAL)[:2]
    assert real.startswith("# needs hardware: an SLCAN adapter on /dev/ttyACM0")
    only_simulated = set(_code_lines(simulated)) - set(_code_lines(real))
    only_real = set(_code_lines(real)) - set(_code_lines(simulated))
    # what differs is where the transport is made and imported, nothing else
    assert only_simulated and all("Sim" in line or "MyActuatorMotor" in line for line in only_simulated), (
        only_simulated
    )
    assert all("SlcanTransport" in line for line in only_real), only_real
    assert len(only_real) == 2, only_real


def _figure(text: str) -> float:
    return float(text.replace(",", ""))


# (the words around a figure on the page, the figure's path in bench/results.json, decimals kept:
# None where the page truncates, as a ratio "76x" of 76.47)
QUOTED = [
    (TUTORIAL, r"ran ([\d,]+) ticks/s of 1,000 on the Loop", ("loop1k", "achieved_hz"), 0),
    (TUTORIAL, r"against (\d+) with\s+`Bus.cycle`", ("loop1k", "cycle", "achieved_hz"), 0),
    (TUTORIAL, r"kept (\d+) ticks/s \(`bench/RESULTS.md`", ("loop1k", "cycle", "achieved_hz"), 0),
    (TUTORIAL, r"were p50 ([\d.]+) ms", ("loop1k", "state_age_p50_ms"), 2),
    (TUTORIAL, r"and p99 ([\d.]+) ms old", ("loop1k", "state_age_p99_ms"), 2),
    (TUTORIAL, r"host at (\d+) %", ("loop1k", "host_cpu_pct"), 0),
    (TUTORIAL, r"Loop costs ([\d,]+) µs", ("loop", "host_us_per_tick"), 0),
    (HARDWARE, r"received ([\d,]+) frames/s over a pty", ("transport", "slcan_native_frames_s"), 0),
    (HARDWARE, r"`slcan` received\s+([\d,]+)", ("transport", "slcan_python_can_frames_s"), 0),
    (HARDWARE, r"\((\d+)x; `bench/RESULTS.md`", ("transport", "slcan_vs_python_can"), None),
]


@pytest.mark.parametrize(("page", "words", "key", "decimals"), QUOTED, ids=[q[1][:30] for q in QUOTED])
def test_a_quoted_benchmark_figure_is_the_results_file_s(
    page: Path, words: str, key: tuple[str, ...], decimals: int | None
) -> None:
    found = re.search(words, page.read_text(encoding="utf-8"))
    assert found, f"{page.name} no longer says {words!r}"
    value = RESULTS
    for part in key:
        value = value[part]
    expected = int(value) if decimals is None else round(value, decimals)
    assert _figure(found.group(1)) == expected, (key, value, found.group(0))
