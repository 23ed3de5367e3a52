"""The only importer of the compiled C core. Checks that it matches this package (ABI number and
version), and maps status codes to exceptions through one table. Nothing outside servobus.core
sees cdata."""

from __future__ import annotations

import sys
from typing import Any, NoReturn

from servobus._version import __version__

try:
    from servobus._core import ffi, lib
except ImportError as exc:  # pragma: no cover - depends on how the package was installed
    raise ImportError(
        "servobus._core (the C core) is not built. Install the package with `pip install .` "
        "(or `pip install -e .` for development); it needs a C compiler."
    ) from exc

# The SB_CORE_ABI this wrapper calls (csrc/servobus_core.h). A core built from another header takes
# other arguments, so it is refused before anything calls it.
CORE_ABI = 2


def check_abi(core_abi: int) -> None:
    """Raise ImportError unless the compiled core's ABI number is the one this wrapper calls."""
    if core_abi != CORE_ABI:
        raise ImportError(
            f"servobus._core has C ABI {core_abi} but this servobus wrapper needs ABI {CORE_ABI}: "
            "the compiled core is stale; reinstall servobus to rebuild it (`pip install -e .` in a "
            "checkout, `pip install --force-reinstall servobus` otherwise)."
        )


# A core older than sb_core_abi() itself is ABI 1.
check_abi(lib.sb_core_abi() if hasattr(lib, "sb_core_abi") else 1)

_built_for = ffi.string(lib.sb_core_version()).decode()
if _built_for != __version__:  # pragma: no cover - only after an upgrade without rebuild
    raise ImportError(
        f"servobus._core was built for servobus {_built_for} but this is servobus {__version__}: "
        "rebuild it with `pip install -e .` (or reinstall)."
    )

__all__ = [
    "CORE_ABI",
    "Buffer",
    "as_cbuffer",
    "check_abi",
    "ffi",
    "is_buffer",
    "lib",
    "raise_status",
    "readable_cbuffer",
    "writable_cbuffer",
]

if sys.version_info >= (3, 12):
    from collections.abc import Buffer
else:  # pragma: no cover - the same protocol, backported (typeshed gives array, mmap, ... __buffer__)
    from typing_extensions import Buffer

_STATUS: dict[int, tuple[type[Exception], str]] = {
    lib.SB_E_RANGE: (ValueError, "value out of range"),
    lib.SB_E_NAN: (ValueError, "value is NaN"),
    lib.SB_E_LAYOUT: (ValueError, "unknown layout or de-framer kind"),
    lib.SB_E_ARG: (ValueError, "bad argument (pointer, size, capacity, stride, field scale, flag or option)"),
}


def raise_status(status: int, detail: str = "") -> NoReturn:
    """Raise the exception that a non-zero C status code stands for."""
    exc_type, text = _STATUS.get(status, (RuntimeError, f"C core returned unknown status {status}"))
    raise exc_type(f"{detail}: {text}" if detail else text)


def readable_cbuffer(data: Any, what: str = "data") -> Any:
    """Any buffer as a C char array, without copying.

    Raises:
        TypeError: ``data`` is not a C-contiguous buffer (cffi says BufferError for a strided one).
    """
    try:
        return ffi.from_buffer(data)
    except (BufferError, TypeError) as exc:
        raise TypeError(
            f"{what} must be a contiguous bytes-like buffer (bytes, bytearray, array, contiguous "
            f"memoryview), not {type(data).__name__}"
        ) from exc


def as_cbuffer(data: Any, what: str = "data") -> Any:
    """bytes go to C as they are (no copy); other buffers as :func:`readable_cbuffer` (no copy)."""
    return data if type(data) is bytes else readable_cbuffer(data, what)


def is_buffer(obj: object) -> bool:
    """True for anything that exposes the buffer protocol (bytes, array, numpy arrays, ...)."""
    try:
        memoryview(obj)  # type: ignore[arg-type]
    except TypeError:
        return False
    return True


def writable_cbuffer(ctype: str, obj: Any, what: str) -> Any:
    """A writable buffer as a C array, without copying; TypeError names the argument otherwise."""
    try:
        return ffi.from_buffer(ctype, obj, require_writable=True)
    except (BufferError, TypeError) as exc:
        raise TypeError(f"{what} must be a writable buffer (bytearray, array, numpy array)") from exc
