"""Where the shared protocol specs live, and their vectors as parametrisation cases.

The specs sit beside the repository (``../shared/spec``), as in CI; SERVOBUS_SPEC_DIR overrides.
Without them the vector tests skip with the path they looked at, except under CI, where missing
vectors are an error: a green run must have checked every vector.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

SPEC_DIR = Path(os.environ.get("SERVOBUS_SPEC_DIR", Path(__file__).resolve().parents[2] / "shared" / "spec"))


def load_vectors(name: str) -> list[dict[str, Any]]:
    """The vectors of spec/vectors/<name>.json; skip (or fail under CI) when they are absent."""
    path = SPEC_DIR / "vectors" / f"{name}.json"
    if not path.exists():
        if os.environ.get("CI"):
            raise FileNotFoundError(f"spec vectors not found at {path} (set SERVOBUS_SPEC_DIR)")
        pytest.skip(f"spec vectors not found at {path} (set SERVOBUS_SPEC_DIR)", allow_module_level=True)
    vectors: list[dict[str, Any]] = json.loads(path.read_text())
    return vectors


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace("0x", ""))


def vector_id(vector: dict[str, Any]) -> str:
    if "id" in vector:
        return str(vector["id"])
    parts = (vector["section"], vector["command"], vector["transport"], vector["direction"])
    return "-".join(parts) + f"-ex{vector.get('example', '')}"
