"""The build: generated tables are fresh, the compiled core matches the package, the builder's
switches do what the README says."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import servobus
from servobus.codec import _lib

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
    assert _lib.lib.SB_CORE_ABI == 1


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


def _load_builder(monkeypatch_env: dict[str, str]) -> list[str]:
    import os

    old = {k: os.environ.get(k) for k in monkeypatch_env}
    os.environ.update(monkeypatch_env)
    try:
        spec = importlib.util.spec_from_file_location(
            "_sb_builder", ROOT / "src" / "servobus" / "_build_core.py"
        )
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        cflags, ldflags = module.compile_args()
        assert module.package_version() == servobus.__version__
        return [*cflags, *ldflags]
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def test_builder_switches() -> None:
    """SERVOBUS_SANITIZE=1 adds ASan+UBSan to compile and link; the default is -O2 without them;
    FMA contraction is always off so C rounds like the Python reference."""
    default = _load_builder({"SERVOBUS_SANITIZE": "0", "SERVOBUS_DEBUG": "0"})
    assert "-O2" in default and not any("sanitize" in f for f in default)
    assert "-ffp-contract=off" in default
    sanitized = _load_builder({"SERVOBUS_SANITIZE": "1"})
    assert sanitized.count("-fsanitize=address,undefined") == 2
