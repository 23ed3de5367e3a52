"""cffi builder for servobus._core (a build input only: runtime code never imports it).

The public headers (HEADERS: csrc/servobus_core.h, then the simulator's) are the cdef; csrc/*.c are
compiled in. Switches:
  SERVOBUS_SANITIZE=1   build with -fsanitize=address,undefined (see docs/guides/development.md, "Sanitizers")
  SERVOBUS_DEBUG=1      build with -O0 -g
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

from cffi import FFI

ROOT = Path(__file__).resolve().parents[2]
CSRC = ROOT / "csrc"
# In this order: each may use the types of those before it (csrc/sb_internal.h includes the same).
HEADERS = [
    CSRC / name
    for name in (
        "servobus_core.h",
        "sim_plant.h",
        "sim_timing.h",
        "sim_core.h",
        "sim_myactuator.h",
        "sim_lk.h",
        "sim_hollow.h",
        "sim_net.h",
    )
]
SOURCES = sorted(CSRC.glob("*.c"))


def package_version() -> str:
    text = (ROOT / "src" / "servobus" / "_version.py").read_text()
    match = re.search(r'__version__\s*=\s*"([^"]+)"', text)
    if not match:
        raise RuntimeError("servobus: no __version__ in src/servobus/_version.py")
    return match.group(1)


def compile_args(env: Mapping[str, str] = os.environ) -> tuple[list[str], list[str]]:
    """(compile flags, link flags) for the switches set in ``env``."""
    # -ffp-contract=off: no fused multiply-add, so the C scaling rounds exactly as the Python
    # reference in tests/reference does.
    cflags = ["-std=c11", "-Wall", "-Wextra", "-ffp-contract=off"]
    ldflags: list[str] = []
    if env.get("SERVOBUS_SANITIZE") == "1":
        san = ["-fsanitize=address,undefined", "-fno-sanitize-recover=undefined", "-fno-omit-frame-pointer"]
        cflags += ["-O1", "-g", *san]
        ldflags += san
    elif env.get("SERVOBUS_DEBUG") == "1":
        cflags += ["-O0", "-g"]
    else:
        cflags += ["-O2"]
    return cflags, ldflags


ffibuilder = FFI()
ffibuilder.cdef("\n".join(header.read_text() for header in HEADERS))
_cflags, _ldflags = compile_args()
ffibuilder.set_source(
    "servobus._core",
    '#include "sb_internal.h"\n',
    sources=[str(p.relative_to(ROOT)) for p in SOURCES],
    include_dirs=[str(CSRC.relative_to(ROOT))],
    define_macros=[("SB_CORE_VERSION", f'"{package_version()}"')],
    extra_compile_args=_cflags,
    extra_link_args=_ldflags,
    libraries=["m"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
