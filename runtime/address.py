"""ZeroMQ endpoint validation, before any socket exists: a malformed address is refused in one line
instead of hanging in a connect that can never succeed (``http://...``, or ``tcp://HOST`` without a port).
Used by the commands that take ``--sim``/``--bind``; client and server can call it too."""

from __future__ import annotations

import re

EXAMPLE = "tcp://127.0.0.1:5555"
_TCP = re.compile(r"^tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\s]+):(?P<port>[^:/\s]+)$")


def check_endpoint(endpoint: str, bind: bool = False) -> str:
    """``endpoint`` unchanged if ZeroMQ can use it, else ValueError naming the problem and the fix.

    Accepted: ``tcp://HOST:PORT`` (PORT 1..65535; ``*`` for any free port when binding), ``ipc://PATH``
    and ``inproc://NAME``.
    """
    if not isinstance(endpoint, str) or "://" not in endpoint:
        raise ValueError(f"address {endpoint!r} has no transport; use one like {EXAMPLE}")
    scheme, rest = endpoint.split("://", 1)
    if scheme in ("ipc", "inproc"):
        if not rest:
            raise ValueError(f"address {endpoint!r} names no {scheme} endpoint; e.g. {scheme}://vtr-sim")
        return endpoint
    if scheme != "tcp":
        raise ValueError(
            f"address {endpoint!r} uses {scheme}://, which ZeroMQ does not speak; use one like {EXAMPLE}"
        )
    match = _TCP.match(endpoint)
    if match is None:
        raise ValueError(f"address {endpoint!r} has no port; use tcp://HOST:PORT, e.g. {EXAMPLE}")
    port = match["port"]
    if port == "*" and bind:
        return endpoint
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        hint = " (or * to pick a free one)" if bind else ""
        raise ValueError(f"address {endpoint!r}: port must be a number in 1..65535{hint}")
    return endpoint
