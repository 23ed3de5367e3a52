"""``servobus bench``: the benchmarks' quick mode from the source tree, as one table of their figures;
without bench/ (an installed wheel) one line and exit 1."""

from __future__ import annotations

from pathlib import Path

import pytest

import servobus.cli.bench as bench
from cli._bus_cli import one_line, run, run_json

FAKE = """
import json, sys
from pathlib import Path
assert sys.argv[1:3] == ["--quick", "--output"], sys.argv
Path(sys.argv[3], "results.json").write_text(json.dumps({"bus": {
    "cycle32_transactions_s": 101436.0, "efficiency_can1m_32": 1.0, "meta": {"x": 1},
    "targets_missed": ["cycle32_vs_naive = 4.7 (target >= 5.0)"]}}))
print("progress that is not shown")
"""


def test_the_figures_of_each_benchmark_in_one_table(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "bench_bus.py").write_text(FAKE)
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path / "bench")
    out, _ = run(capsys, ["bench", "--only", "bus"])
    assert "cycle32_transactions_s" in out and "101,436" in out and "meta" not in out
    assert "targets missed: bus: cycle32_vs_naive = 4.7" in out and "progress" not in out
    assert run_json(capsys, ["bench", "--only", "bus"])["bus"]["efficiency_can1m_32"] == 1.0
    assert sorted(p.name for p in (tmp_path / "bench").iterdir()) == ["bench_bus.py"]  # nothing written there


def test_the_real_bus_benchmark_quick_mode(capsys: pytest.CaptureFixture[str]) -> None:
    figures = run_json(capsys, ["bench", "--only", "bus"])["bus"]
    assert figures["efficiency_can1m_32"] > 0.9 and figures["cycle32_transactions_s"] > 0


def test_without_bench_folder_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path / "nowhere")
    assert "source checkout" in one_line(capsys, ["bench"], code=1)


def test_a_failing_benchmark_is_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    (tmp_path / "bench_codec.py").write_text("raise SystemExit('broken on purpose')")
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path)
    err = one_line(capsys, ["bench", "--only", "codec"], code=1)
    assert "bench_codec.py --quick failed (exit 1): broken on purpose" in err


def test_an_unknown_benchmark_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert "--only" in one_line(capsys, ["bench", "--only", "nope"])


def test_verbose_json_keeps_stdout_for_the_json(
    capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """--verbose shows the scripts' own output on stderr: stdout is the JSON document alone."""
    import json

    from servobus.cli import main

    (tmp_path / "bench_bus.py").write_text(FAKE)
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path)
    assert main(["bench", "--only", "bus", "--verbose", "--json"]) == 0
    out, err = capfd.readouterr()
    assert json.loads(out)["bus"]["efficiency_can1m_32"] == 1.0
    assert "progress that is not shown" in err
