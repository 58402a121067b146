"""The robot side every robot shares, whatever its hardware: the seam of ros2_control's hardware
interface and the firmware in front of it.

- :mod:`.hardware`: :class:`~.hardware.HardwareInterface` — ``read()`` the measured state,
  ``write()`` the rates the actuators get; the simulated plants (kinematic, MuJoCo) implement it,
  as does a driver's link to a real robot.
- :mod:`.referee`, :mod:`.collision`: the referees that judge what a robot executes (limits of
  (13), collisions), the same for the sim and a real robot.
- :mod:`.lease_gate`: the lease, instance and seq gate a robot puts in front of its commands.
- :mod:`.shaper`: the jerk-limited command shaper with its stream rules, for a robot that aborts a
  discontinuous velocity stream (the FR3).

Layers: ``wmm_qp`` ← ``wmm_qp_robot`` ← ``wmm_qp_sim`` ← ``wmm_qp_service`` ← ``wmm_qp_tools``.
No module here knows which robot it serves; none imports the sim.
"""
