"""Zenoh sessions: peer mode, no multicast scouting, explicit loopback endpoints.

The only module that opens Zenoh sessions. Always use the
session as a context manager (or close it): an open session with a subscriber hangs the
process at exit.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import zenoh

from wmm_qp import ConfigError

from .acl import apply_credentials, check_listen_endpoints, file_endpoints
from .config import ServiceConfig
from .rate_loop import realtime_priority

ROLE_DAEMON = "daemon"
ROLE_SIM = "sim"
ROLE_CLIENT = "client"
ROLE_EMBEDDED = "embedded"


def session_config(cfg: ServiceConfig, role: str) -> zenoh.Config:
    """The Zenoh config of one process.

    The daemon listens on ``daemon_endpoint`` and connects to the sim; the sim listens on
    ``sim_endpoint``; a client listens nowhere and connects to both; a robot side that hosts
    the control core (``embedded``: ``wmm-qp sim --embedded``) is both, and listens on both. Peers retry their
    connects in the background, so the start order does not matter.

    Endpoints listed in the config file are kept: its listen endpoints are added to the
    role's, its connect endpoints replace the role's (``acl_daemon.json5`` reaches the sim
    over the sim's unix socket only). Relative paths (``dictionary_file``, unix sockets,
    ``password: "file:NAME"``) are relative to the config file; credentials are checked
    (:mod:`.acl`).

    Args:
        cfg: service config (base JSON5 file and endpoints).
        role: ``daemon``, ``sim``, ``client`` or ``embedded``.

    Raises:
        ConfigError: the base file is not a valid Zenoh config, a credential file it names is
            missing or holds a placeholder, or it listens where its ACL trusts any peer.
    """
    z = cfg.zenoh
    try:
        zc = zenoh.Config.from_file(str(z.config)) if z.config is not None else zenoh.Config()
    except Exception as e:  # zenoh.ZError: unreadable or not a Zenoh config
        raise ConfigError(z.config or "", "", f"not a valid Zenoh config: {str(e).splitlines()[0][:200]}") from None
    file_listen: list[str] = []
    file_connect: list[str] = []
    if z.config is not None:
        apply_credentials(zc, Path(z.config))
        file_listen, file_connect = file_endpoints(zc, Path(z.config))
    listen: Sequence[str]
    connect: Sequence[str]
    if role == ROLE_DAEMON:
        listen, connect = [z.daemon_endpoint], [z.sim_endpoint]
    elif role == ROLE_SIM:
        listen, connect = [z.sim_endpoint], []
    elif role == ROLE_EMBEDDED:
        listen, connect = [z.daemon_endpoint, z.sim_endpoint], []
    else:
        listen, connect = [], [z.daemon_endpoint, z.sim_endpoint]
    listen = list(dict.fromkeys([*file_listen, *listen]))
    connect = file_connect or connect
    if z.config is not None:
        check_listen_endpoints(zc, Path(z.config), listen)
    zc.insert_json5("mode", json.dumps("peer"))
    zc.insert_json5("scouting/multicast/enabled", "false")
    zc.insert_json5("listen/endpoints", json.dumps(list(listen)))
    zc.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return zc


def open_session(cfg: ServiceConfig, role: str, priority: int = 0) -> zenoh.Session:
    """Open a Zenoh session for ``role`` (see :func:`session_config`).

    ``priority`` > 0: Zenoh's I/O threads run under SCHED_FIFO at that priority (the session
    opens from this thread raised to it, its own scheduling given back after:
    :func:`threads_started_at`); 0: they keep the caller's scheduling. A process
    with a real-time loop gives :func:`io_priority` of the loop's priority.
    """
    zc = session_config(cfg, role)
    with threads_started_at(priority):
        return zenoh.open(zc)


def io_priority(rt_priority: int) -> int:
    """The SCHED_FIFO priority of a real-time process's I/O threads (Zenoh's): one below its
    loop's ``rt_priority`` (at least 1), so the loop preempts them; 0 (normal) when the loop is."""
    return max(rt_priority - 1, 1) if rt_priority > 0 else 0


@contextlib.contextmanager
def threads_started_at(priority: int) -> Iterator[str]:
    """Threads this thread starts inside the block run under SCHED_FIFO ``priority`` (Linux
    threads inherit their creator's scheduling); this thread's own is given back on exit.

    A process whose loop is real-time opens its Zenoh session inside it: Zenoh's I/O threads
    (those the open starts, and those they start later for each link) then carry its states and
    commands at a real-time priority, so a busy host's ordinary processes (a browser rendering
    3-D in software on the same cores) cannot hold them back past the stale timeouts, nor hold the
    GIL while preempted (a thread that takes the GIL from a Zenoh callback would make the loop
    wait for it). Yields what happened, as :func:`realtime_priority` says it.
    """
    if priority <= 0:
        yield "normal scheduling"
        return
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
    except (AttributeError, OSError) as e:  # not Linux
        yield f"normal scheduling ({e})"
        return
    said = realtime_priority(priority)
    try:
        yield said
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, *before)
