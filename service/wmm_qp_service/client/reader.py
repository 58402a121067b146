"""The reading half of a client: the robot's streams (state, truth, status, telemetry) and the
daemon's queries (liveliness, ``info``), up to waiting until the daemon is ready.

:class:`~.client.Client` adds the session's lifecycle, the commands and the fault handling.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

import msgspec
import zenoh

from ..config import ServiceConfig
from ..keys import Keys
from ..protocol import InfoMsg, StateMsg, StatusMsg, TelemetryMsg, TruthMsg
from ..readiness import wait_ready


class Reader:
    """What a client reads from one robot's daemon and robot (the base of :class:`~.client.Client`).

    Args:
        svc: the resolved service config (prefix, robot id, endpoints).
        telemetry: also subscribe to per-tick telemetry (see :meth:`telemetry`).
    """

    def __init__(self, svc: ServiceConfig, telemetry: bool = False) -> None:
        self.svc = svc
        self.keys = Keys.of(svc.prefix, svc.robot)
        self._want_telemetry = telemetry
        self.session: zenoh.Session | None = None
        self._last_state: StateMsg | None = None
        self._last_truth: TruthMsg | None = None
        self._last_status: StatusMsg | None = None
        self._status_count = 0  # statuses received
        self._dec_state = msgspec.msgpack.Decoder(StateMsg)
        self._dec_truth = msgspec.msgpack.Decoder(TruthMsg)
        self._dec_status = msgspec.msgpack.Decoder(StatusMsg)
        self._dec_tel = msgspec.msgpack.Decoder(TelemetryMsg)
        self._dec_info = msgspec.msgpack.Decoder(InfoMsg)

    def _declare_subscribers(self, s: zenoh.Session) -> None:
        """Subscribe to the state, truth and status (the newest only) and the telemetry (all of it)."""
        k = self.keys
        self._sub_state = s.declare_subscriber(k.state, zenoh.handlers.RingChannel(1))
        self._sub_truth = s.declare_subscriber(k.sim_truth, zenoh.handlers.RingChannel(1))
        self._sub_status = s.declare_subscriber(k.status, zenoh.handlers.RingChannel(1))
        self._sub_tel = (s.declare_subscriber(k.telemetry, zenoh.handlers.FifoChannel(100_000))
                         if self._want_telemetry else None)

    def _on_status(self, st: StatusMsg) -> None:
        """Called with each new status :meth:`latest_status` decodes (the client's fault bookkeeping)."""

    # ------------------------------------------------------------------ the daemon
    def daemon_alive(self, timeout: float = 0.5) -> bool:
        """The daemon's liveliness token for this robot is present."""
        assert self.session is not None
        replies = self.session.liveliness().get(self.keys.alive("daemon"), timeout=timeout)
        return any(r.ok is not None for r in replies)

    def robots(self, timeout: float = 0.5) -> list[str]:
        """``<prefix>/<robot>`` of every robot whose daemon this session can see (liveliness)."""
        assert self.session is not None
        prefix = self.svc.prefix.strip("/")
        out = set()
        for r in self.session.liveliness().get(f"{prefix}/*/alive/daemon", timeout=timeout):
            if r.ok is not None:
                out.add(str(r.ok.key_expr).removesuffix("/alive/daemon"))
        return sorted(out)

    def no_daemon_reason(self) -> str:
        """Why no daemon answers: "no daemon for robot X" and the robots that are seen."""
        seen = self.robots()
        return (f"no daemon for robot {self.keys.root} (no liveliness token {self.keys.alive('daemon')}); "
                f"daemons seen: {', '.join(seen) if seen else 'none'}")

    def info(self, timeout: float = 2.0) -> InfoMsg | None:
        """Query the daemon's status and configuration (None: no daemon answered)."""
        assert self.session is not None
        for reply in self.session.get(self.keys.info, timeout=timeout):
            if reply.ok is not None:
                try:
                    return self._dec_info.decode(reply.ok.payload.to_bytes())
                except msgspec.DecodeError:
                    return None
        return None

    def wait_for_daemon(self, timeout: float = 10.0) -> InfoMsg | None:
        """Query until the daemon answers (None after ``timeout`` [s]; then
        :meth:`no_daemon_reason` says why). Queries are sent only while the daemon's liveliness
        token is present, so a mistyped robot id costs no query time-outs."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self.daemon_alive(timeout=min(0.5, max(0.05, end - time.monotonic()))):
                time.sleep(0.05)
                continue
            info = self.info(timeout=min(1.0, max(0.1, end - time.monotonic())))
            if info is not None:
                return info
            time.sleep(0.05)
        return None

    def wait_ready(self, timeout: float = 90.0, state_timeout: float | None = None, *,
                   exited: Callable[[], str | None] | None = None,
                   say: Callable[[str], None] | None = None) -> InfoMsg:
        """Wait until the daemon is up and has a valid state from its robot (``status.state_ok``):
        :func:`~..readiness.wait_ready` with this client.

        Args:
            timeout: [s] from the call, for the daemon's liveliness token (a first start compiles
                its kernels, tens of seconds); with ``exited``, for the sim's and the daemon's.
            state_timeout: [s] from then, for its state to be valid (the robot's first states);
                None: within ``timeout``, counted from the call. A query that goes unanswered
                meanwhile is asked again.
            exited: for a program that started the processes (e.g. ``Stack.exited``): the reason
                one of them is gone, None while all run; a process that exits ends the wait at once.
            say: progress (what is being waited for), a few times a second.

        Returns:
            The daemon's info, its status's ``state_ok`` true.

        Raises:
            NotReady: no daemon came up within ``timeout`` (``info`` None; without ``exited`` the
                reason is :meth:`no_daemon_reason`'s), its state was not valid within
                ``state_timeout`` (``info`` its last answer), or (with ``exited``) a process
                exited or did not come up.
        """
        if exited is not None:
            return wait_ready(self, exited, timeout=timeout, state_timeout=state_timeout, robot=self.keys.root,
                              say=say)
        return wait_ready(self, timeout=timeout, state_timeout=state_timeout, robot=self.keys.root,
                          tokens=lambda t: ["daemon"] if self.daemon_alive(t) else [],
                          absent=self.no_daemon_reason, say=say)

    # ------------------------------------------------------------------ the robot's streams
    def latest_state(self) -> StateMsg | None:
        """The robot's most recent state (kept from earlier calls when nothing new arrived)."""
        s = self._sub_state.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_state = self._dec_state.decode(s.payload.to_bytes())
        return self._last_state

    def latest_truth(self) -> TruthMsg | None:
        """The sim's most recent evaluation data (``sim/truth``; None: none yet, or a robot that
        publishes none). Nothing on the control path needs it."""
        s = self._sub_truth.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_truth = self._dec_truth.decode(s.payload.to_bytes())
        return self._last_truth

    def wait_truth(self, timeout: float = 5.0) -> TruthMsg | None:
        """Wait for fresh evaluation data from the sim (None after ``timeout`` [s])."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self._sub_truth.try_recv()
            if s is not None:
                with contextlib.suppress(msgspec.DecodeError):
                    self._last_truth = self._dec_truth.decode(s.payload.to_bytes())
                    return self._last_truth
            time.sleep(0.005)
        return None

    def latest_status(self) -> StatusMsg | None:
        """The daemon's most recent published status (it also feeds the fault bookkeeping:
        :attr:`~.client.Client.fault_active`, ``on_fault``)."""
        s = self._sub_status.try_recv()
        if s is not None:
            with contextlib.suppress(msgspec.DecodeError):
                self._last_status = st = self._dec_status.decode(s.payload.to_bytes())
                self._status_count += 1
                self._on_status(st)
        return self._last_status

    def wait_state(self, timeout: float = 5.0) -> StateMsg | None:
        """Wait for a fresh state from the sim (None after ``timeout`` [s])."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self._sub_state.try_recv()
            if s is not None:
                try:
                    self._last_state = self._dec_state.decode(s.payload.to_bytes())
                    return self._last_state
                except msgspec.DecodeError:
                    pass
            time.sleep(0.005)
        return None

    def telemetry(self) -> list[TelemetryMsg]:
        """Every telemetry message received since the last call (needs ``telemetry=True``)."""
        out: list[TelemetryMsg] = []
        if self._sub_tel is None:
            return out
        while (s := self._sub_tel.try_recv()) is not None:
            with contextlib.suppress(msgspec.DecodeError):
                out.append(self._dec_tel.decode(s.payload.to_bytes()))
        return out

    def alive(self, timeout: float = 1.0) -> list[str]:
        """Names of the live nodes of this robot (daemon, sim, clients)."""
        assert self.session is not None
        names = []
        for reply in self.session.liveliness().get(self.keys.alive_all, timeout=timeout):
            if reply.ok is not None:
                names.append(str(reply.ok.key_expr).rsplit("/", 1)[-1])
        return sorted(names)
