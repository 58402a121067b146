"""The embedded mode: the robot side hosts the daemon's control core in its own process and
thread — each robot cycle reads the state, runs the tick and writes the command, with no
serialisation and no transport between them (ros2_control's read → update → write; libfranka's
control callback).

- :mod:`.link` — :class:`InProcessLink`, the :class:`~..daemon.RobotLink` in memory;
- :mod:`.control` — :class:`EmbeddedControl`, the core and its cycle inside a robot's cycle,
  the slack after the command (inputs, hand-overs); no Zenoh;
- :mod:`.collector` — :class:`SlackCollector`, Python's garbage collector in the slack only;
- :mod:`.timing` — :class:`CycleTiming` (the status's loop figures) and :func:`decimation`;
- :mod:`.service` — :class:`ServiceThread`, the Zenoh side on its own thread (setpoints, modes,
  obstacles, status, telemetry, ``info``, the state for clients, the lease), and
  :func:`embedded_session`;
- :mod:`.sim` — :class:`EmbeddedSim`, ``wmm-qp sim --embedded`` (either plant).

The Franka driver's ``--embedded`` (:mod:`..drivers.franka`) hosts the same control in
libfranka's cycle.
"""

from .collector import SlackCollector
from .control import EmbeddedControl, Telemetry, telemetry_msg
from .link import InProcessLink
from .timing import CycleTiming, decimation

__all__ = ["CycleTiming", "EmbeddedControl", "InProcessLink", "SlackCollector", "Telemetry", "decimation",
           "telemetry_msg"]
