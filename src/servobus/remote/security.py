"""The Zenoh session configuration of a bridge and of its clients, and who may do what on a bridge.

A bridge (:func:`bridge_config`) is a Zenoh peer that listens, by default on loopback only
(:data:`DEFAULT_ENDPOINT`), and never connects out nor scouts: a multicast socket would listen beyond
loopback, and gossip would let a connected peer make the bridge dial addresses it names. It refuses
(:class:`InsecureListen`) to listen beyond this host without :class:`Access` unless told ``insecure``.

With :class:`Access`, clients authenticate with a user name and password (Zenoh's ``usrpwd``: a
dictionary file of ``user:password`` lines), with a client certificate (mutual TLS: the subject is the
certificate's common name), or both (then a client's user name and common name must both be in the
same set). Zenoh's access control denies everything but, for the keys of node ``N``:

* readers and commanders: subscribe to ``servobus/N/<B>/<M>/state``; query
  ``servobus/N/<B>/info``, ``servobus/N/<B>/metrics`` and ``servobus/N/<B>/<M>/read``; see the
  bridge's liveliness token ``servobus/N/_alive``;
* commanders also: put ``servobus/N/<B>/<M>/setpoint`` and ``servobus/N/<B>/setpoints``; query
  ``servobus/N/<B>/<M>/request``; declare a liveliness token ``servobus/N/_clients/<client id>``.

Without :class:`Access` every session that connects is a commander, under the same rules: nothing
is routed from one client to another (a Zenoh session in ``client`` mode is otherwise routed every
other client's set-points, requests and tokens, secret ids included), so a local program cannot
learn another client's secret nor keep its token alive, whatever the session's mode.

Zenoh matches a message's key expression by *inclusion* in a rule's key expressions, the bridge's own
declarations included: the bridge must declare its subscribers, queryables and liveliness subscriber
on key expressions inside those above (``servobus/N/B/*/setpoint`` is fine, ``servobus/N/**`` is not
and would never be announced to a client), and a client's wildcard query reaches only what its whole
key expression is allowed (``servobus/N/B/*/read`` does, ``servobus/N/B/**`` is denied).

Usrpwd alone authenticates a client when it connects but does not encrypt what follows (set-points
included): beyond a network you trust, listen on ``tls/`` with client certificates.

A client (:func:`client_config`) is a peer that listens on nothing and connects to the bridge only;
``zenoh.open`` fails (``zenoh.ZError``, within the connect timeout) when no bridge answers or the
bridge refuses its credentials, and :func:`open_error` says so in one line.
"""

from __future__ import annotations

import ipaddress
import json
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

__all__ = [
    "DEFAULT_ENDPOINT",
    "Access",
    "InsecureListen",
    "bridge_config",
    "client_config",
    "is_loopback",
    "open_error",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

# Zenoh link protocols whose address is host:port.
_IP_PROTOCOLS = frozenset({"tcp", "udp", "tls", "quic", "ws"})
# Link protocols that never leave this host (a socket file, a named pipe).
_LOCAL_PROTOCOLS = frozenset({"unixsock-stream", "unixpipe"})
# Protocols that carry the TLS configuration (a client certificate, hence a common name).
_TLS_PROTOCOLS = frozenset({"tls", "quic"})

# A key chunk (node, bus): no separator and none of Zenoh's wildcard or reserved characters.
_CHUNK = re.compile(r"[^/*$?#\s]+")
# The Rust source location Zenoh appends to its errors (" at /…/orchestrator.rs:388.").
_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+\.?\s*$")


def _address(endpoint: str) -> tuple[str, str]:
    """``(protocol, address)`` of a Zenoh endpoint, the address without its ``?``/``#`` suffixes."""
    protocol, slash, rest = endpoint.strip().partition("/")
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    if not slash or not protocol or not address:
        raise ValueError(
            f"bad zenoh endpoint {endpoint!r}: expected <protocol>/<address>, e.g. {DEFAULT_ENDPOINT}"
        )
    return protocol.lower(), address


def _host(endpoint: str, address: str) -> str:
    """The host of ``host:port`` (IPv6 in brackets), the port checked."""
    if address.startswith("["):
        host, bracket, port = address[1:].partition("]")
        if not bracket or not port.startswith(":"):
            raise ValueError(f"bad zenoh endpoint {endpoint!r}: expected [<IPv6>]:<port>")
        port = port[1:]
    else:
        host, colon, port = address.rpartition(":")
        if not colon:
            raise ValueError(f"bad zenoh endpoint {endpoint!r}: expected <host>:<port>")
    if not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"bad zenoh endpoint {endpoint!r}: expected <host>:<port> (port 0-65535)")
    return host


def is_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint is reachable from this host only.

    Args:
        endpoint: a Zenoh locator or endpoint, e.g. ``tcp/127.0.0.1:7447``, ``tls/[::1]:7447``,
            ``unixsock-stream//tmp/bridge.sock``; ``?…`` and ``#…`` suffixes (``#iface=lo``) are
            ignored.

    Returns:
        True for tcp/udp/tls/quic/ws on 127.0.0.0/8, ::1 (IPv4-mapped too) or ``localhost``, and for
        unix sockets and pipes; False for anything else: the unspecified addresses (0.0.0.0, ``[::]``),
        a LAN address, any other host name (it may resolve anywhere), or another protocol.

    Raises:
        ValueError: the text is not ``<protocol>/<address>``, or its host:port is malformed.
    """
    protocol, address = _address(endpoint)
    if protocol in _LOCAL_PROTOCOLS:
        return True
    if protocol not in _IP_PROTOCOLS:
        return False
    host = _host(endpoint, address)
    if host.lower() == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])  # (an IPv6 scope is not part of the address)
    except ValueError:
        return False  # a host name: where it points is not ours to know
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        return ip.ipv4_mapped.is_loopback
    return ip.is_loopback


def _names(value: Iterable[str], what: str) -> frozenset[str]:
    # A bare string would become a set of its characters.
    if isinstance(value, str):
        raise ValueError(f"Access.{what} must be a collection of names, not the string {value!r}")
    names = frozenset(value)
    for name in names:
        if not isinstance(name, str) or not name or name != name.strip() or ":" in name:
            raise ValueError(f"Access.{what}: bad name {name!r} (empty, padded, or with ':')")
    return names


def _users(path: Path) -> frozenset[str]:
    """The user names of a usrpwd dictionary file (the rules Zenoh 1.10 loads it by)."""
    users = set()
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue  # (Zenoh skips blank lines; anything else without ':' makes zenoh.open fail)
        user, colon, _password = line.partition(":")
        if not colon or not user:
            raise ValueError(f"users file {path}: line {number} is not user:password")
        users.add(user)
    return frozenset(users)


@dataclass(frozen=True, slots=True)
class Access:
    """Who may do what on a bridge: the clients' credentials and the names they map to.

    A subject is a user name of ``users_file`` (usrpwd authentication), the common name of a client
    certificate signed by ``tls_ca`` (mutual TLS), or, with both, a client whose user name and common
    name are both in the set. The bridge needs no usrpwd identity of its own: it only accepts
    connections (checked with Zenoh 1.10.2), so none is asked for.

    Attributes:
        commanders: names that may command (set-points, any request, a ``_clients`` token) and read.
        readers: names that may only read (state, info, metrics, read-only requests, ``_alive``).
        users_file: Zenoh's usrpwd dictionary, one ``user:password`` a line; every name of
            ``commanders`` and ``readers`` must be one of its users.
        tls_cert: the bridge's certificate (PEM), for its ``tls/`` or ``quic/`` listen endpoints.
        tls_key: the bridge's private key (PEM, PKCS#8).
        tls_ca: the CA (PEM) that signs the clients' certificates; clients without one are refused.

    Raises:
        ValueError: a file is missing, TLS is given in part, a name is in both sets or in neither
            the users file, no name is given, or there is no authentication at all.
    """

    commanders: frozenset[str] = field(default_factory=frozenset)
    readers: frozenset[str] = field(default_factory=frozenset)
    users_file: Path | None = None
    tls_cert: Path | None = None
    tls_key: Path | None = None
    tls_ca: Path | None = None

    def __post_init__(self) -> None:
        # Sets, lists and str paths are accepted and stored as frozensets and Paths (frozen: hashable).
        object.__setattr__(self, "commanders", _names(self.commanders, "commanders"))
        object.__setattr__(self, "readers", _names(self.readers, "readers"))
        for name in ("users_file", "tls_cert", "tls_key", "tls_ca"):
            value = getattr(self, name)
            if value is not None:
                path = Path(value)
                if not path.is_file():
                    raise ValueError(f"Access.{name}: no such file: {path}")
                object.__setattr__(self, name, path)
        parts = (self.tls_cert, self.tls_key, self.tls_ca)
        if any(part is not None for part in parts) and not all(part is not None for part in parts):
            raise ValueError("Access: TLS needs all of tls_cert, tls_key and tls_ca (or none of them)")
        if self.users_file is None and not self.tls:
            raise ValueError("Access: no authentication: give users_file, or tls_cert/tls_key/tls_ca")
        both = self.commanders & self.readers
        if both:
            raise ValueError(f"Access: {', '.join(sorted(both))} both commander and reader; choose one")
        if not self.commanders and not self.readers:
            raise ValueError("Access: no subject: give at least one commander or reader")
        if self.users_file is not None:
            unknown = (self.commanders | self.readers) - _users(self.users_file)
            if unknown:
                raise ValueError(f"Access: {', '.join(sorted(unknown))} not in users file {self.users_file}")

    @property
    def tls(self) -> bool:
        """Whether clients authenticate with a certificate (mutual TLS)."""
        return self.tls_ca is not None


class InsecureListen(ValueError):
    """A bridge was asked to listen beyond this host with no :class:`Access` (and not ``insecure``)."""


def _chunk(value: str, what: str) -> str:
    if not _CHUNK.fullmatch(value):
        raise ValueError(f"bad {what} {value!r}: one key chunk, without '/', '*', '$', '?', '#' or spaces")
    return value


def _endpoints(endpoints: Sequence[str], what: str) -> list[str]:
    if isinstance(endpoints, str):
        raise ValueError(f"{what} must be a sequence of endpoints, not the string {endpoints!r}")
    listed = [str(endpoint).strip() for endpoint in endpoints]
    for endpoint in listed:
        _address(endpoint)  # (malformed text is refused here, not deep inside zenoh.open)
    return listed


def _rule(rule_id: str, flow: str, messages: Sequence[str], keys: Sequence[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": [flow],
        "messages": list(messages),
        "key_exprs": list(keys),
    }


def _access_control(node: str, access: Access | None) -> dict[str, Any]:
    """Zenoh's ``access_control`` for ``access`` on node ``node``: deny all but what is listed;
    without ``access``, every session may do what a commander may.

    Flows are seen from the bridge: ingress is what a client sends it, egress what it sends a client.
    Each line below was found needed by experiment (Zenoh 1.10.2, peer to peer, each rule dropped in
    turn): a client's subscription or query is routed only if the bridge's declaration of the
    matching subscriber/queryable may egress to it, and its replies too.
    """
    root = f"servobus/{node}"
    state = [f"{root}/*/*/state"]
    readable = [f"{root}/*/info", f"{root}/*/metrics", f"{root}/*/*/read"]
    alive = [f"{root}/_alive"]
    setpoints = [f"{root}/*/*/setpoint", f"{root}/*/setpoints"]
    request = [f"{root}/*/*/request"]
    reading = [
        _rule("state-out", "egress", ["put"], state),  # the bridge's state samples
        _rule("state-subscribe-in", "ingress", ["declare_subscriber"], state),  # else never sent
        _rule("read-query-in", "ingress", ["query"], readable),
        _rule("read-queryable-out", "egress", ["declare_queryable", "reply"], readable),
        _rule("alive-out", "egress", ["liveliness_token"], alive),
        # Not needed in 1.10.2 (tokens reach every peer unasked); lets a client subscribe to or query
        # _alive where Zenoh routes liveliness by interest.
        _rule("alive-watch-in", "ingress", ["declare_liveliness_subscriber", "liveliness_query"], alive),
    ]
    commanding = [
        _rule("setpoint-in", "ingress", ["put"], setpoints),
        _rule("setpoint-subscriber-out", "egress", ["declare_subscriber"], setpoints),  # else never put
        _rule("request-query-in", "ingress", ["query"], request),
        _rule("request-queryable-out", "egress", ["declare_queryable", "reply"], request),
        # One chunk: a client id, no deeper keys.
        _rule("client-token-in", "ingress", ["liveliness_token"], [f"{root}/_clients/*"]),
        # Not needed in 1.10.2, as alive-watch-in: the bridge's watch on the tokens, announced.
        _rule("client-watch-out", "egress", ["declare_liveliness_subscriber"], [f"{root}/_clients/**"]),
    ]
    if access is None:
        # Everyone a commander, but the same rules: nothing a client sends is routed to another
        # client (no set-point, request, token or query of one reaches the other), whatever the
        # session's mode. A subject with no field is any session (checked with Zenoh 1.10.2).
        return {
            "enabled": True,
            "default_permission": "deny",
            "rules": reading + commanding,
            "subjects": [{"id": "anyone"}],
            "policies": [
                {
                    "id": "command",
                    "rules": [rule["id"] for rule in reading + commanding],
                    "subjects": ["anyone"],
                }
            ],
        }
    subjects: list[dict[str, Any]] = []
    for subject_id, names in (("commanders", access.commanders), ("readers", access.readers)):
        if not names:
            continue  # (an empty list would be read as "any")
        subject: dict[str, Any] = {"id": subject_id}
        # Within one subject Zenoh ANDs its fields: with both, user name and common name must match.
        if access.users_file is not None:
            subject["usernames"] = sorted(names)
        if access.tls:
            subject["cert_common_names"] = sorted(names)
        subjects.append(subject)
    ids = [subject["id"] for subject in subjects]
    policies = [{"id": "read", "rules": [rule["id"] for rule in reading], "subjects": ids}]
    if access.commanders:
        policies.append(
            {"id": "command", "rules": [rule["id"] for rule in commanding], "subjects": ["commanders"]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": reading + commanding,
        "subjects": subjects,
        "policies": policies,
    }


def _config(config_file: Path | None, settings: Mapping[str, Any]) -> zenoh.Config:
    """The user's config (or Zenoh's defaults), then ``settings`` (key path → value) on top."""
    config = zenoh.Config() if config_file is None else zenoh.Config.from_file(str(config_file))
    for key, value in settings.items():
        config.insert_json5(key, json.dumps(value))
    return config


# What bridge and client both set: peer mode, no scouting (multicast would open a socket beyond
# loopback; gossip would let a peer make this one dial addresses it names), no admin space.
_COMMON: dict[str, Any] = {
    "mode": "peer",
    "scouting/multicast/enabled": False,
    "scouting/gossip/enabled": False,
    "adminspace/enabled": False,
    # A peer that stops answering without closing its link (a frozen process, a pulled cable) is
    # dropped after 1 s instead of Zenoh's 10 s, and with it its liveliness token: the bridge stops
    # the motors it commanded (set-points going stale stop them sooner).
    "transport/link/tx/lease": 1000,
    "transport/link/tx/keep_alive": 4,
}


def bridge_config(
    node: str,
    listen: Sequence[str] = (DEFAULT_ENDPOINT,),
    access: Access | None = None,
    *,
    insecure: bool = False,
    config_file: Path | None = None,
) -> zenoh.Config:
    """The Zenoh configuration of the bridge serving node ``node``.

    Args:
        node: the node's key chunk (``servobus/<node>/…``).
        listen: the endpoints to listen on, exactly these.
        access: who may do what; None: anyone who can connect may command (and nothing of one
            client reaches another: see the module's docstring).
        insecure: listen beyond this host without ``access`` all the same.
        config_file: a Zenoh JSON5 config loaded first. Set on top of it, whatever it says: ``mode``,
            ``listen/endpoints``, ``connect/endpoints`` (none), ``scouting/multicast/enabled`` and
            ``scouting/gossip/enabled`` (false), ``adminspace/enabled`` (false),
            ``transport/link/tx/lease`` (1 s) and ``keep_alive`` (4 a lease), ``access_control``;
            with ``access``, ``transport/auth/usrpwd/dictionary_file`` (with a users file) and
            ``transport/link/tls/{listen_certificate,listen_private_key,root_ca_certificate,
            enable_mtls}`` (with TLS).

    Returns:
        The config to ``zenoh.open``.

    Raises:
        InsecureListen: an endpoint is reachable from beyond this host, with no ``access`` and not
            ``insecure``.
        ValueError: a malformed node or endpoint, no endpoint, or TLS access with an endpoint that
            does not carry TLS (its clients could have no common name, so no right at all).
    """
    _chunk(node, "node")
    endpoints = _endpoints(listen, "listen")
    if not endpoints:
        raise ValueError("bridge_config: no listen endpoint")
    if access is None and not insecure:
        for endpoint in endpoints:
            if not is_loopback(endpoint):
                raise InsecureListen(
                    f"refusing to listen on {endpoint} without access control (it is reachable from "
                    "other hosts): give --users FILE or --tls-cert/--tls-key/--tls-ca with "
                    "--commander/--reader, or --insecure to let anyone who reaches it command the motors"
                )
    settings: dict[str, Any] = {
        **_COMMON,
        "listen/endpoints": endpoints,
        "connect/endpoints": [],
    }
    if access is not None:
        if access.tls:
            plain = [ep for ep in endpoints if _address(ep)[0] not in _TLS_PROTOCOLS]
            if plain:
                raise ValueError(
                    f"bridge_config: TLS access but {', '.join(plain)} is not tls/ or quic/: a client "
                    "there has no certificate, so no right"
                )
            for key, path in (
                ("listen_certificate", access.tls_cert),
                ("listen_private_key", access.tls_key),
                ("root_ca_certificate", access.tls_ca),
            ):
                if path is not None:  # (all three are: Access checked)
                    settings[f"transport/link/tls/{key}"] = str(path.resolve())
            # Without it the bridge asks no certificate, and a client has no common name.
            settings["transport/link/tls/enable_mtls"] = True
        if access.users_file is not None:
            settings["transport/auth/usrpwd/dictionary_file"] = str(access.users_file.resolve())
    settings["access_control"] = _access_control(node, access)
    return _config(config_file, settings)


def client_config(
    connect: Sequence[str] = (DEFAULT_ENDPOINT,),
    *,
    user: str | None = None,
    password: str | None = None,
    tls_cert: Path | None = None,
    tls_key: Path | None = None,
    tls_ca: Path | None = None,
    config_file: Path | None = None,
    connect_timeout_s: float = 2.0,
) -> zenoh.Config:
    """The Zenoh configuration of a client of a bridge: a peer that listens on nothing.

    Args:
        connect: the bridge's endpoints.
        user: the usrpwd user name (with ``password``).
        password: its password.
        tls_cert: the client certificate (PEM; its common name is the subject), with ``tls_key``.
        tls_key: its private key (PEM, PKCS#8).
        tls_ca: the CA that signed the bridge's certificate.
        config_file: a Zenoh JSON5 config loaded first. Set on top of it: ``mode``,
            ``listen/endpoints`` (none), ``connect/endpoints``, ``connect/timeout_ms``,
            ``connect/exit_on_failure`` (true), the scouting and admin space switches as in
            :func:`bridge_config`, and the usrpwd/TLS keys given here.
        connect_timeout_s: how long ``zenoh.open`` tries before it raises ``zenoh.ZError``.

    Returns:
        The config to ``zenoh.open``; with it, ``zenoh.open`` raises when no bridge is reachable or
        the credentials are refused (rather than opening a session with nobody to talk to).

    Raises:
        ValueError: a malformed endpoint, no endpoint, a user without password (or the reverse), a
            certificate without key (or the reverse), a missing file, or a timeout not above 0.
    """
    endpoints = _endpoints(connect, "connect")
    if not endpoints:
        raise ValueError("client_config: no endpoint to connect to")
    if (user is None) != (password is None):
        raise ValueError("client_config: user and password go together")
    if (tls_cert is None) != (tls_key is None):
        raise ValueError("client_config: tls_cert and tls_key go together")
    if not connect_timeout_s > 0:
        raise ValueError(f"client_config: connect_timeout_s must be above 0, not {connect_timeout_s}")
    settings: dict[str, Any] = {
        **_COMMON,
        "listen/endpoints": [],
        "connect/endpoints": endpoints,
        "connect/timeout_ms": max(1, round(connect_timeout_s * 1000)),
        # Without it a peer opens even when every connection failed, and just hears nothing.
        "connect/exit_on_failure": True,
    }
    if user is not None and password is not None:
        settings["transport/auth/usrpwd/user"] = user
        settings["transport/auth/usrpwd/password"] = password
    for key, value in (
        ("root_ca_certificate", tls_ca),
        ("connect_certificate", tls_cert),
        ("connect_private_key", tls_key),
    ):
        if value is not None:
            path = Path(value)
            if not path.is_file():
                raise ValueError(f"client_config: no such file: {path}")
            settings[f"transport/link/tls/{key}"] = str(path.resolve())
    if tls_cert is not None:
        # Zenoh sends its certificate only with mTLS on at this end too.
        settings["transport/link/tls/enable_mtls"] = True
    return _config(config_file, settings)


def open_error(endpoints: Sequence[str], exc: BaseException) -> str:
    """One line for a client's failed ``zenoh.open``.

    Args:
        endpoints: the endpoints it tried.
        exc: what ``zenoh.open`` raised.

    Returns:
        e.g. ``no bridge reachable at tcp/127.0.0.1:7447: not running, or the credentials were
        refused``, or, for another failure (a bad certificate file…), Zenoh's own first line.
    """
    where = ", ".join(endpoints) if not isinstance(endpoints, str) else endpoints
    detail = " ".join(str(exc).split())  # (one line)
    detail = _RUST_LOCATION.sub("", detail)
    if not detail or "Unable to connect" in detail or "Timeout" in detail:
        # Zenoh says the same for a refused handshake as for nobody listening: both are possible.
        return f"no bridge reachable at {where}: not running, or the credentials were refused"
    return f"could not open a zenoh session for {where}: {detail}"
