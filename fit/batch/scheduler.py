"""The address of a running dask scheduler (``rbrdf-fit batch --scheduler``): checked before
anything is read (:func:`check_address`), then reached within a few seconds (:func:`connect`).

Accepted: ``[SCHEME://]HOST:PORT`` with ``SCHEME`` one of :data:`SCHEMES` (``tcp`` when
omitted, as dask reads it; ``tls`` needs dask's TLS configuration), ``HOST`` a host name, an
IPv4 address or a bracketed IPv6 address, ``PORT`` in 1-65535. Refused in one line naming
``--scheduler``: ``http(s)://`` (the dashboard's address, not the scheduler's), ``inproc://``
(only within one process), ``ucx://`` and other schemes, a missing or bad host or port.

Connecting: a plain socket first reaches ``HOST:PORT`` within ``timeout_s`` (default
:data:`CONNECT_TIMEOUT_S`), so the error says why it cannot -- the name does not resolve,
the connection is refused (nothing listens there), no answer within the timeout (host down,
unroutable or filtered), network or host unreachable; then dask's handshake must finish
within the same timeout (a port that accepts and never answers as a scheduler is "no dask
scheduler answered": ``distributed.Client`` alone would wait for it without end). Every
failure is one :class:`fit.errors.FlagError` naming ``--scheduler``, the address and the cause.
"""
from __future__ import annotations

import errno
import ipaddress
import re
import socket
import threading

from ..errors import FlagError, display_text

#: dask.distributed schemes of a scheduler on the network that the batch connects to.
SCHEMES = ("tcp", "tls", "ws", "wss")
#: Seconds to reach the scheduler (socket, then dask's handshake), each.
CONNECT_TIMEOUT_S = 5.0
MAX_ADDRESS_CHARS = 300

_LABEL = r"[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?"
_HOSTNAME = re.compile(rf"{_LABEL}(?:\.{_LABEL})*\.?")


def _bad(address: str, problem: str) -> FlagError:
    return FlagError("--scheduler", f"{display_text(address)[:MAX_ADDRESS_CHARS]!r}: {problem}")


def check_address(address) -> tuple:
    """``(scheme, host, port)`` of the scheduler address ``address`` (see the module's
    docstring); a one-line :class:`FlagError` naming ``--scheduler`` otherwise. Contacts
    nothing."""
    if not isinstance(address, str) or not address.strip():
        raise FlagError("--scheduler", "empty address; expected tcp://HOST:PORT")
    if len(address) > MAX_ADDRESS_CHARS:
        raise FlagError("--scheduler", f"address of {len(address)} characters, at most {MAX_ADDRESS_CHARS}")
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    scheme = scheme.lower()
    if scheme in ("http", "https"):
        raise _bad(address, f"{scheme}:// is a web address (the dashboard's?), not a scheduler's; "
                               "expected tcp://HOST:PORT (dask's default port is 8786)")
    if scheme == "inproc":
        raise _bad(address, "inproc:// reaches a scheduler inside the same process only; expected tcp://HOST:PORT")
    if scheme not in SCHEMES:
        raise _bad(address, f"unknown scheme {display_text(scheme)[:20]!r}; expected one of "
                               f"{', '.join(s + '://' for s in SCHEMES)} and HOST:PORT")
    if rest.startswith("["):
        host, close, tail = rest[1:].partition("]")
        if not close or not tail.startswith(":"):
            raise _bad(address, "expected [IPv6]:PORT")
        port_text = tail[1:]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise _bad(address, f"{display_text(host)[:60]!r} is not an IPv6 address")
    else:
        host, colon, port_text = rest.rpartition(":")
        if not colon:
            raise _bad(address, "no port; expected HOST:PORT (dask's default port is 8786)")
        if not host or not _HOSTNAME.fullmatch(host):
            raise _bad(address, f"{display_text(host)[:60]!r} is not a host name or IP address")
    if not port_text.isascii() or not port_text.isdigit() or len(port_text) > 5 or not 1 <= int(port_text) <= 65535:
        raise _bad(address, f"port {display_text(port_text)[:20]!r} is not an integer in 1-65535")
    return scheme, host, int(port_text)


def _resolve(host: str, port: int, timeout_s: float) -> tuple:
    """The first TCP socket address of ``host:port``, resolved within ``timeout_s`` (a
    resolver that does not answer is not waited on)."""
    box = {}

    def work():
        try:
            box["info"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as e:
            box["error"] = e

    t = threading.Thread(target=work, daemon=True, name="rbrdf-resolve")
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        raise TimeoutError(f"cannot resolve host {host!r} within {timeout_s:g} s")
    if "error" in box:
        raise box["error"]
    family, _, _, _, sockaddr = box["info"][0]
    return family, sockaddr


def _cause(e: OSError, port: int, timeout_s: float) -> str:
    if isinstance(e, socket.gaierror):
        return f"host name does not resolve ({e.strerror or e})"
    if isinstance(e, ConnectionRefusedError):
        return f"connection refused (nothing listens on port {port})"
    if isinstance(e, TimeoutError):       # socket.timeout too; or the resolver's own (its text says so)
        return str(e) if "resolve" in str(e) else (f"timed out: no answer within {timeout_s:g} s "
                                                   "(host down, unroutable or filtered)")
    if e.errno == errno.ENETUNREACH:
        return "network unreachable"
    if e.errno == errno.EHOSTUNREACH:
        return "host unreachable"
    return e.strerror or str(e)


def probe(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Open and close a plain connection to the scheduler's ``HOST:PORT`` within ``timeout_s``;
    :class:`FlagError` naming the address and why it cannot be reached."""
    _, host, port = check_address(address)
    try:
        family, sockaddr = _resolve(host, port, timeout_s)
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.settimeout(timeout_s)
            s.connect(sockaddr)
    except OSError as e:
        raise FlagError("--scheduler", f"cannot connect to {display_text(address)}: "
                                       f"{_cause(e, port, timeout_s)}") from None


def handshake(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """dask's own handshake with the scheduler at ``address``, within ``timeout_s`` in all
    (``distributed.Client`` waits without end for the answer of a port that accepts and never
    speaks). Runs in a thread of its own, so that it works under a running event loop too;
    :class:`FlagError` naming the address when no dask scheduler answers."""
    import asyncio

    from distributed.comm import connect as comm_connect
    from distributed.security import Security

    box = {}

    async def go():
        comm = await asyncio.wait_for(comm_connect(address, timeout=timeout_s,
                                                   **Security().get_connection_args("client")), timeout_s)
        await comm.close()

    def work():
        try:
            asyncio.run(go())
        except BaseException as e:     # noqa: BLE001 - reported by the caller
            box["error"] = e

    t = threading.Thread(target=work, daemon=True, name="rbrdf-scheduler-handshake")
    t.start()
    t.join(timeout_s + 1.0)
    e = box.get("error")
    if t.is_alive() or isinstance(e, (TimeoutError, asyncio.TimeoutError)):
        raise FlagError("--scheduler", f"cannot connect to {display_text(address)}: no dask scheduler answered "
                                       f"within {timeout_s:g} s (something listens there, but does not speak dask)")
    if e is not None:
        raise FlagError("--scheduler", f"cannot connect to {display_text(address)}: "
                                       f"{display_text(f'{type(e).__name__}: {e}')[:200]}")


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S):
    """A ``distributed.Client`` of the scheduler at ``address``: checked, reached with a plain
    socket (:func:`probe`), dask's handshake (:func:`handshake`), each within ``timeout_s``;
    :class:`FlagError` naming the address and the cause."""
    from distributed import Client

    probe(address, timeout_s)
    handshake(address, timeout_s)
    try:
        return Client(address, timeout=timeout_s)
    except (OSError, TimeoutError) as e:
        raise FlagError("--scheduler", f"cannot connect to {display_text(address)}: no dask scheduler "
                                       f"answered within {timeout_s:g} s ({display_text(str(e))[:200]})") from None
    except ValueError as e:           # dask's own address checks (should be unreachable after check_address)
        raise _bad(address, display_text(str(e))[:200]) from None
