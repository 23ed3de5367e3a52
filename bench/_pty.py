"""A raw pseudo-terminal whose master end is played by a separate process (shared by the benches)."""

from __future__ import annotations

import os
import subprocess
import sys
import tty

__all__ = ["Pty"]


class Pty:
    """A raw pty; :meth:`start` runs ``script`` (Python source, given the master's fd as argv[1] and
    ``blob`` on stdin) in a child process that plays the device side."""

    def __init__(self, script: str) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self._script = script
        self._child: subprocess.Popen[bytes] | None = None

    def start(self, blob: bytes) -> None:
        self._child = subprocess.Popen(
            [sys.executable, "-c", self._script, str(self.master)],
            stdin=subprocess.PIPE,
            pass_fds=[self.master],
        )
        assert self._child.stdin is not None
        self._child.stdin.write(blob)
        self._child.stdin.close()

    def close(self) -> None:
        if self._child is not None:
            self._child.kill()
            self._child.wait()
        os.close(self.master)
        os.close(self.slave)
