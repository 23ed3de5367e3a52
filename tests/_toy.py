"""The toy plug-in family (tests/plugins): its folder, and ``servobus`` run the way an installed
plug-in is found (the folder on ``PYTHONPATH``, its dist-info registering the entry point)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

PLUGINS = Path(__file__).resolve().parent / "plugins"
#: ``servobus`` in a subprocess
SERVOBUS = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())"]


@contextmanager
def installed() -> Iterator[ModuleType]:
    """The ``servobus_toy`` package with its folder on ``sys.path`` (what installing it would do),
    removed again afterwards with every module of it."""
    sys.path.insert(0, str(PLUGINS))
    try:
        yield importlib.import_module("servobus_toy")
    finally:
        sys.path.remove(str(PLUGINS))
        for name in [n for n in sys.modules if n.partition(".")[0] == "servobus_toy"]:
            del sys.modules[name]


def another_family(into: Path, name: str = "fake", media: tuple[str, ...] = ("can",)) -> Path:
    """A copy of ``servobus_toy`` registered as the family ``name`` (package ``servobus_<name>``, with a
    dist-info whose entry point registers it) written into ``into``, which is returned: on ``sys.path``
    or ``PYTHONPATH`` it is another installed plug-in family, to show that no test depends on which
    families are installed besides those it uses. ``media``: what its simulator part says it serves
    (listed in other families' "use --family X" hints; its motors still speak classic CAN only)."""
    package = f"servobus_{name}"
    target = into / package
    target.mkdir(parents=True)
    for source in (PLUGINS / "servobus_toy").glob("*.py"):
        text = source.read_text().replace("servobus_toy", package).replace('"toy"', f'"{name}"')
        text = text.replace('media=("can",)', f"media={media!r}")
        (target / source.name).write_text(text)
    info = into / f"{package}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[servobus.families]\n{name} = {package}:FAMILY\n")
    return into


def mypy_strict(source: str, tmp_path: Path) -> tuple[list[str], str]:
    """A user's script ``source`` checked by ``mypy --strict`` with the plug-ins installed: the
    lines about it (``note: ...``, ``error: ...``), and mypy's whole output."""
    import os

    import mypy.api as mypy_api

    user = tmp_path / "user.py"
    user.write_text(source)
    before = os.environ.get("MYPYPATH")
    os.environ["MYPYPATH"] = str(PLUGINS)
    try:
        stdout, stderr, _ = mypy_api.run(
            ["--strict", "--no-incremental", "--cache-dir", str(tmp_path / ".cache"), str(user)]
        )
    finally:
        if before is None:
            del os.environ["MYPYPATH"]
        else:
            os.environ["MYPYPATH"] = before
    assert not stderr, stderr
    return [line.split(": ", 1)[1] for line in stdout.splitlines() if line.startswith(str(user))], stdout
