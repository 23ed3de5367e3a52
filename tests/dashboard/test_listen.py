"""Where ``servobus dashboard`` listens (issue 40): 127.0.0.1 only by default; beyond this host it is
refused without users, and with users the page asks for a password. HTTP checks, no browser."""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import sys
from pathlib import Path

import httpx
import pytest

from dashboard._serving import dashboard, run
from servobus.dashboard import DEFAULT_PORT

QUIET = ("--sim", "1", "--still")


def _free(port: int) -> bool:
    """Nothing listens on ``port`` here, on any address (the default port may be someone's)."""
    for host in ("127.0.0.1", "0.0.0.0"):
        with socket.socket() as probe:
            try:
                probe.bind((host, port))
            except OSError:
                return False
    return True


def _listening(pid: int) -> list[tuple[str, int]]:
    """The TCP addresses process ``pid`` listens on, from Linux's socket table (IPv4 shown dotted)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = []
    for table in ("tcp", "tcp6"):
        with open(f"/proc/{pid}/net/{table}") as f:
            for line in f.read().splitlines()[1:]:
                cols = line.split()
                local, state, inode = cols[1], cols[3], cols[9]
                if state != "0A" or inode not in inodes:  # 0A: LISTEN
                    continue
                address, port = local.split(":")
                raw = bytes.fromhex(address)
                if table == "tcp":
                    host = socket.inet_ntop(socket.AF_INET, raw[::-1])
                else:  # (four little-endian 32-bit words)
                    words = b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4))
                    host = socket.inet_ntop(socket.AF_INET6, words)
                found.append((host, int(port, 16)))
    return found


def _outside_addresses() -> set[str]:
    """This machine's IPv4 addresses other than loopback (none on a machine without a network)."""
    found = set()
    with contextlib.suppress(OSError):
        found.update(socket.gethostbyname_ex(socket.gethostname())[2])
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.connect(("192.0.2.1", 9))  # (no packet leaves: the route picks this host's address)
        found.add(udp.getsockname()[0])
    return {a for a in found if not a.startswith("127.") and a != "0.0.0.0"}


def test_listens_on_loopback_only_by_default() -> None:
    busy = f"port {DEFAULT_PORT} is in use here: the default --listen cannot be tried"
    if not _free(DEFAULT_PORT):
        pytest.skip(busy)
    with contextlib.ExitStack() as stack:
        try:
            served = stack.enter_context(dashboard(*QUIET))
        except AssertionError as exc:
            if "Address already in use" in str(exc):  # (taken since we looked)
                pytest.skip(busy)
            raise
        assert served.url == f"http://127.0.0.1:{DEFAULT_PORT}/", served.first_line
        assert httpx.get(served.url, timeout=10).status_code == 200
        if sys.platform == "linux":
            assert _listening(served.process.pid) == [("127.0.0.1", DEFAULT_PORT)]
        for address in _outside_addresses():
            with socket.socket() as probe:
                probe.settimeout(5)
                code = probe.connect_ex((address, DEFAULT_PORT))
            assert code == errno.ECONNREFUSED, (address, os.strerror(code))


def test_listening_beyond_this_host_without_users_is_refused() -> None:
    done = run([*QUIET, "--listen", "0.0.0.0:0", "--duration", "3"])  # (if it served: not for long)
    assert done.returncode == 2, done
    assert done.stdout == ""
    assert len(done.stderr.splitlines()) == 1, done.stderr
    assert "without users" in done.stderr and "Traceback" not in done.stderr


def test_beyond_this_host_with_users_asks_for_a_password(tmp_path: Path) -> None:
    users = tmp_path / "users.txt"
    users.write_text("# who may look\nalice:wonderland\n")
    with dashboard(*QUIET, "--listen", "0.0.0.0:0", "--users", str(users)) as served:
        port = int(served.url.rsplit(":", 1)[1].strip("/"))
        assert served.url == f"http://0.0.0.0:{port}/", served.first_line
        if sys.platform == "linux":
            assert _listening(served.process.pid) == [("0.0.0.0", port)]
        page = f"http://127.0.0.1:{port}/"
        with httpx.Client(timeout=10) as client:
            for path in ("", "api/snapshot", "api/info", "static/dashboard.js"):
                refused = client.get(page + path)
                assert refused.status_code == 401, (path, refused.text)
                assert refused.headers["www-authenticate"].startswith("Basic ")
            assert client.get(page, auth=("alice", "rabbit")).status_code == 401
            assert client.get(page, auth=("bob", "wonderland")).status_code == 401
            answer = client.get(page, auth=("alice", "wonderland"))
            assert answer.status_code == 200 and "servobus dashboard" in answer.text
            assert client.get(page + "api/snapshot", auth=("alice", "wonderland")).json()["motors"]
