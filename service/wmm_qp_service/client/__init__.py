"""A small client API for the daemon: send setpoints and mode changes, read status and state,
wait until the daemon is ready, notice faults and resume after them.

Example::

    from wmm_qp_service.client import Client

    with Client.for_robot("configs/robots/ur5_omni.toml") as c:   # or Client(robot="ur5_omni")
        info = c.wait_ready(timeout=60.0)            # the daemon answers with a valid state (else NotReady)
        c.set_mode("track")
        if not c.send_setpoint([0.65, 0.0, 0.49]):   # False: the daemon does not follow setpoints
            c.resume("track")                        # after a fault: resume deliberately
        print(c.info().status.loop)                  # query: status + config
        st = c.latest_state()                        # the sim's last state (or None)
        tr = c.latest_truth()                        # the sim's last ground truth, referee (or None)

:class:`Client` (:mod:`.client`) is a :class:`~.reader.Reader` (the streams and the daemon's
queries) that also commands; :func:`robot_id` (:mod:`.robot_id`) says which robot it talks to;
:class:`NotReady` is the wait's one failure (:mod:`..readiness`, the wait itself).
"""

from ..readiness import NotReady
from .client import FOLLOWING, Client
from .reader import Reader
from .robot_id import robot_id

__all__ = ["FOLLOWING", "Client", "NotReady", "Reader", "robot_id"]
