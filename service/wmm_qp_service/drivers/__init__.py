"""Drivers: processes that speak the daemon's protocol for a robot's own interface: the simulated
robot's Zenoh node (:mod:`.sim_node`, ``wmm-qp sim``) and a real Franka FR3 (:mod:`.franka`)."""
