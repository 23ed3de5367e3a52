"""``servobus plot``: a PNG of position, speed and current per motor from what ``record`` wrote against
the simulator; without matplotlib one line telling how to install it (exit 1)."""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import pytest

from _cli_run import invoke, moving_sim, one_line_error

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert data[-8:-4] == b"IEND"  # written whole
    return width, height


@pytest.mark.parametrize("suffix", [".csv", ".jsonl"])
def test_a_recording_plots_to_a_png_of_the_size_asked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    moving_sim(monkeypatch)
    telemetry, image = tmp_path / f"run{suffix}", tmp_path / "run.png"
    invoke(["record", "--sim", "2", "--duration", "0.15", "-o", str(telemetry)])
    result = invoke(["plot", str(telemetry), "-o", str(image), "--size", "640x480", "--title", "bench"])
    assert _png_size(image) == (640, 480)
    assert result.stderr.startswith("plot: ") and "2 motors" in result.stderr


def test_the_default_size_and_other_families(tmp_path: Path) -> None:
    telemetry, image = tmp_path / "lk.csv", tmp_path / "lk.png"
    invoke(["record", "--family", "lk", "--sim", "1", "--duration", "0.1", "-o", str(telemetry)])
    invoke(["plot", str(telemetry), "-o", str(image)])
    assert _png_size(image) == (1200, 900)


def test_without_matplotlib_one_line_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    telemetry = tmp_path / "run.csv"
    telemetry.write_text("time_s,motor_id,speed_dps\n0.0,1,1.0\n")
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
    err = one_line_error(capsys, ["plot", str(telemetry), "-o", str(tmp_path / "x.png")], code=1)
    assert "pip install 'servobus[plot]'" in err
    assert not (tmp_path / "x.png").exists()


def test_files_that_hold_no_telemetry_are_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    empty, other, broken = tmp_path / "empty.csv", tmp_path / "other.csv", tmp_path / "broken.jsonl"
    empty.write_text("")
    other.write_text("a,b\n1,2\n")
    broken.write_text("{not json\n")
    for path, says in ((empty, "no telemetry rows"), (other, "no position"), (broken, "not a record")):
        assert says in one_line_error(capsys, ["plot", str(path), "-o", str(tmp_path / "x.png")], code=1)
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["-o", "out.jpg"], ".png"),
        (["-o", "exists.png"], "exists"),
        (["-o", "out.png", "--size", "big"], "WIDTHxHEIGHT"),
        (["-o", "out.png", "--size", "5x5"], "WIDTHxHEIGHT"),
        ([], "-o"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    says: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("run.csv").write_text("time_s,motor_id,speed_dps\n0.0,1,1.0\n")
    Path("exists.png").write_bytes(b"mine")
    assert says in one_line_error(capsys, ["plot", "run.csv", *args])
    assert Path("exists.png").read_bytes() == b"mine"
    assert "missing.csv" in one_line_error(capsys, ["plot", "missing.csv", "-o", "out.png"])
