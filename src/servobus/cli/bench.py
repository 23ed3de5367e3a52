"""``servobus bench``: the front of the benchmark suite's one command, ``python -m bench``.

By default it runs the suite's quick mode over every part (codec, transport, bus, efficiency, loop1k,
scaling; ``--only`` picks, ``--skip`` leaves out): ``python -m bench --quick --output <temporary folder>``
from the repository root, then prints every numeric figure of the ``results.json`` written there in one
table (nested figures by dotted names, ``detail.read_status2.turnaround_s``; the runner's ``meta`` and
``machine`` records left out) and the targets missed. Nothing in ``bench/`` is written. ``--full`` is the
full run, ``python -m bench``: it rewrites ``bench/RESULTS.md`` and ``bench/results.json`` in the source
tree (~15-20 min on 2 cores), then prints the same table for the parts it ran. ``--skip``,
``--wait-load`` and ``--wait-max-s`` are passed to the runner as they are.

``--check`` (exit status 1) is judged here, from the ``results.json`` of this invocation, by one rule
(:data:`CHECK_RULE`): only the parts that ran now are judged (figures of earlier runs never are); the
quick mode's figures (tiny sizes, 1 s runs) are never judged against the full run's targets, so a quick
``--check`` fails only when a part failed or its C core and reference disagreed; a target the runner
itself says no host can meet is never judged; and the real-time targets (``loop1k*``: 1 kHz with the
simulated devices in a second process) are judged only on a host with at least
:data:`REAL_TIME_MIN_CORES` cores (on 2 cores they are known missed, bench/RESULTS.md). Targets left
unjudged are still listed, marked as such.

The benchmarks live in the source tree, not in the installed package: outside a clone of the repository
(an installed wheel run from another folder) the command says in one line to run it from a clone's root
folder, and exits 2.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import click

from servobus.cli._output import SETTINGS, console, emit_json, examples, json_option, table

__all__ = ["bench"]

#: the parts of ``python -m bench``, in its order (``PARTS`` of bench/__main__.py; a test keeps them equal)
PARTS = (
    "codec", "transport", "bus", "efficiency", "sim", "loop", "loop1k", "scaling", "remote", "pacer",
    "dashboard", "limits",
)  # fmt: skip
#: records of how a figure was measured, not figures
SKIPPED = frozenset({"meta", "machine"})
#: results.json keys whose targets are real-time figures (1 kHz, devices in a second process)
REAL_TIME = ("loop1k",)
#: the fewest cores a host needs for ``--check`` to judge the real-time targets (host, device process
#: and the rest of the machine each need a core; on 2 cores they are known missed, bench/RESULTS.md)
REAL_TIME_MIN_CORES = 4
#: what the runner appends to a target that cannot be met on any host (bench_loop1k.py)
NO_HOST_CAN = "no host can"
#: the rule ``--check`` follows, as its help says
CHECK_RULE = (
    "Exit with status 1 when a target is missed, judged by one rule: only parts run now; only --full "
    "figures (the quick mode's tiny sizes are never judged against the full run's targets: a quick "
    "--check fails only on a C/reference disagreement); never a target no host can meet; the real-time "
    f"loop1k targets only on a host with >= {REAL_TIME_MIN_CORES} cores (known missed on 2). Unjudged "
    "misses are still listed."
)


#: what to do when servobus runs outside a clone of its repository (bench/ is not installed)
NOT_A_CLONE = (
    "the benchmarks are not installed with servobus: run servobus bench from the root folder of a clone "
    "of the servobus repository (pip install -e . there)"
)


def bench_dir() -> Path | None:
    """``bench/`` of the clone servobus runs from (an editable install: ``src/servobus`` -> the
    repository root), else of the clone whose root is the current folder; None outside a clone."""
    import servobus

    for root in (Path(servobus.__file__).resolve().parents[2], Path.cwd()):
        if _is_clone(root):
            return root / "bench"
    return None


def _is_clone(root: Path) -> bool:
    """``root`` is a clone of servobus's repository: the suite's runner and the package's sources (a
    ``bench/`` folder of something else is not run)."""
    return (root / "bench" / "__main__.py").is_file() and (root / "src" / "servobus").is_dir()


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus bench                              # quick mode, every part, ~20 s here",
        "servobus bench --only bus                   # ~2 s",
        "servobus bench --only codec --json",
        "servobus bench --full --check --skip loop1k # exit 1 when a target is missed",
        "servobus bench --full --wait-load 1.0       # first wait for a quiet machine",
        "servobus bench --full --only efficiency     # rewrites its part of bench/RESULTS.md",
        "servobus bench --full                       # every part, ~15-20 min on 2 cores",
    ),
)
@click.option(
    "--only",
    type=click.Choice(PARTS),
    multiple=True,
    help="Run only this part of the suite (repeatable) [default: all].",
)
@click.option(
    "--skip",
    type=click.Choice(PARTS),
    multiple=True,
    help="Leave this part out (repeatable; passed to python -m bench).",
)
@click.option(
    "--full",
    is_flag=True,
    help="The full run (python -m bench: medians of >= 5 runs, ~15-20 min on 2 cores for every part) "
    "instead of the quick mode; writes bench/RESULTS.md and bench/results.json in the source tree.",
)
@click.option("--check", is_flag=True, help=CHECK_RULE)
@click.option(
    "--wait-load",
    type=click.FloatRange(min=0, min_open=True),
    metavar="X",
    help="First wait for a 1-minute load average below X (passed to python -m bench).",
)
@click.option(
    "--wait-max-s",
    type=click.FloatRange(min=0),
    metavar="S",
    help="The longest --wait-load wait, in seconds (passed to python -m bench) [default: 1800].",
)
@click.option("--verbose", "-v", is_flag=True, help="Show the runner's own output as it runs (on stderr).")
@json_option
def bench(
    only: tuple[str, ...],
    skip: tuple[str, ...],
    full: bool,
    check: bool,
    wait_load: float | None,
    wait_max_s: float | None,
    verbose: bool,
    as_json: bool,
) -> None:
    """Run the benchmark suite (python -m bench) and print its figures in one table.

    Quick mode by default (small sizes, ~20 s for every part here; writes nothing).
    """
    folder = bench_dir()
    if folder is None or not (folder / "__main__.py").is_file():
        raise click.UsageError(NOT_A_CLONE)
    if wait_max_s is not None and wait_load is None:
        raise click.UsageError("--wait-max-s is the longest --wait-load wait: give --wait-load too")
    parts = [part for part in (only or PARTS) if part not in skip]
    if not parts:
        raise click.UsageError("--skip leaves no part to run")
    selection = [arg for part in only for arg in ("--only", part)]
    selection += [arg for part in skip for arg in ("--skip", part)]
    selection += ["--wait-load", f"{wait_load:g}"] if wait_load is not None else []
    selection += ["--wait-max-s", f"{wait_max_s:g}"] if wait_max_s is not None else []
    if full:
        _run(selection, folder, "python -m bench", verbose)
        data = _read(folder / "results.json")
    else:
        with tempfile.TemporaryDirectory(prefix="servobus-bench-") as out:
            _run(["--quick", "--output", out, *selection], folder, "python -m bench --quick", verbose)
            data = _read(Path(out) / "results.json")
    keys = _keys(data, parts)
    results = {key: dict(_figures(data[key])) for key in keys}
    missed = [
        (key, f"{key}: {m}" if not m.startswith(f"{key}.") else m) for key in keys for m in _missed(data[key])
    ]
    judged = []
    shown = []
    for key, text in missed:
        why = _unjudged(key, text, full) if check else None
        judged += [text] if check and why is None else []
        shown.append(text if why is None else f"{text} [not judged: {why}]")
    failed = [
        f"{key}: C core and reference disagree" for key in keys if data[key].get("reference_agrees") is False
    ]
    if as_json:
        emit_json(results)
    else:
        rows = [
            (key, name, _number(value)) for key, figures in results.items() for name, value in figures.items()
        ]
        title = (
            "full run (written to bench/RESULTS.md and bench/results.json)"
            if full
            else "quick mode (small sizes; --full for the full run)"
        )
        console().print(table(title, ["part", "figure", "value"], rows))
        click.echo("targets missed: " + "; ".join(shown) if shown else "all targets met")
        for line in failed:
            click.echo(line)
    if check and (judged or failed):
        raise click.exceptions.Exit(1)


def _unjudged(key: str, missed: str, full: bool) -> str | None:
    """Why ``--check`` does not judge this missed target (:data:`CHECK_RULE`), or None: it does."""
    if not full:
        return "quick-mode figure"
    if NO_HOST_CAN in missed:
        return "no host can meet it"
    cores = os.cpu_count() or 1
    if key.startswith(REAL_TIME) and cores < REAL_TIME_MIN_CORES:
        return f"real-time target, needs >= {REAL_TIME_MIN_CORES} cores, this host has {cores}"
    return None


def _number(value: float) -> str:
    """Thousands grouped, small figures to 4 significant digits."""
    if isinstance(value, int) or abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.4g}"


def _keys(data: dict[str, Any], parts: Sequence[str]) -> list[str]:
    """The keys of results.json the parts write, in the parts' order: ``part`` and ``part_*`` (loop1k
    writes ``loop1k``, ``loop1k_fd`` and ``loop1k_fd_4pb``); other keys (``reliability``) are not theirs."""
    keys = []
    for part in parts:
        keys += [k for k in data if k == part and isinstance(data[k], dict)]
        keys += [k for k in data if k.startswith(f"{part}_") and isinstance(data[k], dict) and k not in keys]
    return keys


def _figures(node: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, float]]:
    """Every number under ``node`` by its dotted name; bools, strings, lists and records skipped."""
    for key, value in node.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            if key not in SKIPPED:
                yield from _figures(value, f"{name}.")
        elif isinstance(value, int | float) and not isinstance(value, bool):
            yield name, value


def _missed(node: dict[str, Any], prefix: str = "") -> Iterator[str]:
    """The ``targets_missed`` entries wherever they are under ``node`` (nested ones named by where)."""
    for key, value in node.items():
        if key == "targets_missed" and isinstance(value, list):
            yield from (f"{prefix}{m}" for m in value)
        elif isinstance(value, dict) and key not in SKIPPED:
            yield from _missed(value, f"{prefix}{key}: ")


def _read(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise click.ClickException(f"python -m bench wrote no readable {path}: {exc}") from None
    if not isinstance(data, dict):
        raise click.ClickException(f"{path} is not a JSON object")
    return data


def _run(args: list[str], folder: Path, what: str, verbose: bool) -> None:
    """Run ``python -m bench ARGS`` from the repository root (never with ``--check``: targets are judged
    here); a failure raises, with its last stderr line."""
    command = [sys.executable, "-m", "bench", *args]
    if verbose:  # its output on stderr, as it comes: stdout is the table or the JSON alone
        with subprocess.Popen(command, cwd=folder.parent, stdout=subprocess.PIPE, text=True) as process:
            assert process.stdout is not None
            for line in process.stdout:
                sys.stderr.write(line)
                sys.stderr.flush()
        code, err = process.returncode, ""  # (its stderr went to the terminal)
    else:
        with console(stderr=True).status(what, spinner="dots"):
            done = subprocess.run(command, cwd=folder.parent, capture_output=True, text=True, check=False)
        code, err = done.returncode, done.stderr or ""
    if code == 0:
        return
    why = _reason(err)
    raise click.ClickException(f"{what} failed (exit {code})" + (f": {why}" if why else ""))


def _reason(err: str) -> str:
    """Why the runner failed, from its stderr: the last exception line of a traceback (a warning printed
    after it, such as "coroutine ... was never awaited", is not the reason), else its last line."""
    lines = [line.strip() for line in err.splitlines() if line.strip()]
    errors = [line for line in lines if re.match(r"[A-Za-z_][\w.]*(Error|Exception)(: |$)", line)]
    return (errors or lines or [""])[-1]
