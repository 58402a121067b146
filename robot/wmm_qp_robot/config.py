"""Configuration of the robot side every robot shares: the referee's tolerances.

Read from the ``[referee]`` table of ``configs/sim.toml`` (the simulated robot) or given by a
driver (the FR3's, a ROS 2 robot's): the same judge for every robot.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RefereeConfig:
    """Tolerance of the limit referee: legal when ``|v| <= limit·(1 + rtol) + atol``.

    Attributes:
        rtol: [-] relative tolerance (numerical round-off of the controller's bounds).
        atol: absolute tolerance, in the unit of the checked quantity ([rad], [rad/s]).
        collision_distance: [m] a monitored pair (self, floor, obstacles) closer than this counts a
            ``collision`` violation each step (the controller's dampers keep
            ``collision.safety_distance``, 3 cm by default; 0 would count contact only).
        collisions: check collisions every step (self, floor, obstacles: :mod:`.collision`).
    """

    rtol: float = 1e-9
    atol: float = 1e-9
    collision_distance: float = 0.01
    collisions: bool = True
