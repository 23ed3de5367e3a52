"""docs/recording.md's "Logging both directions of a link with TapLink": its Python examples run as
written (each in its own process and directory) and print what the page says they print; and
TapLink's docstring says what the page relies on."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from servobus.tools.recording import TapLink

PAGE = Path(__file__).resolve().parents[1] / "docs" / "recording.md"
SECTION = "## Logging both directions of a link with TapLink"


def _section() -> str:
    text = PAGE.read_text(encoding="utf-8")
    assert SECTION in text
    return text.split(SECTION, 1)[1].split("\n## ", 1)[0]


def _blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", _section(), re.S)


def _run(code: str, cwd: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_section_has_two_examples_and_their_outputs() -> None:
    assert len(_blocks("python")) == 2 and len(_blocks("text")) == 2


def test_the_tap_example_logs_both_directions_and_the_safe_stop(tmp_path: Path) -> None:
    out = _run(_blocks("python")[0], tmp_path).splitlines()
    said = _blocks("text")[0].splitlines()
    pattern = re.compile(r"^ *(\d+\.\d{3}) ms (->|<-) ([0-9A-F]{3}#[0-9A-F]{16})$")
    got = [pattern.match(line) for line in out]
    assert all(got), out
    expected = [pattern.match(line) for line in said]
    assert all(expected), said
    # the same frames, the same directions, in the same order as the page says; only the times vary
    assert [(m.group(2), m.group(3)) for m in got] == [(m.group(2), m.group(3)) for m in expected]  # type: ignore[union-attr]
    times = [float(m.group(1)) for m in got]  # type: ignore[union-attr]
    assert times[0] == 0.0 and times == sorted(times) and times[-1] < 50.0


def test_the_candump_example_writes_a_log_that_decodes(tmp_path: Path) -> None:
    out = _run(_blocks("python")[1], tmp_path)
    assert out.splitlines() == _blocks("text")[1].splitlines()
    log = (tmp_path / "frames.log").read_text().splitlines()
    assert [line.split()[-1] for line in log] == ["T", "R"]  # python-can's candump marks: sent, received


@pytest.mark.parametrize(
    "said",
    [
        "received=False",
        "received=True",
        "must not block",
        "must not raise",
        "Args:",
        "clock:",
        "docs/recording.md",
    ],
)
def test_the_docstrings_say_it(said: str) -> None:
    import servobus.tools.recording as recording

    assert said in (TapLink.__doc__ or "") + (recording.__doc__ or "")
