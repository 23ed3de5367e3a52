"""``servobus bench``: the front of ``python -m bench``; its quick mode (by default) or its full run
(``--full``, only with a fake runner here), as one table of every part's figures; outside a clone of
the repository (an installed wheel run elsewhere) one line saying to run it from a clone, and exit 2."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import click
import pytest

import servobus.cli.bench as bench
from cli._bus_cli import one_line, run, run_json

RUNNER = Path(__file__).resolve().parents[2] / "bench" / "__main__.py"

#: a stand-in for ``python -m bench``: records its arguments in $FAKE_ARGV, writes figures for the
#: parts asked to --output (or to its own folder: the full run), a missed target when $FAKE_MISSED
FAKE = """
import json, os, sys
from pathlib import Path
args = sys.argv[1:]
Path(os.environ["FAKE_ARGV"]).write_text(json.dumps(args))
only = [args[i + 1] for i, a in enumerate(args) if a == "--only"] or ["codec", "bus", "loop1k"]
only = [p for p in only if p not in [args[i + 1] for i, a in enumerate(args) if a == "--skip"]]
out = Path(args[args.index("--output") + 1]) if "--output" in args else Path(__file__).parent
missed = [os.environ["FAKE_MISSED"]] if os.environ.get("FAKE_MISSED") else []
figures = {
    "codec": {"crc16_mb_s": 512.25, "targets_missed": []},
    "bus": {"cycle32_transactions_s": 101436.0, "efficiency_can1m_32": 1.0, "is_flagged": True,
            "command": "python bench/bench_bus.py --quick", "sizes_list": [1, 4, 32],
            "meta": {"runtime_s": 1.5}, "detail": {"read": {"turnaround_s": 0.00025}},
            "targets_missed": missed},
    "loop1k_fd": {"on_time_pct": 99.9, "layout": {"fd": {"targets_missed": ["deep = 1 (target 2)"]}}},
}
if os.environ.get("FAKE_LOOP1K"):
    figures["loop1k"] = {"on_time_pct": 0.0, "targets_missed": ["loop1k.on_time_pct = 0.0 (target >= 99.5)"]}
    no_host = "loop1k_fd.on_time_pct = 0.0 (target >= 99.5; its bus can carry at most 896/s, so no host can)"
    figures["loop1k_fd"] = {"on_time_pct": 0.0, "targets_missed": [no_host]}
if os.environ.get("FAKE_DISAGREE"):
    figures["codec"]["reference_agrees"] = False
path = out / "results.json"
data = json.loads(path.read_text()) if path.exists() else {}
data.update({k: v for k, v in figures.items() if k.split("_")[0] in only})
path.write_text(json.dumps(data))
print("progress that is not shown")
if "--check" in args and missed:
    print("parts with a missed target (--check): bus")
    sys.exit(1)
"""


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """A fake bench/ folder (``bench/__main__.py`` = FAKE) that ``servobus bench`` runs; the file its
    arguments are recorded in is returned."""
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "__main__.py").write_text(FAKE)
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path / "bench")
    monkeypatch.setenv("FAKE_ARGV", str(tmp_path / "argv.json"))
    for name in ("FAKE_MISSED", "FAKE_LOOP1K", "FAKE_DISAGREE"):
        monkeypatch.delenv(name, raising=False)
    return tmp_path / "argv.json"


def test_the_only_choices_are_the_parts_of_the_runner() -> None:
    """bench/ is no package of the installed servobus: the CLI keeps the parts' names, equal to PARTS."""
    tree = ast.parse(RUNNER.read_text(encoding="utf-8"))
    parts = next(
        ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "PARTS" for t in node.targets)
    )
    assert tuple(parts) == bench.PARTS  # the same parts, in the runner's order
    only = next(p for p in bench.bench.params if p.name == "only")
    assert isinstance(only.type, click.Choice) and tuple(only.type.choices) == tuple(parts)


def test_the_figures_of_each_part_in_one_table(capsys: pytest.CaptureFixture[str], fake: Path) -> None:
    out, _ = run(capsys, ["bench", "--only", "bus", "--only", "loop1k"])
    args = json.loads(fake.read_text())
    assert args[:2] == ["--quick", "--output"] and args[3:] == ["--only", "bus", "--only", "loop1k"]
    assert "cycle32_transactions_s" in out and "101,436" in out and "detail.read.turnaround_s" in out
    assert "loop1k_fd" in out and "on_time_pct" in out and "99.9" in out and "crc16" not in out
    for absent in ("meta", "runtime_s", "is_flagged", "sizes_list", "command", "progress"):
        assert absent not in out, absent
    assert out.rstrip().endswith("targets missed: loop1k_fd: layout: fd: deep = 1 (target 2)")
    written = sorted(p.name for p in fake.parent.joinpath("bench").iterdir())
    assert written == ["__main__.py"]  # nothing written in bench/


def test_every_part_by_default_and_all_targets_met(capsys: pytest.CaptureFixture[str], fake: Path) -> None:
    out, _ = run(capsys, ["bench", "--only", "codec"])
    assert "512.2" in out and out.rstrip().endswith("all targets met")
    run(capsys, ["bench"])
    args = json.loads(fake.read_text())
    assert args[:2] == ["--quick", "--output"] and len(args) == 3  # every part: no --only


def test_json_has_the_dotted_figure_names_of_the_part_asked(
    capsys: pytest.CaptureFixture[str], fake: Path
) -> None:
    figures = run_json(capsys, ["bench", "--only", "bus"])
    bus = {"cycle32_transactions_s": 101436.0, "efficiency_can1m_32": 1.0}
    bus["detail.read.turnaround_s"] = 0.00025  # nested: by its dotted name
    assert figures == {"bus": bus}


def test_check_exits_1_when_a_full_run_target_is_missed(
    capsys: pytest.CaptureFixture[str], fake: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run(capsys, ["bench", "--full", "--only", "bus", "--check"])  # met: 0
    assert "--check" not in json.loads(fake.read_text())  # judged here, from results.json
    monkeypatch.setenv("FAKE_MISSED", "cycle32_vs_floor = 5.8 (target <= 4.0)")
    out, err = run(capsys, ["bench", "--full", "--only", "bus", "--check"], code=1)
    assert "101,436" in out and "targets missed: bus: cycle32_vs_floor = 5.8 (target <= 4.0)" in out
    assert "not judged" not in out and err == ""
    figures = run_json(capsys, ["bench", "--full", "--only", "bus", "--check"], code=1)
    assert figures["bus"]["efficiency_can1m_32"] == 1.0
    out, _ = run(
        capsys, ["bench", "--full", "--only", "bus"]
    )  # without --check, a missed target is only shown
    assert "targets missed: bus: cycle32_vs_floor" in out


def test_check_never_judges_quick_figures_against_full_targets(
    capsys: pytest.CaptureFixture[str], fake: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The quick mode's tiny sizes miss full-run targets by design: shown, marked, exit 0; a C/reference
    disagreement (a wrong result, not a slow one) still fails a quick --check."""
    monkeypatch.setenv("FAKE_MISSED", "cycle32_vs_floor = 5.8 (target <= 4.0)")
    out, _ = run(capsys, ["bench", "--only", "bus", "--check"])
    assert "bus: cycle32_vs_floor = 5.8 (target <= 4.0) [not judged: quick-mode figure]" in out
    monkeypatch.setenv("FAKE_DISAGREE", "1")
    out, _ = run(capsys, ["bench", "--only", "codec", "--check"], code=1)
    assert "codec: C core and reference disagree" in out


def test_check_judges_only_the_parts_run_now(capsys: pytest.CaptureFixture[str], fake: Path) -> None:
    results = fake.parent / "bench" / "results.json"
    results.write_text(json.dumps({"codec": {"crc16_mb_s": 1.0, "targets_missed": ["stale = 1"]}}))
    out, _ = run(capsys, ["bench", "--full", "--only", "bus", "--check"])  # codec's old miss: not judged
    assert "stale" not in out and out.rstrip().endswith("all targets met")


@pytest.mark.parametrize("cores", [2, 8])
def test_check_judges_real_time_targets_only_where_a_host_can_meet_them(
    capsys: pytest.CaptureFixture[str], fake: Path, monkeypatch: pytest.MonkeyPatch, cores: int
) -> None:
    """loop1k is known missed on 2 cores (bench/RESULTS.md): on such a host --check passes over it; a
    target the runner says no host can meet (loop1k_fd's bus bound) is never judged."""
    monkeypatch.setenv("FAKE_LOOP1K", "1")
    monkeypatch.setattr(bench.os, "cpu_count", lambda: cores)
    out, _ = run(capsys, ["bench", "--full", "--only", "loop1k", "--check"], code=0 if cores == 2 else 1)
    assert "loop1k.on_time_pct = 0.0 (target >= 99.5)" in out
    assert ("real-time target, needs >= 4 cores, this host has 2" in out) == (cores == 2)
    assert "so no host can) [not judged: no host can meet it]" in out
    help_text, _ = run(capsys, ["bench", "--help"])
    assert "only parts run now" in help_text and ">= 4 cores" in help_text


def test_skip_and_wait_load_are_passed_to_the_runner(capsys: pytest.CaptureFixture[str], fake: Path) -> None:
    out, _ = run(capsys, ["bench", "--skip", "codec", "--skip", "loop1k", "--wait-load", "1.5"])
    args = json.loads(fake.read_text())
    assert args[3:] == ["--skip", "codec", "--skip", "loop1k", "--wait-load", "1.5"]
    assert "101,436" in out and "crc16" not in out and "loop1k" not in out
    run(capsys, ["bench", "--full", "--only", "bus", "--wait-load", "0.8", "--wait-max-s", "60"])
    assert json.loads(fake.read_text()) == ["--only", "bus", "--wait-load", "0.8", "--wait-max-s", "60"]
    assert "--wait-load" in one_line(capsys, ["bench", "--wait-max-s", "60"])
    assert "no part" in one_line(capsys, ["bench", "--only", "bus", "--skip", "bus"])
    assert "--skip" in one_line(capsys, ["bench", "--skip", "nope"])


def test_full_writes_to_bench_and_shows_only_the_parts_it_ran(
    capsys: pytest.CaptureFixture[str], fake: Path
) -> None:
    results = fake.parent / "bench" / "results.json"
    results.write_text(json.dumps({"codec": {"crc16_mb_s": 1.0, "targets_missed": ["stale = 1"]}}))
    out, _ = run(capsys, ["bench", "--full", "--only", "bus"])
    assert json.loads(fake.read_text()) == ["--only", "bus"]  # no --quick, no --output: bench/ itself
    assert "full run" in out and "101,436" in out and "crc16" not in out and "stale" not in out
    assert out.rstrip().endswith("all targets met")
    assert sorted(json.loads(results.read_text())) == ["bus", "codec"]  # the runner wrote into bench/


def test_the_real_bus_part_quick_mode(capsys: pytest.CaptureFixture[str]) -> None:
    results = run_json(capsys, ["bench", "--only", "bus"])
    assert list(results) == ["bus"]
    figures = results["bus"]
    assert figures["efficiency_can1m_32"] > 0.9 and figures["cycle32_transactions_s"] > 0
    assert figures["cycle_sizes.32.transactions_s"] > 0 and not any(k.startswith("meta.") for k in figures)


def test_without_bench_folder_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(bench, "bench_dir", lambda: None)
    err = one_line(capsys, ["bench", "--only", "bus"], code=2)
    assert err.startswith("servobus bench: error: ") and "from the root folder of a clone" in err
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path)  # a folder without the runner
    assert "clone of the servobus repository" in one_line(capsys, ["bench"], code=2)


def test_an_installed_servobus_outside_a_clone_says_to_run_from_a_clone(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The real look-up, as from a wheel (servobus in site-packages) run in a folder that is no clone:
    one line, exit 2; a bench/ folder there that is not servobus's is never run."""
    import servobus

    installed = tmp_path / "lib" / "python3.11" / "site-packages" / "servobus" / "__init__.py"
    monkeypatch.setattr(servobus, "__file__", str(installed))
    elsewhere = tmp_path / "project"
    (elsewhere / "bench").mkdir(parents=True)
    ran = elsewhere / "ran"
    (elsewhere / "bench" / "__main__.py").write_text(f"open({str(ran)!r}, 'w').close()")
    monkeypatch.chdir(elsewhere)
    assert bench.bench_dir() is None
    err = one_line(capsys, ["bench", "--only", "bus"], code=2)
    assert "run servobus bench from the root folder of a clone of the servobus repository" in err
    assert not ran.exists()
    monkeypatch.chdir(RUNNER.parents[1])  # the root of a clone: its bench/, with the installed servobus
    assert bench.bench_dir() == RUNNER.parent


def test_a_failing_runner_is_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "__main__.py").write_text("raise SystemExit('broken on purpose')")
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path / "bench")
    err = one_line(capsys, ["bench", "--only", "codec"], code=1)
    assert "python -m bench --quick failed (exit 1): broken on purpose" in err
    err = one_line(capsys, ["bench", "--check"], code=1)  # status 1: a failure
    assert "failed (exit 1): broken on purpose" in err
    err = one_line(capsys, ["bench", "--full"], code=1)
    assert "python -m bench failed (exit 1): broken on purpose" in err


def test_a_runner_that_died_of_an_exception_is_named_by_it_not_by_a_warning_after_it(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A clone installed without the sim extra: the traceback ends in ModuleNotFoundError, then Python
    warns of a coroutine never awaited; the line names the error, which says what to install."""
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "__main__.py").write_text(
        "import sys\n"
        "sys.stderr.write('Traceback (most recent call last):\\n  File x, line 1\\n')\n"
        "sys.stderr.write('ModuleNotFoundError: virtual time needs looptime: pip install looptime\\n')\n"
        "sys.stderr.write(\"sys:1: RuntimeWarning: coroutine 'efficiency_run' was never awaited\\n\")\n"
        "sys.exit(1)\n"
    )
    monkeypatch.setattr(bench, "bench_dir", lambda: tmp_path / "bench")
    err = one_line(capsys, ["bench", "--only", "bus"], code=1)
    assert err.rstrip().endswith(
        "failed (exit 1): ModuleNotFoundError: virtual time needs looptime: pip install looptime"
    ), err


def test_an_unknown_part_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert "--only" in one_line(capsys, ["bench", "--only", "nope"])
    assert "--quick" in one_line(capsys, ["bench", "--quick"])  # quick is the default, not an option


def test_verbose_json_keeps_stdout_for_the_json(capfd: pytest.CaptureFixture[str], fake: Path) -> None:
    """--verbose shows the runner's own output on stderr: stdout is the JSON document alone."""
    from servobus.cli import main

    assert main(["bench", "--only", "bus", "--verbose", "--json"]) == 0
    out, err = capfd.readouterr()
    assert json.loads(out)["bus"]["efficiency_can1m_32"] == 1.0
    assert "progress that is not shown" in err
