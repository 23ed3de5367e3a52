"""The dashboard's cost on the control loop: ``servobus demo`` and loop1k with a page open, and without.

What is measured (rounds of runs: without the dashboard, with its page open in a browser, and beside
them with only an SSE client and with the dashboard served but no page, their order rotated each round;
medians; the ratios are with / without, of the medians of the same invocation):

* ``dashboard.demo_*``: ``servobus demo --duration S --json`` (32 simulated MyActuator motors on 11
  buses at 1 kHz, the simulator in the same process), and the same with ``--dashboard 127.0.0.1:0``
  with the page open in a browser. ``demo_ticks_s``: the achieved tick rate (``achieved_hz``);
  ``demo_host_us_per_tick``, ``demo_state_age_p99_ms`` beside it. The demo starts at once, so the page
  opens a moment after it (``demo_page_live_after_s``, from the URL line to the page's first update, is
  given): that part of a run is without the page.
* ``dashboard.loop1k_*``: bench_loop1k.py's ``loop1k`` (32 motors at 1 kHz through 11 SLCAN ptys to a
  device process, the pipelined Loop), and the same with the host serving the dashboard of its buses and
  Loop (``--host --dashboard``): there the Loop starts only once the page gets its updates, so the whole
  measured window is with the page. ``loop1k_ticks_s`` (achieved rate), ``loop1k_state_age_p99_ms``,
  ``loop1k_host_cpu_pct`` (the host process's CPU, % of one core), and ``loop1k_on_time_pct`` (info).
  ``loop1k_updates_s``: the updates the host made per second of the window (the page's stream).
* ``*_ratio``: with the page / without. Target (issue 40): the tick rates and loop1k's state age p99
  and host CPU within 5 % of without (tick rate ratio >= 0.95; age ratio <= 1.05; host CPU ratio 0.95
  to 1.05: a host that gets less of its core with the page open is not cheaper, it is starved).
  ``*_sse_ratio`` (information): with the SSE client only / without: the dashboard's cost in the loop's
  process (its updates, their JSON and their sending, the tap on every frame), the browser's CPU apart;
  ``*_unwatched_ratio`` (information): the dashboard served and its links tapped, no page: the tap's
  cost on every frame alone.

"Open" is a real page: Debian's headless Chromium driven by selenium (chromedriver's path given, no
browser download), which loads the page and gets its server-sent updates (30 a second) and draws them
with uPlot; it runs on the same machine (its CPU is given: ``*_page_cpu_pct``, the browser's processes,
% of one core). Without a browser (``--page sse``, or none found) an SSE client in another process
(``curl -N`` on ``/api/events``) takes the updates instead, and the section says so.

The machine is shared (2 cores): the load at each run's start is in results.json.

Usage (from the repository root)::

    python bench/bench_dashboard.py             # 5 pairs x 15 s each, demo and loop1k: writes RESULTS.md
    python bench/bench_dashboard.py --quick     # CI smoke run (1 pair of short runs each), writes nothing
    python bench/bench_dashboard.py --only demo --pairs 7 --seconds 20
"""

from __future__ import annotations

import argparse
import json
import math
import os
import selectors
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

BENCH_DIR = Path(__file__).resolve().parent
if str(BENCH_DIR) not in sys.path:
    sys.path.insert(0, str(BENCH_DIR))

import _meta  # noqa: E402
import _profile  # noqa: E402
import _results  # noqa: E402
import bench_loop1k  # noqa: E402

KEY = "dashboard"
TARGET_RATIO = 0.95  # a tick rate with the page >= 95 % of without (an age or CPU <= 105 %)
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
SERVOBUS = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())"]
PARTS = ("demo", "loop1k")
OPEN_S = 60.0  # the longest a page may take to get its first update


@dataclass(frozen=True, slots=True)
class Config:
    mode: str
    pairs: int
    seconds: float


FULL = Config("full", pairs=5, seconds=15.0)
QUICK = Config("quick", pairs=1, seconds=2.0)  # (a page takes a second or two to open)


# ============================================================================================ the page


class Page:
    """Where the dashboard is opened: Chromium through selenium, or an SSE client (curl) in another
    process. ``open(url)`` returns once updates flow; ``close()`` ends that page's stream."""

    kind = ""
    label = ""  # its runs' suffix in results.json, when not the page measured (``dashboard``)

    def open(self, url: str, until: Callable[[], bool] = lambda: False) -> bool:
        """Open the page at ``url``; True once updates flow, False if ``until()`` came first (what
        serves it ended).

        Raises:
            RuntimeError: no update within OPEN_S.
        """
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def quit(self) -> None:
        self.close()

    def cpu_s(self) -> float:
        """The CPU seconds the page's processes have used so far."""
        raise NotImplementedError


def _tree_cpu_s(pid: int) -> float:
    """User + system CPU of ``pid`` and its live descendants (Linux /proc)."""
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        cpu = _profile.proc_cpu_s(p)
        total += 0.0 if cpu != cpu else cpu  # (a process gone meanwhile: nan)
        try:
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return total


class Browser(Page):
    """Headless Debian Chromium, driven by selenium with chromedriver's path (selenium-manager, which
    would download a browser, is never used): one browser for every run, each run's page opened in it."""

    kind = "headless Chromium (selenium, Debian's chromium and chromedriver)"

    def __init__(self) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        options.page_load_strategy = "none"  # (open() waits for the page's first update itself)
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
            options.add_argument(arg)
        self.driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
        self.driver.set_page_load_timeout(30)
        self.pid = self.driver.service.process.pid

    def open(self, url: str, until: Callable[[], bool] = lambda: False) -> bool:
        from selenium.common.exceptions import NoSuchElementException
        from selenium.webdriver.common.by import By

        self.driver.get(url)  # (returns at once: the page load strategy is "none")
        deadline = time.monotonic() + OPEN_S
        while True:
            try:
                if self.driver.find_element(By.ID, "conn").text == "live":  # (updates flow: its badge)
                    return True
            except NoSuchElementException:  # (not loaded yet)
                pass
            if until():
                return False
            if time.monotonic() > deadline:
                raise RuntimeError(f"the page at {url} got no update within {OPEN_S:g} s")
            time.sleep(0.02)

    def close(self) -> None:
        self.driver.get("about:blank")  # (the page's stream closed with it)

    def quit(self) -> None:
        self.driver.quit()

    def cpu_s(self) -> float:
        return _tree_cpu_s(self.pid)


class SseClient(Page):
    """``curl -N`` on the page's ``/api/events`` in another process (without a browser), its stream
    written to a file: live once the first update is in it."""

    kind = "no browser: an SSE client in another process (curl -N on /api/events)"
    label = "sse"

    def __init__(self) -> None:
        self.process: subprocess.Popen[bytes] | None = None
        self.sink: IO[bytes] | None = None
        self._spent = 0.0

    def open(self, url: str, until: Callable[[], bool] = lambda: False) -> bool:
        self.sink = tempfile.TemporaryFile()  # noqa: SIM115 (closed in close(), with its stream)
        self.process = subprocess.Popen(["curl", "-sN", url + "api/events"], stdout=self.sink)
        deadline = time.monotonic() + OPEN_S
        while os.fstat(self.sink.fileno()).st_size == 0:
            if until():
                return False
            if time.monotonic() > deadline or self.process.poll() is not None:
                raise RuntimeError(f"no update from {url}api/events within {OPEN_S:g} s")
            time.sleep(0.02)
        return True

    def close(self) -> None:
        if self.process is not None:
            self._spent += _tree_cpu_s(self.process.pid)
            self.process.kill()
            self.process.wait()
            self.process = None
        if self.sink is not None:
            self.sink.close()
            self.sink = None

    def cpu_s(self) -> float:
        return self._spent + (_tree_cpu_s(self.process.pid) if self.process is not None else 0.0)


class Unwatched(Page):
    """No page: the dashboard served (its tap on every frame), nobody watching. loop1k's host waits for
    a page's updates before it starts: three snapshots are asked for, then nothing more."""

    kind = "no page: the dashboard served and its links tapped, nobody watching"
    label = "unwatched"

    def open(self, url: str, until: Callable[[], bool] = lambda: False) -> bool:
        import urllib.request

        for _ in range(3):
            with urllib.request.urlopen(url + "api/snapshot", timeout=OPEN_S) as answer:
                answer.read()
        return True

    def close(self) -> None:
        pass

    def cpu_s(self) -> float:
        return 0.0


def make_page(kind: str, say: Callable[[str], None]) -> Page:
    """The browser unless told ``sse`` or none can start here (then the SSE client, said why)."""
    if kind == "browser":
        missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not Path(p).exists()]
        try:
            if missing:
                raise RuntimeError(f"{', '.join(missing)} not found")
            return Browser()
        except Exception as exc:  # (selenium missing, the browser does not start: said, then curl)
            say(f"  no browser ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})")
    if shutil.which("curl") is None:
        raise RuntimeError("neither a browser nor curl: no page to open")
    return SseClient()


# ============================================================================================ the demo


def _line(stream: IO[str], timeout_s: float) -> str:
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        if not selector.select(timeout_s):
            raise RuntimeError(f"no line within {timeout_s} s")
    return stream.readline()


def demo_run(seconds: float, page: Page | None) -> dict[str, Any]:
    """``servobus demo --duration seconds --json``, with ``--dashboard`` and ``page`` opened on it
    when ``page``; its summary, and when and at what cost the page was open."""
    command = [*SERVOBUS, "demo", "--duration", str(seconds), "--json"]
    command += ["--dashboard", "127.0.0.1:0"] if page is not None else []
    load = [round(x, 2) for x in os.getloadavg()]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    extra: dict[str, Any] = {}
    try:
        if page is not None:
            assert process.stderr is not None
            line = _line(process.stderr, 30)
            started, cpu0 = time.perf_counter(), page.cpu_s()
            live = page.open(line.split()[2], until=lambda: process.poll() is not None)
            extra["page_live"] = int(live)  # (0: the demo ended before the page got an update)
            if live:
                extra["page_live_after_s"] = time.perf_counter() - started
        process.wait(timeout=seconds * 4 + 60)
        if page is not None:
            extra["page_cpu_pct"] = 100 * (page.cpu_s() - cpu0) / max(1e-9, time.perf_counter() - started)
            page.close()
        assert process.stdout is not None and process.stderr is not None
        out, err = process.stdout.read(), process.stderr.read()
    finally:
        process.kill()
        process.wait()
    if process.returncode != 0:
        raise RuntimeError(f"servobus demo failed ({process.returncode}): {err[-2000:]}")
    summary = json.loads(out)
    return {
        "ticks_s": summary["achieved_hz"],
        "host_us_per_tick": summary["host_us_per_tick"],
        "state_age_p99_ms": summary["state_age_p99_ms"],
        "cpu_pct": summary["cpu_pct"],
        "missed_ticks": summary["missed_ticks"],
        "preempted": summary["preempted"],
        "errors": summary["errors"],
        "load_before": load,
        **extra,
    }


# ========================================================================================== loop1k


def loop1k_run(seconds: float, page: Page | None) -> dict[str, Any]:
    """bench_loop1k's ``loop1k`` run of the Loop, with its dashboard open in ``page`` when given."""
    layout = bench_loop1k.LAYOUTS["loop1k"]
    if page is None:
        run = bench_loop1k.one_run(layout, seconds, "loop")
    else:
        cpu0 = page.cpu_s()
        started = time.perf_counter()
        try:
            run = bench_loop1k.one_run(layout, seconds, "loop", on_url=page.open)
        finally:
            spent = page.cpu_s() - cpu0
            page.close()
        run["page_cpu_pct"] = 100 * spent / max(1e-9, time.perf_counter() - started)
        run["updates_s"] = run["dashboard_updates"] / run["wall_s"]
    return {
        "ticks_s": run["achieved_hz"],
        "state_age_p99_ms": run["state_age_p99_ms"],
        "host_cpu_pct": run["host_cpu_pct"],
        "on_time_pct": run["on_time_pct"],
        "load_before": run["load_before"],
        **{k: run[k] for k in ("page_cpu_pct", "updates_s") if k in run},
    }


#: the runs beside the page's (information): their label and header
ALSO = {"sse": "SSE client", "unwatched": "served, no page"}
RUNS: dict[str, Callable[[float, Page | None], dict[str, Any]]] = {"demo": demo_run, "loop1k": loop1k_run}
#: per part: (figure, direction of "better") compared with / without; the first is the tick rate
COMPARED: dict[str, tuple[tuple[str, str], ...]] = {
    "demo": (("ticks_s", "up"), ("host_us_per_tick", "down"), ("state_age_p99_ms", "down")),
    "loop1k": (("ticks_s", "up"), ("state_age_p99_ms", "down"), ("host_cpu_pct", "either")),
}
#: the figures the target judges (issue 40): the demo's tick rate; loop1k's rate, state age, host CPU
JUDGED = {"demo": ("ticks_s",), "loop1k": ("ticks_s", "state_age_p99_ms", "host_cpu_pct")}


def measure(part: str, cfg: Config, pages: Sequence[Page], say: Callable[[str], None]) -> dict[str, Any]:
    """``cfg.pairs`` rounds of runs without the page and with each of ``pages`` (the real page first,
    then the SSE client beside it when both are measured), their order rotated round by round; the
    medians, the ratios with / without, and the targets (on the first page's)."""
    variants: list[tuple[str, Page | None]] = [("without", None)]
    variants += [("dashboard" if n == 0 else page.label, page) for n, page in enumerate(pages)]
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name, _ in variants}
    never = dict.fromkeys(runs, 0)  # runs whose page got no update before the run ended: left out
    for i in range(cfg.pairs):
        for which, page in variants[i % len(variants) :] + variants[: i % len(variants)]:
            run = RUNS[part](cfg.seconds, page)
            if run.get("page_live", 1) == 0:
                never[which] += 1
                say(
                    f"  {part:<6} {which:<9} {i + 1}/{cfg.pairs}: no update reached the page before the end "
                    "(left out)"
                )
                continue
            runs[which].append(run)
            say(
                f"  {part:<6} {which:<9} {i + 1}/{cfg.pairs}: "
                + ", ".join(f"{k} {run[k]:,.2f}" for k, _ in COMPARED[part])
                + (f", page cpu {run['page_cpu_pct']:.0f} %" if "page_cpu_pct" in run else "")
                + f"; load {run['load_before'][0]:.2f}"
            )
    out: dict[str, Any] = {}
    for which, done in runs.items():
        suffix = "" if which == "without" else f"_{which}"
        if not done:
            raise RuntimeError(f"{part} {which}: no run had its page open (see above)")
        out[f"{part}_page_never_live{suffix}"] = never[which]
        names = sorted({k for r in done for k, v in r.items() if isinstance(v, int | float)})
        for name in names:
            values = [r[name] for r in done if name in r]
            out[f"{part}_{name}{suffix}"] = round(statistics.median(values), 3)
            out[f"{part}_{name}{suffix}_runs"] = [round(v, 3) for v in values]
        out[f"{part}_load_before{suffix}"] = [r["load_before"] for r in done]
    missed = []
    for name, better in COMPARED[part]:
        base = out[f"{part}_{name}"]
        for which in runs:
            if which == "without":
                continue
            suffix = "" if which == "dashboard" else f"_{which}"
            ratio = round(out[f"{part}_{name}_{which}"] / base, 4) if base else float("nan")
            out[f"{part}_{name}{suffix}_ratio"] = ratio
            if which == "dashboard" and name in JUDGED[part]:
                low, high = (TARGET_RATIO, math.inf) if better == "up" else (0.0, 2 - TARGET_RATIO)
                if better == "either":  # (a host starved of its core uses less of it: not better)
                    low, high = TARGET_RATIO, 2 - TARGET_RATIO
                if not low <= ratio <= high:
                    target = (
                        f">= {low:.2f}"
                        if high == math.inf
                        else f"<= {high:.2f}"
                        if not low
                        else (f"{low:.2f} to {high:.2f}")
                    )
                    missed.append(f"{KEY}.{part}_{name}_ratio = {ratio} (target {target})")
    out[f"{part}_targets_missed"] = missed
    return out


def render_markdown(f: dict[str, Any], info: dict[str, Any]) -> str:
    doc = (__doc__ or "").split("What is measured", 1)[1].split("\n\nUsage", 1)[0]
    labels = {
        "ticks_s": ("tick rate", "{:,.1f} /s"),
        "host_us_per_tick": ("host CPU per tick", "{:,.0f} µs"),
        "state_age_p99_ms": ("state age p99", "{:.2f} ms"),
        "host_cpu_pct": ("host CPU", "{:.1f} %"),
    }
    also = [label for label in ALSO if label in info.get("also", ())]
    rows = []
    for part in info["parts"]:
        for name, _ in COMPARED[part]:
            label, form = labels[name]
            judged = name in JUDGED[part]
            ratio = f"{f[f'{part}_{name}_ratio']:.3f}"
            rows.append(
                (
                    f"{part}: {label}" + ("" if judged else " (info)"),
                    f"`{KEY}.{part}_{name}_ratio`",
                    form.format(f[f"{part}_{name}"]),
                    form.format(f[f"{part}_{name}_dashboard"]),
                    f"**{ratio}**" if judged else ratio,
                    *(
                        f"{form.format(f[f'{part}_{name}_{x}'])} ({f[f'{part}_{name}_{x}_ratio']:.3f})"
                        for x in also
                    ),
                    ", ".join(form.format(v) for v in f[f"{part}_{name}_runs"]),
                    ", ".join(form.format(v) for v in f[f"{part}_{name}_dashboard_runs"]),
                )
            )
    notes = []
    if "demo" in info["parts"]:
        notes.append(
            f"The demo's page was live {f['demo_page_live_after_s_dashboard']:.2f} s (median) after its URL "
            f"line, of a {info['seconds']:g} s run (open "
            f"{100 * max(0.0, 1 - f['demo_page_live_after_s_dashboard'] / info['seconds']):.0f} % of it; the "
            "demo's start, before its first tick, is part of that); the page's processes used "
            f"{f['demo_page_cpu_pct_dashboard']:.0f} % of a core meanwhile."
        )
    if "loop1k" in info["parts"]:
        notes.append(
            f"loop1k with the page: {f['loop1k_updates_s_dashboard']:.1f} updates/s made in the measured "
            f"window (the page's stream); ticks on time {f['loop1k_on_time_pct']:.2f} % without, "
            f"{f['loop1k_on_time_pct_dashboard']:.2f} % with; the page's processes used "
            f"{f['loop1k_page_cpu_pct_dashboard']:.0f} % of a core."
        )
    if also:
        notes.append(
            "Information, in the same rounds: *SSE client*, the same runs with curl taking the updates "
            "instead of the browser (the dashboard's own cost in the loop's process, without the browser's "
            "CPU on the machine's cores); *served, no page*, with the dashboard served and its links "
            "tapped but nobody watching (the tap's cost on every frame alone)."
        )
    missed = f["targets_missed"]
    lines = [
        *_meta.header_lines("## The dashboard's cost on the loop (`bench/bench_dashboard.py`)", info),
        f"- The page: {info['page']}; {info['pairs']} rounds of {info['seconds']:g} s runs per part "
        "(without, with the page" + "".join(f", {ALSO[label]}" for label in also) + "; their order rotated)",
        "",
        "What is measured" + doc.rstrip(),
        "",
        _results.markdown_table(
            [
                "figure",
                "key (with / without)",
                "without",
                "with the page",
                "ratio",
                *(f"{ALSO[label]} (ratio)" for label in also),
                "runs without",
                "runs with",
            ],
            rows,
            "llrrr" + "r" * len(also) + "ll",
        ),
        " ".join(notes),
        "",
        "Targets missed: " + ("; ".join(missed) if missed else "none."),
    ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs (CI smoke run), writes nothing")
    parser.add_argument("--output", type=Path, help="write RESULTS.md and results.json to this directory")
    parser.add_argument("--check", action="store_true", help="exit with status 1 when a target is missed")
    parser.add_argument("--only", action="append", choices=PARTS, help="parts to run (repeatable)")
    parser.add_argument("--pairs", type=int, help="runs without and with the page, per part")
    parser.add_argument("--seconds", type=float, help="seconds per run")
    parser.add_argument(
        "--page", choices=("browser", "sse"), default="browser", help="what opens the page (default: browser)"
    )
    args = parser.parse_args(argv)
    started = time.perf_counter()
    load = _meta.load_average()
    base = QUICK if args.quick else FULL
    cfg = Config(base.mode, args.pairs or base.pairs, args.seconds or base.seconds)
    out_dir: Path | None = args.output if args.output is not None else (None if args.quick else BENCH_DIR)
    parts = args.only or list(PARTS)
    say: Callable[[str], None] = lambda line: print(line, flush=True)  # noqa: E731
    page = make_page(args.page, say)
    pages = [page] + ([SseClient(), Unwatched()] if isinstance(page, Browser) and not args.quick else [])
    print(
        f"bench_dashboard ({cfg.mode}): {', '.join(parts)}, {cfg.pairs} pair(s) x {cfg.seconds:g} s; the "
        f"page: {page.kind}; load {load}",
        flush=True,
    )
    figures: dict[str, Any] = {}
    try:
        for part in parts:
            figures |= measure(part, cfg, pages, say)
    finally:
        page.quit()
    figures["targets_missed"] = [m for part in parts for m in figures.pop(f"{part}_targets_missed")]
    arguments = list(sys.argv[1:] if argv is None else argv)
    info = _meta.meta(
        "bench/bench_dashboard.py",
        arguments,
        mode=cfg.mode,
        parts=parts,
        pairs=cfg.pairs,
        seconds=cfg.seconds,
        page=page.kind,
        also=[page.label for page in pages[1:]],
        load_average_at_start=load,
        statistic=f"median of {cfg.pairs} runs each, without and with the page alternated",
        runtime_s=round(time.perf_counter() - started, 1),
    )
    for part in parts:
        print(
            f"{part}: "
            + ", ".join(
                f"{name} {figures[f'{part}_{name}']:,.2f} -> {figures[f'{part}_{name}_dashboard']:,.2f} "
                f"(x{figures[f'{part}_{name}_ratio']:.3f})"
                for name, _ in COMPARED[part]
            )
        )
    missed = figures["targets_missed"]
    print("TARGETS MISSED: " + "; ".join(missed) if missed else "All dashboard targets met.")
    if out_dir is not None:
        _results.replace_markdown_section(out_dir / "RESULTS.md", KEY, render_markdown(figures, info))
        _results.update_results_json(out_dir / "results.json", KEY, {**figures, "meta": info})
        print(f"Wrote {out_dir / 'RESULTS.md'} and {out_dir / 'results.json'} (key {KEY!r}).")
    print(f"Total runtime: {time.perf_counter() - started:.1f} s")
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())
