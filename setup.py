"""Only the cffi hook lives here; metadata is in pyproject.toml."""

from setuptools import setup
from setuptools.command.build_ext import build_ext


class build_ext_plainly(build_ext):
    """Turn a missing or failing C compiler into one plain sentence instead of a traceback."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # distutils raises several unrelated classes for this
            name = type(exc).__name__
            if "Compile" in name or "Exec" in name or "Platform" in name or isinstance(exc, OSError):
                raise SystemExit(
                    "servobus: building the C core (servobus._core) failed: "
                    f"{exc}\nservobus needs a C compiler and the Python headers to install; "
                    "on Debian/Ubuntu: apt-get install build-essential python3-dev"
                ) from exc
            raise


setup(
    cffi_modules=["src/servobus/_build_core.py:ffibuilder"],
    cmdclass={"build_ext": build_ext_plainly},
)
