"""Mutant drivers for the contract kit's tests: ``wmm-qp sim`` with exactly one duty of
docs/drivers.md broken, each named after the check of ``wmm-qp contract`` that must catch it.

Run as a process (``python tests/support/contract_mutants.py NAME sim ARGS…``): the module
patches the sim robot node (:mod:`wmm_qp_service.drivers.sim_node`), its firmware
(:mod:`wmm_qp_sim.robot`) or the robot side (:mod:`wmm_qp_robot`) in this process, then runs
``wmm-qp`` with the remaining arguments. Everything else is the reference driver, unchanged.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np


def _obey_without(skip: str) -> Callable[..., Any]:
    """:meth:`LeaseGate.obey` without one of its rules (``lease``, ``instance`` or ``seq``)."""

    def obey(self: Any, msg: Any, referee: Any) -> Any:
        if skip != "lease" and msg.lease != self.holder:
            self.refused["lease"] += 1
            return None
        if skip != "instance" and msg.instance != self.instance:
            self.refused["instance"] += 1
            return None
        if msg.lease != self._holder:
            self._holder, self._holder_seq = msg.lease, -1
            referee.break_stream()
        elif skip != "seq" and msg.seq <= self._holder_seq:
            self.refused["seq"] += 1
            return None
        self._holder_seq = msg.seq
        return msg

    return obey


def _after_init(fix: Callable[[Any], None]) -> None:
    """Run ``fix(robot)`` after every :class:`SimRobot` is built."""
    from wmm_qp_sim.robot import SimRobot

    init = SimRobot.__init__

    def patched(self: Any, *a: Any, **kw: Any) -> None:
        init(self, *a, **kw)
        fix(self)

    SimRobot.__init__ = patched  # type: ignore[method-assign]


def states() -> None:
    """The state's seq stalls (each value twice): not consecutive and increasing."""
    from wmm_qp_service.drivers.sim_node import SimNode

    orig = SimNode.state_msg
    SimNode.state_msg = lambda self, st, seq: orig(self, st, seq // 2)  # type: ignore[method-assign]


def liveliness() -> None:
    """No liveliness token ``alive/robot``."""
    from wmm_qp_service import robot_side

    class NoToken:
        def undeclare(self) -> None:
            pass

    robot_side.alive_token = lambda session, keys: NoToken()  # type: ignore[assignment,return-value]


def lease() -> None:
    """Obeys any sender's lease."""
    from wmm_qp_robot.lease_gate import LeaseGate

    assert hasattr(LeaseGate, "obey")
    LeaseGate.obey = _obey_without("lease")  # type: ignore[method-assign]


def instance() -> None:
    """Obeys commands for any instance."""
    from wmm_qp_robot.lease_gate import LeaseGate

    assert hasattr(LeaseGate, "obey")
    LeaseGate.obey = _obey_without("instance")  # type: ignore[method-assign]


def seq() -> None:
    """Obeys a holder's old and replayed seqs."""
    from wmm_qp_robot.lease_gate import LeaseGate

    assert hasattr(LeaseGate, "obey")
    LeaseGate.obey = _obey_without("seq")  # type: ignore[method-assign]


def invalid() -> None:
    """Decodes commands without validating them (a NaN rate reaches the firmware; its model
    ignores a non-finite command, but the node reports it applied in ``cmd_seq``)."""
    import msgspec
    from wmm_qp_service.drivers.sim_node import SimNode
    from wmm_qp_service.protocol import CommandMsg

    class Lenient:
        def __init__(self) -> None:
            self.rejected: dict[str, int] = {}
            self.dec = msgspec.msgpack.Decoder(CommandMsg)

        def __call__(self, data: bytes) -> Any:
            try:
                return self.dec.decode(data)
            except msgspec.DecodeError:
                return None

        def checked(self, msg: Any) -> Any:
            return msg

    init = SimNode.__init__

    def patched(self: Any, *a: Any, **kw: Any) -> None:
        init(self, *a, **kw)
        self.validate = Lenient()

    SimNode.__init__ = patched  # type: ignore[method-assign]


def refusal_counts() -> None:
    """Refuses as the contract says, but reports only the firmware's counts in ``state.refused``."""
    from wmm_qp_service.drivers import sim_node

    orig = sim_node.state_refused
    sim_node.state_refused = lambda gate, st: {k: v for k, v in orig(gate, st).items()  # type: ignore[assignment]
                                               if k in ("firmware", "ended")}


def ramp() -> None:
    """Executes each commanded rate at once (no acceleration ramp; ``wmm-qp sim --no-ramp``)."""

    def fix(robot: Any) -> None:
        robot.ramp = False

    _after_init(fix)


def stale() -> None:
    """Brakes on stale commands only after 100 ms (the contract: 25 ms)."""

    def fix(robot: Any) -> None:
        robot.config = robot.config.with_(stale_timeout=0.1)

    _after_init(fix)


def stale_stream() -> None:
    """A stale stop forgets the stream it stopped: its late commands resume it."""
    from wmm_qp_sim.robot import SimRobot

    orig = SimRobot.step

    def step(self: Any, command: Any, dt: float) -> Any:
        out = orig(self, command, dt)
        if self.stale and not self.protective:
            self.stopped_stream = None
        return out

    SimRobot.step = step  # type: ignore[method-assign]


def velocity_limit() -> None:
    """No velocity-limit check of the commands (the position-limit check stays)."""

    def fix(robot: Any) -> None:
        robot._v_tol = np.full_like(robot._v_tol, np.inf)

    _after_init(fix)


def position_limit() -> None:
    """No check that a joint can still brake before its position limit."""
    from wmm_qp_sim.robot import SimRobot

    assert hasattr(SimRobot, "_cannot_stop")
    SimRobot._cannot_stop = lambda self, v, dt: -1  # type: ignore[method-assign]


def stopped_stream() -> None:
    """A protective stop forgets the stream it stopped: its commands resume it once at rest."""
    from wmm_qp_sim.robot import SimRobot

    orig = SimRobot.protect

    def stop(self: Any, code: Any, why: str) -> None:
        orig(self, code, why)
        self.stopped_stream = None

    SimRobot.protect = stop  # type: ignore[method-assign]


MUTANTS: dict[str, Callable[[], None]] = {f.__name__: f for f in (
    states, liveliness, lease, instance, seq, invalid, refusal_counts, ramp, stale, stale_stream, velocity_limit,
    position_limit, stopped_stream)}


def main(argv: list[str]) -> int:
    from wmm_qp_service import cli

    if argv == ["--check"]:  # every mutant still finds the code it patches (a refactor renamed nothing)
        for mutant in MUTANTS.values():
            mutant()
        return 0
    MUTANTS[argv[0]]()
    return cli.main(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
