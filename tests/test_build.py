"""The build: generated tables are fresh, the compiled core matches the package, the builder's
switches do what the README says."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import servobus
from servobus.core import _lib

ROOT = Path(__file__).resolve().parents[1]


def test_crc_tables_are_generated_from_the_polynomials() -> None:
    """csrc/crc_tables.h is exactly what csrc/gen_crc_tables.py prints (no hand edits, no copy
    from the manuals' OCR-damaged tables)."""
    generated = subprocess.run(
        [sys.executable, str(ROOT / "csrc" / "gen_crc_tables.py")], check=True, capture_output=True, text=True
    ).stdout
    assert (ROOT / "csrc" / "crc_tables.h").read_text() == generated


def test_core_version_matches_package() -> None:
    """The wrapper refuses a stale build; here the build is current."""
    assert _lib.ffi.string(_lib.lib.sb_core_version()).decode() == servobus.__version__
    assert _lib.lib.SB_CORE_ABI == _lib.CORE_ABI


def test_one_crc_call_smoke() -> None:
    assert _lib.lib.sb_crc16_modbus(b"123456789", 9, 0xFFFF) == 0x4B37


def test_status_codes_map_to_exceptions() -> None:
    for status in (_lib.lib.SB_E_RANGE, _lib.lib.SB_E_NAN, _lib.lib.SB_E_LAYOUT, _lib.lib.SB_E_ARG):
        try:
            _lib.raise_status(status, "ctx")
        except ValueError as exc:
            assert str(exc).startswith("ctx: ")
        else:  # pragma: no cover
            raise AssertionError(f"status {status} raised nothing")


def _builder() -> ModuleType:
    spec = importlib.util.spec_from_file_location("_sb_builder", ROOT / "src" / "servobus" / "_build_core.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_builder_switches() -> None:
    """SERVOBUS_SANITIZE=1 adds ASan+UBSan to compile and link; the default is -O2 without them;
    FMA contraction is always off so C rounds like the Python reference."""
    builder = _builder()
    assert builder.package_version() == servobus.__version__
    cflags, ldflags = builder.compile_args({})
    assert "-O2" in cflags and not any("sanitize" in f for f in cflags + ldflags)
    assert "-ffp-contract=off" in cflags
    cflags, ldflags = builder.compile_args({"SERVOBUS_SANITIZE": "1"})
    assert "-fsanitize=address,undefined" in cflags and "-fsanitize=address,undefined" in ldflags
    assert "-O2" not in cflags
    cflags, _ = builder.compile_args({"SERVOBUS_DEBUG": "1"})
    assert "-O0" in cflags and "-g" in cflags
