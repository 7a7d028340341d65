"""Who may talk to the panel: the per-launch token, the Host allowlist and the Origin check.

The panel can energise a coil, so it is guarded as a Jupyter server is. Pure functions of a
request's headers, so the rules are tested apart from the server:

* **Token**: a random secret per launch. The printed URL carries it once (``?token=``); the page
  then holds it in a cookie named per port (cookies are not scoped by port), and sends it in the
  ``X-Sashil-Token`` header on every request that changes anything (a cookie alone is what a
  cross-site form would carry). The websocket carries it as a subprotocol, since a browser cannot
  set headers on one.
* **Host**: only loopback names and addresses, with the server's own port, are served; a page
  from a rebound DNS name (DNS rebinding) gets 403.
* **Origin**: a state-changing request or a websocket handshake must come from the panel's own
  origin (``http://127.0.0.1:PORT`` or ``http://localhost:PORT``). No CORS headers are ever sent.
"""

from __future__ import annotations

import hmac
import secrets
from collections.abc import Mapping

#: the header a state-changing request carries the token in
TOKEN_HEADER = "x-sashil-token"
#: the websocket's application subprotocol; the token travels as a second one, ``token.<TOKEN>``
SUBPROTOCOL = "sashil-panel.v1"
TOKEN_PROTOCOL_PREFIX = "token."
#: host names a loopback server answers to
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")


def new_token() -> str:
    """A fresh launch token: 24 random bytes as hex (a valid cookie value and subprotocol token)."""
    return secrets.token_hex(24)


def cookie_name(port: int) -> str:
    """The cookie holding the token for the panel on ``port`` (one name per port)."""
    return f"sashil-panel-{port}"


def same_token(given: str | None, token: str) -> bool:
    """``given`` equals ``token`` (compared in constant time)."""
    return given is not None and hmac.compare_digest(given.encode(), token.encode())


def host_allowed(host: str | None, port: int, names: tuple[str, ...] = LOOPBACK_NAMES) -> bool:
    """The Host header names this server: one of ``names`` (by default the loopback names
    ``127.0.0.1``, ``localhost`` and ``[::1]``), with ``:port`` (or without one)."""
    if not host:
        return False
    host = host.strip().lower()
    return any(host == name or host == f"{name}:{port}" for name in names)


def allowed_origins(port: int, names: tuple[str, ...] = LOOPBACK_NAMES, scheme: str = "http") -> tuple[str, ...]:
    """The origins of the panel's own pages."""
    return tuple(f"{scheme}://{name}:{port}" for name in names)


def origin_allowed(
    origin: str | None, port: int, names: tuple[str, ...] = LOOPBACK_NAMES, scheme: str = "http"
) -> bool:
    """``origin`` is the panel's own (a missing Origin is refused: every browser sends one on a
    websocket handshake and on a POST)."""
    return origin is not None and origin.strip().lower() in allowed_origins(port, names, scheme)


def is_loopback(host: str) -> bool:
    """``host`` (an address or name to listen on) is this machine's loopback."""
    import ipaddress

    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def is_wildcard(host: str) -> bool:
    """``host`` is every interface (``0.0.0.0``, ``::``)."""
    import ipaddress

    try:
        return ipaddress.ip_address(host.strip("[]")).is_unspecified
    except ValueError:
        return False


def host_names(host: str) -> tuple[str, ...]:
    """The Host header names a server listening on ``host`` answers to: the loopback names, and
    ``host`` itself when it is another address (an IPv6 one in brackets)."""
    if is_loopback(host):
        return LOOPBACK_NAMES
    name = host.lower()
    return (*LOOPBACK_NAMES, f"[{name}]" if ":" in name and not name.startswith("[") else name)


def subprotocol_token(headers: Mapping[str, str]) -> str | None:
    """The token a websocket handshake offers as ``token.<TOKEN>`` in Sec-WebSocket-Protocol."""
    offered = headers.get("sec-websocket-protocol", "")
    for item in offered.split(","):
        item = item.strip()
        if item.startswith(TOKEN_PROTOCOL_PREFIX):
            return item[len(TOKEN_PROTOCOL_PREFIX) :]
    return None
