"""servobus.remote.security: endpoints judged local or not, the refusal to listen beyond loopback
unprotected, :class:`Access` validated, and, on real Zenoh sessions over 127.0.0.1, the commander /
reader split enforced by the bridge's access control, with usrpwd and with mutual TLS; refused
credentials fail ``zenoh.open``; a client listens on no socket.

The bridge side here stands in for the real bridge: it declares what a bridge declares (subscribers
on the set-point keys, queryables on read/request/info, its ``_alive`` token, a watch on
``_clients``) and records what reaches it.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import zenoh

from remote._certs import Issued, issue, make_ca
from servobus.remote.security import (
    DEFAULT_ENDPOINT,
    Access,
    InsecureListen,
    bridge_config,
    client_config,
    is_loopback,
    open_error,
)

NODE = "n"
ROOT = f"servobus/{NODE}"
# What a refused client waits at most: short, so the refusals stay cheap.
REFUSED_TIMEOUT_S = 0.5
# How long something that must not arrive is watched for, once what must arrive has.
QUIET_S = 0.3


def _port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _until(
    condition: Callable[[], bool], timeout: float = 2.0, step: Callable[[], None] | None = None
) -> bool:
    """Poll ``condition`` (doing ``step`` first each time) until true or ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        if step is not None:
            step()
        if condition():
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)


def _settings(config: zenoh.Config) -> dict[str, Any]:
    return dict(json.loads(str(config)))


# --- endpoints --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("endpoint", "local"),
    [
        ("tcp/127.0.0.1:7447", True),
        ("tcp/127.1.2.3:7447", True),
        ("udp/127.0.0.1:7447", True),
        ("tls/localhost:7447", True),
        ("quic/LOCALHOST:7447", True),
        ("ws/127.0.0.1:8080", True),
        ("tcp/[::1]:7447", True),
        ("tcp/[::ffff:127.0.0.1]:7447", True),
        ("tcp/127.0.0.1:7447#iface=lo", True),
        ("tcp/127.0.0.1:7447?rel=1#iface=lo", True),
        ("unixsock-stream//tmp/bridge.sock", True),
        ("tcp/0.0.0.0:7447", False),
        ("tcp/[::]:7447", False),
        ("tcp/192.168.1.10:7447", False),
        ("tcp/10.0.0.1:7447#iface=eth0", False),
        ("tls/[fe80::1%eth0]:7447", False),
        ("tcp/robot.local:7447", False),
        ("serial//dev/ttyUSB0", False),
    ],
)
def test_is_loopback(endpoint: str, local: bool) -> None:
    assert is_loopback(endpoint) is local


@pytest.mark.parametrize(
    "endpoint",
    ["", "tcp", "tcp/", "127.0.0.1:7447", "tcp/127.0.0.1", "tcp/[::1]7447", "tcp/:7447", "tcp/h:99999"],
)
def test_is_loopback_bad_text(endpoint: str) -> None:
    with pytest.raises(ValueError, match="bad zenoh endpoint") as caught:
        is_loopback(endpoint)
    assert repr(endpoint) in str(caught.value)


# --- Access -----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def users_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("users") / "users.txt"
    path.write_text("cmd:cmd-secret\nro:ro-secret\n\nother:other-secret\n")
    return path


@dataclass(frozen=True)
class Pki:
    ca: Issued
    server: Issued
    cmd: Issued
    ro: Issued
    stranger: Issued  # CN "cmd", signed by another CA


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    here = tmp_path_factory.mktemp("pki")
    ca = make_ca(here)
    elsewhere = here / "other"
    elsewhere.mkdir()  # (same CN "cmd": its own directory, or it would overwrite ours)
    return Pki(
        ca=ca,
        server=issue(ca, here, "bridge", server=True),
        cmd=issue(ca, here, "cmd"),
        ro=issue(ca, here, "ro"),
        stranger=issue(make_ca(elsewhere, "other CA"), elsewhere, "cmd"),
    )


def test_access_is_normalised(users_file: Path) -> None:
    access = Access(commanders={"cmd"}, readers=["ro"], users_file=str(users_file))  # type: ignore[arg-type]
    assert access.commanders == frozenset({"cmd"})
    assert access.readers == frozenset({"ro"})
    assert access.users_file == users_file
    assert not access.tls
    hash(access)


def test_access_refusals(users_file: Path, pki: Pki, tmp_path: Path) -> None:
    tls = {"tls_cert": pki.server.cert, "tls_key": pki.server.key, "tls_ca": pki.ca.cert}
    with pytest.raises(ValueError, match="no such file"):
        Access(commanders=frozenset({"cmd"}), users_file=tmp_path / "absent.txt")
    with pytest.raises(ValueError, match="both commander and reader"):
        Access(commanders=frozenset({"cmd", "ro"}), readers=frozenset({"ro"}), users_file=users_file)
    with pytest.raises(ValueError, match="all of tls_cert, tls_key and tls_ca"):
        Access(commanders=frozenset({"cmd"}), tls_cert=pki.server.cert, tls_key=pki.server.key)
    with pytest.raises(ValueError, match="no subject"):
        Access(users_file=users_file)
    with pytest.raises(ValueError, match="no authentication"):
        Access(commanders=frozenset({"cmd"}))
    with pytest.raises(ValueError, match="nobody not in users file"):
        Access(commanders=frozenset({"nobody"}), users_file=users_file)
    with pytest.raises(ValueError, match="not the string"):
        Access(commanders="cmd", users_file=users_file)  # type: ignore[arg-type]
    bad = tmp_path / "bad.txt"
    bad.write_text("# a comment zenoh would refuse\ncmd:x\n")
    with pytest.raises(ValueError, match="line 1 is not user:password"):
        Access(commanders=frozenset({"cmd"}), users_file=bad)
    # TLS alone needs no users file, and its names are not looked up in one
    assert Access(commanders=frozenset({"anyone"}), **tls).tls


# --- bridge_config / client_config -----------------------------------------------------------------


def test_insecure_listen(users_file: Path) -> None:
    with pytest.raises(InsecureListen) as caught:
        bridge_config(NODE, ["tcp/127.0.0.1:7447", "tcp/0.0.0.0:7447"])
    message = str(caught.value)
    assert "\n" not in message
    assert "tcp/0.0.0.0:7447" in message
    assert "--users" in message and "--tls-" in message and "--insecure" in message
    assert isinstance(caught.value, ValueError)
    # accepted when told, or with access (neither is opened here)
    insecure = _settings(bridge_config(NODE, ["tcp/0.0.0.0:7447"], insecure=True))
    assert insecure["listen"]["endpoints"] == ["tcp/0.0.0.0:7447"]
    # (no users, but one client's traffic still reaches no other: every session a commander)
    assert insecure["access_control"]["enabled"]
    (anyone,) = insecure["access_control"]["subjects"]
    assert anyone["id"] == "anyone" and not any(v for k, v in anyone.items() if k != "id"), anyone
    access = Access(commanders=frozenset({"cmd"}), users_file=users_file)
    guarded = _settings(bridge_config(NODE, ["tcp/0.0.0.0:7447"], access))
    assert guarded["access_control"]["enabled"]


def test_bridge_config_settings(users_file: Path) -> None:
    default = _settings(bridge_config(NODE))
    assert default["mode"] == "peer"
    assert default["listen"]["endpoints"] == [DEFAULT_ENDPOINT]
    assert default["connect"]["endpoints"] == []
    assert default["scouting"]["multicast"]["enabled"] is False
    assert default["scouting"]["gossip"]["enabled"] is False
    assert default["adminspace"]["enabled"] is False
    # the default bridge isolates its clients with the commanders' rules, for any session
    open_acl = default["access_control"]
    assert open_acl["enabled"] is True and open_acl["default_permission"] == "deny"
    assert [p["subjects"] for p in open_acl["policies"]] == [["anyone"]]
    assert not any(
        rule["flows"] == ["egress"]
        and "put" in rule["messages"]
        and any(k.endswith("setpoint") or k.endswith("setpoints") for k in rule["key_exprs"])
        for rule in open_acl["rules"]
    )
    access = Access(commanders=frozenset({"cmd"}), readers=frozenset({"ro"}), users_file=users_file)
    guarded = _settings(bridge_config(NODE, access=access))
    acl = guarded["access_control"]
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    assert guarded["transport"]["auth"]["usrpwd"]["dictionary_file"] == str(users_file.resolve())
    # the bridge accepts only: it is given no usrpwd identity of its own
    assert guarded["transport"]["auth"]["usrpwd"]["user"] is None
    for bad in ("", "a/b", "n*", "$n", "a b"):
        with pytest.raises(ValueError, match="bad node"):
            bridge_config(bad)
    with pytest.raises(ValueError, match="no listen endpoint"):
        bridge_config(NODE, [])
    with pytest.raises(ValueError, match="not the string"):
        bridge_config(NODE, DEFAULT_ENDPOINT)


def test_tls_access_needs_tls_endpoints(pki: Pki) -> None:
    access = Access(
        commanders=frozenset({"cmd"}), tls_cert=pki.server.cert, tls_key=pki.server.key, tls_ca=pki.ca.cert
    )
    with pytest.raises(ValueError, match="is not tls/ or quic/"):
        bridge_config(NODE, ["tcp/127.0.0.1:7447"], access)
    tls = _settings(bridge_config(NODE, ["tls/127.0.0.1:7447"], access))["transport"]["link"]["tls"]
    assert tls["enable_mtls"] is True
    assert tls["root_ca_certificate"] == str(pki.ca.cert.resolve())


def test_config_file_first_ours_on_top(tmp_path: Path) -> None:
    user_config = tmp_path / "zenoh.json5"
    user_config.write_text(
        "{ mode: 'router', listen: { endpoints: ['tcp/0.0.0.0:9'] },"
        " scouting: { multicast: { enabled: true } }, queries_default_timeout: 1234,"
        " access_control: { enabled: false } }"
    )
    bridge = _settings(bridge_config(NODE, config_file=user_config))
    assert bridge["mode"] == "peer"
    assert bridge["access_control"]["enabled"] is True  # (its clients stay apart, whatever the file says)
    assert bridge["listen"]["endpoints"] == [DEFAULT_ENDPOINT]
    assert bridge["scouting"]["multicast"]["enabled"] is False
    assert bridge["queries_default_timeout"] == 1234  # theirs, where we set nothing
    client = _settings(client_config(config_file=user_config))
    assert client["listen"]["endpoints"] == []
    assert client["queries_default_timeout"] == 1234


def test_client_config_settings(pki: Pki) -> None:
    settings = _settings(client_config(["tcp/127.0.0.1:1"], user="u", password="p", connect_timeout_s=0.25))
    assert settings["mode"] == "peer"
    assert settings["listen"]["endpoints"] == []
    assert settings["connect"]["endpoints"] == ["tcp/127.0.0.1:1"]
    assert settings["connect"]["timeout_ms"] == 250
    assert settings["connect"]["exit_on_failure"] is True
    assert settings["scouting"]["multicast"]["enabled"] is False
    assert settings["transport"]["auth"]["usrpwd"]["user"] == "u"
    tls = _settings(client_config(tls_cert=pki.cmd.cert, tls_key=pki.cmd.key, tls_ca=pki.ca.cert))
    assert tls["transport"]["link"]["tls"]["enable_mtls"] is True
    for kwargs in ({"user": "u"}, {"password": "p"}, {"tls_cert": pki.cmd.cert}, {"connect_timeout_s": 0}):
        with pytest.raises(ValueError):
            client_config(**kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="bad zenoh endpoint"):
        client_config(["nonsense"])


def test_open_error() -> None:
    endpoint = f"tcp/127.0.0.1:{_port()}"
    started = time.monotonic()
    with pytest.raises(zenoh.ZError) as caught:
        zenoh.open(client_config([endpoint], connect_timeout_s=0.3))
    assert time.monotonic() - started < 2.0
    assert open_error([endpoint], caught.value) == (
        f"no bridge reachable at {endpoint}: not running, or the credentials were refused"
    )
    other = open_error(["tls/h:1"], RuntimeError("Cannot read certificate /x.pem\n at /src/a.rs:3."))
    assert other == "could not open a zenoh session for tls/h:1: Cannot read certificate /x.pem"


# --- real sessions ----------------------------------------------------------------------------------


@dataclass
class Bridge:
    """A stand-in bridge session: what it declares, and what reaches it."""

    session: zenoh.Session
    endpoint: str
    puts: list[str] = field(default_factory=list)
    tokens: list[tuple[str, zenoh.SampleKind]] = field(default_factory=list)
    keep: list[Any] = field(default_factory=list)

    def serve(self) -> None:
        def answer(text: bytes) -> Callable[[zenoh.Query], None]:
            return lambda query: query.reply(query.key_expr, text)

        session = self.session
        self.keep = [
            # Inside the ACL's keys: servobus/n/** would never be announced to a client (see security.py).
            session.declare_subscriber(f"{ROOT}/b/*/setpoint", lambda s: self.puts.append(str(s.key_expr))),
            session.declare_subscriber(f"{ROOT}/b/setpoints", lambda s: self.puts.append(str(s.key_expr))),
            session.declare_queryable(f"{ROOT}/b/*/read", answer(b"read")),
            session.declare_queryable(f"{ROOT}/b/*/request", answer(b"request")),
            session.declare_queryable(f"{ROOT}/b/info", answer(b"info")),
            session.liveliness().declare_token(f"{ROOT}/_alive"),
            session.liveliness().declare_subscriber(
                f"{ROOT}/_clients/**", lambda s: self.tokens.append((str(s.key_expr), s.kind))
            ),
        ]


@dataclass
class Seen:
    """What one client managed to do against a :class:`Bridge`."""

    alive: bool
    state: bool
    setpoint: bool
    setpoints: bool
    token: bool
    token_gone: bool
    replies: dict[str, list[bytes]]


def _replies(session: zenoh.Session, key: str) -> list[bytes]:
    return [reply.ok.payload.to_bytes() for reply in session.get(key, timeout=1.0) if reply.ok is not None]


def _probe(bridge: Bridge, config: zenoh.Config, client_id: str, *, reads: bool, commands: bool) -> Seen:
    """Open a client with ``config`` and try everything a client may or may not do.

    What should succeed (``reads``, ``commands``) is polled for until it does (or 2 s); what should not
    is given :data:`QUIET_S` to show up anyway, declarations having had time to travel by then.
    """
    read_s = 2.0 if reads else QUIET_S
    command_s = 2.0 if commands else QUIET_S
    bridge.puts.clear()
    bridge.tokens.clear()
    session = zenoh.open(config)
    states: list[str] = []
    alive: list[str] = []
    token_key = f"{ROOT}/_clients/{client_id}"
    try:
        session.declare_subscriber(f"{ROOT}/*/*/state", lambda s: states.append(str(s.key_expr)))
        session.liveliness().declare_subscriber(
            f"{ROOT}/_alive", lambda s: alive.append(str(s.key_expr)), history=True
        )
        token = session.liveliness().declare_token(token_key)
        seen_alive = _until(lambda: bool(alive), timeout=read_s)
        seen_state = _until(
            lambda: bool(states), read_s, step=lambda: bridge.session.put(f"{ROOT}/b/1/state", b"s")
        )

        def put_setpoints() -> None:
            session.put(f"{ROOT}/b/1/setpoint", b"1")
            session.put(f"{ROOT}/b/setpoints", b"1")

        both = {f"{ROOT}/b/1/setpoint", f"{ROOT}/b/setpoints"}
        _until(lambda: both <= set(bridge.puts), timeout=command_s, step=put_setpoints)
        keys = ("b/1/read", "b/info", "b/1/request", "b/**")
        replies = {key: _replies(session, f"{ROOT}/{key}") for key in keys}
        if commands:  # (a declaration may still be on its way: asked again until answered)
            _until(
                lambda: bool(replies["b/1/request"]),
                step=lambda: replies.update({"b/1/request": _replies(session, f"{ROOT}/b/1/request")}),
            )
        seen_token = _until(lambda: (token_key, zenoh.SampleKind.PUT) in bridge.tokens, timeout=command_s)
        token.undeclare()
        token_gone = _until(
            lambda: (token_key, zenoh.SampleKind.DELETE) in bridge.tokens,
            timeout=command_s if seen_token else 0.0,
        )
        return Seen(
            alive=seen_alive,
            state=seen_state,
            setpoint=f"{ROOT}/b/1/setpoint" in bridge.puts,
            setpoints=f"{ROOT}/b/setpoints" in bridge.puts,
            token=seen_token,
            token_gone=token_gone,
            replies=replies,
        )
    finally:
        session.close()


def _refused(bridge: Bridge, config: zenoh.Config) -> None:
    bridge.puts.clear()
    started = time.monotonic()
    with pytest.raises(zenoh.ZError):
        zenoh.open(config)
    # within the connect timeout (and some slack for a loaded machine)
    assert time.monotonic() - started < REFUSED_TIMEOUT_S + 1.0
    assert bridge.puts == []


def _served(endpoint: str, access: Access | None) -> Iterator[Bridge]:
    """A recording bridge session on ``endpoint`` with ``access``, for one module's tests."""
    session = zenoh.open(bridge_config(NODE, [endpoint], access))
    bridge = Bridge(session, endpoint)
    try:
        bridge.serve()
        yield bridge
    finally:
        session.close()


@pytest.fixture(scope="module")
def usrpwd_bridge(users_file: Path) -> Iterator[Bridge]:
    endpoint = f"tcp/127.0.0.1:{_port()}"
    access = Access(commanders=frozenset({"cmd"}), readers=frozenset({"ro"}), users_file=users_file)
    yield from _served(endpoint, access)


@pytest.fixture(scope="module")
def tls_bridge(pki: Pki) -> Iterator[Bridge]:
    endpoint = f"tls/127.0.0.1:{_port()}"
    access = Access(
        commanders=frozenset({"cmd"}),
        readers=frozenset({"ro"}),
        tls_cert=pki.server.cert,
        tls_key=pki.server.key,
        tls_ca=pki.ca.cert,
    )
    yield from _served(endpoint, access)


def _assert_commander(seen: Seen) -> None:
    assert seen.alive and seen.state
    assert seen.setpoint and seen.setpoints
    # a wildcard beyond the allowed keys is denied whole, even to a commander
    assert seen.replies == {
        "b/1/read": [b"read"],
        "b/info": [b"info"],
        "b/1/request": [b"request"],
        "b/**": [],
    }
    assert seen.token and seen.token_gone


def _assert_reader(seen: Seen) -> None:
    assert seen.alive and seen.state
    assert seen.replies == {"b/1/read": [b"read"], "b/info": [b"info"], "b/1/request": [], "b/**": []}
    assert not seen.setpoint and not seen.setpoints
    assert not seen.token


def test_usrpwd_commander(usrpwd_bridge: Bridge) -> None:
    config = client_config([usrpwd_bridge.endpoint], user="cmd", password="cmd-secret")
    _assert_commander(_probe(usrpwd_bridge, config, "cmd-1", reads=True, commands=True))


def test_usrpwd_reader(usrpwd_bridge: Bridge) -> None:
    config = client_config([usrpwd_bridge.endpoint], user="ro", password="ro-secret")
    _assert_reader(_probe(usrpwd_bridge, config, "ro-1", reads=True, commands=False))


def test_usrpwd_user_in_neither_set_may_do_nothing(usrpwd_bridge: Bridge) -> None:
    config = client_config([usrpwd_bridge.endpoint], user="other", password="other-secret")
    seen = _probe(usrpwd_bridge, config, "other-1", reads=False, commands=False)
    assert not (seen.alive or seen.state or seen.setpoint or seen.setpoints or seen.token)
    assert seen.replies == {"b/1/read": [], "b/info": [], "b/1/request": [], "b/**": []}


@pytest.mark.parametrize(
    "credentials",
    [{"user": "cmd", "password": "wrong"}, {"user": "nobody", "password": "cmd-secret"}, {}],
    ids=["wrong-password", "unknown-user", "none"],
)
def test_usrpwd_refused(usrpwd_bridge: Bridge, credentials: dict[str, str]) -> None:
    config = client_config([usrpwd_bridge.endpoint], connect_timeout_s=REFUSED_TIMEOUT_S, **credentials)
    _refused(usrpwd_bridge, config)


def test_tls_commander(tls_bridge: Bridge, pki: Pki) -> None:
    config = client_config(
        [tls_bridge.endpoint], tls_cert=pki.cmd.cert, tls_key=pki.cmd.key, tls_ca=pki.ca.cert
    )
    _assert_commander(_probe(tls_bridge, config, "cmd-1", reads=True, commands=True))


def test_tls_reader(tls_bridge: Bridge, pki: Pki) -> None:
    config = client_config(
        [tls_bridge.endpoint], tls_cert=pki.ro.cert, tls_key=pki.ro.key, tls_ca=pki.ca.cert
    )
    _assert_reader(_probe(tls_bridge, config, "ro-1", reads=True, commands=False))


@pytest.mark.parametrize("who", ["no-certificate", "other-ca"])
def test_tls_refused(tls_bridge: Bridge, pki: Pki, who: str) -> None:
    cert = {} if who == "no-certificate" else {"tls_cert": pki.stranger.cert, "tls_key": pki.stranger.key}
    config = client_config(
        [tls_bridge.endpoint], tls_ca=pki.ca.cert, connect_timeout_s=REFUSED_TIMEOUT_S, **cert
    )
    _refused(tls_bridge, config)


def test_usrpwd_and_tls_need_the_same_name_in_both(users_file: Path, pki: Pki) -> None:
    endpoint = f"tls/127.0.0.1:{_port()}"
    access = Access(
        commanders=frozenset({"cmd"}),
        readers=frozenset({"ro"}),
        users_file=users_file,
        tls_cert=pki.server.cert,
        tls_key=pki.server.key,
        tls_ca=pki.ca.cert,
    )
    bridge = Bridge(zenoh.open(bridge_config(NODE, [endpoint], access)), endpoint)
    try:
        bridge.serve()
        cert = {"tls_cert": pki.cmd.cert, "tls_key": pki.cmd.key, "tls_ca": pki.ca.cert}
        both = client_config([endpoint], user="cmd", password="cmd-secret", **cert)
        _assert_commander(_probe(bridge, both, "cmd-1", reads=True, commands=True))
        # user ro with certificate cmd: in neither set as a pair, so no right at all
        mixed = client_config([endpoint], user="ro", password="ro-secret", **cert)
        seen = _probe(bridge, mixed, "mixed-1", reads=False, commands=False)
        assert not (seen.alive or seen.state or seen.setpoint or seen.token)
        # the certificate alone is not enough
        _refused(bridge, client_config([endpoint], connect_timeout_s=REFUSED_TIMEOUT_S, **cert))
    finally:
        bridge.session.close()


def test_default_bridge_every_session_commands_and_none_sees_another(tmp_path: Path) -> None:
    """No users: any session may command (a peer, as ``connect`` opens), and a session in Zenoh's
    ``client`` mode, which a peer routes for, is routed nothing of another client's."""
    endpoint = f"tcp/127.0.0.1:{_port()}"
    with contextlib.contextmanager(_served)(endpoint, None) as bridge:
        spy_config = client_config([endpoint])
        spy_config.insert_json5("mode", json.dumps("client"))
        spy = zenoh.open(spy_config)
        seen: list[str] = []
        keep: list[Any] = []
        try:
            keep += [
                spy.declare_subscriber(f"{ROOT}/**", lambda s: seen.append(str(s.key_expr))),
                spy.declare_subscriber(f"{ROOT}/*/*/setpoint", lambda s: seen.append(str(s.key_expr))),
                spy.declare_queryable(f"{ROOT}/**", lambda q: seen.append(str(q.key_expr))),
                spy.liveliness().declare_subscriber(
                    f"{ROOT}/_clients/*", lambda s: seen.append(str(s.key_expr)), history=True
                ),
            ]
            _assert_commander(_probe(bridge, client_config([endpoint]), "cmd-1", reads=True, commands=True))
            time.sleep(QUIET_S)
            assert seen == [], seen
            # what it may see, it sees: the bridge's token (so it is connected and served)
            alive = [str(r.ok.key_expr) for r in spy.liveliness().get(f"{ROOT}/_alive", timeout=1.0) if r.ok]
            assert alive == [f"{ROOT}/_alive"]
            assert not [r for r in spy.liveliness().get(f"{ROOT}/_clients/*", timeout=0.5) if r.ok]
        finally:
            keep.clear()
            spy.close()


# --- sockets ----------------------------------------------------------------------------------------


def _own_sockets() -> set[str]:
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue  # (closed meanwhile)
        if target.startswith("socket:["):
            inodes.add(target[len("socket:[") : -1])
    return inodes


def _address(hex_address: str) -> str:
    host, port = hex_address.split(":")
    raw = bytes.fromhex(host)
    if len(raw) == 4:
        text = socket.inet_ntop(socket.AF_INET, raw[::-1])
    else:  # (four host-order 32-bit words)
        text = socket.inet_ntop(socket.AF_INET6, b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4)))
    return f"{text}:{int(port, 16)}"


def _bound() -> set[tuple[str, str]]:
    """This process's listening TCP sockets and bound UDP sockets, as (kind, address)."""
    ours = _own_sockets()
    found = set()
    for kind in ("tcp", "tcp6", "udp", "udp6"):
        with open(f"/proc/net/{kind}") as table:
            next(table)
            for line in table:
                fields = line.split()
                local, state, inode = fields[1], fields[3], fields[9]
                listening = state == "0A" if kind.startswith("tcp") else True
                if inode in ours and listening:
                    found.add((kind, _address(local)))
    return found


def test_client_listens_on_nothing(usrpwd_bridge: Bridge) -> None:
    before = _bound()
    session = zenoh.open(client_config([usrpwd_bridge.endpoint], user="ro", password="ro-secret"))
    try:
        assert _bound() - before == set()
    finally:
        session.close()


def test_default_bridge_listens_on_loopback_only() -> None:
    with socket.socket() as probe:
        try:
            probe.bind(("127.0.0.1", 7447))
        except OSError:
            pytest.skip("port 7447 is taken on this machine")
    before = _bound()
    session = zenoh.open(bridge_config(NODE))
    try:
        assert _bound() - before == {("tcp", "127.0.0.1:7447")}
    finally:
        session.close()
