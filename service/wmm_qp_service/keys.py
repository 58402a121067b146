"""Key expressions of one robot: everything lives under ``<prefix>/<robot>/``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Keys:
    """The key expressions of one robot (see docs/protocol.md).

    Attributes:
        root: ``<prefix>/<robot>``.
    """

    root: str

    @classmethod
    def of(cls, prefix: str, robot: str) -> Keys:
        """Keys for ``robot`` under ``prefix``."""
        return cls(f"{prefix.strip('/')}/{robot}")

    @property
    def state(self) -> str:
        """sim → daemon: measured robot state (:class:`~.protocol.StateMsg`), sim rate."""
        return f"{self.root}/state"

    @property
    def cmd(self) -> str:
        """daemon → sim: wheel speed and joint rate command (:class:`~.protocol.CommandMsg`)."""
        return f"{self.root}/cmd"

    @property
    def setpoint(self) -> str:
        """client → daemon: EE setpoint stream (:class:`~.protocol.SetpointMsg`)."""
        return f"{self.root}/setpoint"

    @property
    def mode(self) -> str:
        """client → daemon: mode change (:class:`~.protocol.ModeMsg`), never dropped."""
        return f"{self.root}/mode"

    @property
    def sim_box(self) -> str:
        """client → sim: place a box now (:class:`~.protocol.BoxMsg`), never dropped."""
        return f"{self.root}/sim/box"

    @property
    def sim_truth(self) -> str:
        """sim (or a driver's referee) → observers: evaluation data (:class:`~.protocol.TruthMsg`),
        with each state; nothing on the control path needs it."""
        return f"{self.root}/sim/truth"

    @property
    def gripper(self) -> str:
        """client → robot: a gripper command (:class:`~.protocol.GripperMsg`), never dropped."""
        return f"{self.root}/gripper"

    @property
    def obstacles(self) -> str:
        """client → daemon and sim: the live obstacles (:class:`~.protocol.ObstaclesMsg`), latest wins."""
        return f"{self.root}/obstacles"

    @property
    def status(self) -> str:
        """daemon → all: status (:class:`~.protocol.StatusMsg`), ~10 Hz."""
        return f"{self.root}/status"

    @property
    def telemetry(self) -> str:
        """daemon → all: per-tick telemetry (:class:`~.protocol.TelemetryMsg`)."""
        return f"{self.root}/telemetry"

    @property
    def info(self) -> str:
        """Queryable of the daemon: replies an :class:`~.protocol.InfoMsg` (status + config)."""
        return f"{self.root}/info"

    def alive(self, node: str) -> str:
        """Liveliness token of one process (``daemon``, ``sim`` or a client name)."""
        return f"{self.root}/alive/{node}"

    def lease(self, holder: str) -> str:
        """Liveliness token of the control lease held by ``holder`` (a daemon's id)."""
        return f"{self.root}/lease/{holder}"

    @property
    def lease_all(self) -> str:
        """Every control-lease token of this robot (at most one daemon should hold one)."""
        return f"{self.root}/lease/*"

    @property
    def alive_all(self) -> str:
        """Every liveliness token of this robot."""
        return f"{self.root}/alive/*"
