"""``servobus bench``: the benchmark suite's quick mode, from the source tree, as one table.

Runs ``bench/bench_<name>.py --quick --output <temporary folder>`` for each benchmark (codec,
transport, bus; ``--only`` picks), then prints the figures each wrote to its ``results.json`` key:
every number it reports, and the targets it missed. Nothing in ``bench/`` is written (the scripts
write only with ``--output``). The benchmarks live in the source tree, not in the installed package:
from a wheel, the command says so and exits 1.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import click

from servobus.cli._output import SETTINGS, console, emit_json, examples, json_option, table

__all__ = ["bench"]

BENCHMARKS = ("codec", "transport", "bus")


def bench_dir() -> Path:
    """``bench/`` of the source tree servobus runs from (``src/servobus`` -> the repository root), or,
    for an installed wheel, of the source checkout in the current folder."""
    import servobus

    beside = Path(servobus.__file__).resolve().parents[2] / "bench"
    return beside if beside.is_dir() else Path.cwd() / "bench"


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus bench                   # all three, ~30 s",
        "servobus bench --only bus        # ~3 s",
        "servobus bench --only codec --json",
    ),
)
@click.option(
    "--only",
    type=click.Choice(BENCHMARKS),
    multiple=True,
    help="Run only this benchmark (repeatable) [default: all].",
)
@click.option("--verbose", "-v", is_flag=True, help="Show the scripts' own output as they run (on stderr).")
@json_option
def bench(only: tuple[str, ...], verbose: bool, as_json: bool) -> None:
    """Run the benchmarks' quick mode and print their figures in one table."""
    folder = bench_dir()
    if not folder.is_dir():
        raise click.ClickException(
            f"no bench/ folder beside the installed package or here ({folder}): the benchmarks run "
            "from a source checkout"
        )
    results: dict[str, dict[str, Any]] = {}
    for name in only or BENCHMARKS:
        script = folder / f"bench_{name}.py"
        if not script.is_file():
            raise click.ClickException(f"{script} is missing")
        results[name] = _run(script, name, verbose)
    if as_json:
        emit_json(results)
        return
    rows = []
    missed = []
    for name, figures in results.items():
        for key, value in figures.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                rows.append((name, key, _number(value)))
        missed += [f"{name}: {m}" for m in figures.get("targets_missed", [])]
    console().print(
        table(
            "quick mode (tiny sizes; see bench/RESULTS.md for full runs)",
            ["benchmark", "figure", "value"],
            rows,
        )
    )
    click.echo("targets missed: " + "; ".join(missed) if missed else "all targets met")


def _number(value: float) -> str:
    """Thousands grouped, small figures to 4 significant digits."""
    if isinstance(value, int) or abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.4g}"


def _run(script: Path, name: str, verbose: bool) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="servobus-bench-") as out:
        command = [sys.executable, str(script), "--quick", "--output", out]
        shown = console(stderr=True)
        if verbose:  # its output on stderr: stdout is the table or the JSON alone
            done = subprocess.run(command, cwd=script.parent.parent, stdout=2, text=True, check=False)
        else:
            with shown.status(f"bench_{name}.py --quick", spinner="dots"):
                done = subprocess.run(
                    command, cwd=script.parent.parent, capture_output=True, text=True, check=False
                )
        if done.returncode != 0:
            last = (done.stderr or "").strip().splitlines()[-1:]
            raise click.ClickException(
                f"bench_{name}.py --quick failed (exit {done.returncode})" + (f": {last[0]}" if last else "")
            )
        data = json.loads((Path(out) / "results.json").read_text())
    figures: dict[str, Any] = data.get(name, {})
    return figures
