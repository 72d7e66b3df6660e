"""A Dask scheduler address checked before a Client is made: a wrong one is refused at once.

A Client given an address that names no scheduler of another process still runs its finaliser,
which waits 40 s and prints a traceback; given a port nothing listens on, it retries until its
timeout (20 s) and then says only that it timed out. So the address is parsed first, and its host
and port tried with one TCP connection.
"""

from __future__ import annotations

import socket

from mountcal.core.errors import InputError
from mountcal.core.option_names import option

NETWORK_SCHEMES = ("tcp", "tls", "ws", "wss")
PROBE_S = 3.0  # a TCP connect unanswered this long is left to the Client's own timeout


def check_scheduler_address(address: str) -> None:
    """Refuse an address with no network scheme, host and port; a host that does not resolve; a port
    nothing listens on. A host that does not answer within PROBE_S is left to the Client (a slow
    network, a firewall that drops packets): it tries for its timeout and says so."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme not in NETWORK_SCHEMES:
            raise ValueError(f"the scheme {scheme}:// reaches no scheduler outside this process")
        host, port = parse_host_port(location)
    except ValueError as err:
        raise InputError(
            option("scheduler", address),
            "a Dask scheduler address, tcp://HOST:PORT (or tls://, ws://, wss://)",
            f"not such an address ({err})",
            "Write it as tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786 (the port `dask scheduler` prints).",
        ) from err
    try:
        socket.create_connection((host, port), timeout=PROBE_S).close()
    except (socket.gaierror, ConnectionRefusedError) as err:
        found = "no such host" if isinstance(err, socket.gaierror) else f"nothing listening on port {port}"
        raise InputError(
            option("scheduler", address),
            "a reachable Dask scheduler (tcp://HOST:PORT)",
            f"{found} ({err.strerror or err})",
            "Start one (`dask scheduler`, then `dask worker ADDRESS` on each machine) or check the address.",
        ) from err
    except OSError:  # unanswered or unreachable for now: the Client tries for its timeout and says so
        return
