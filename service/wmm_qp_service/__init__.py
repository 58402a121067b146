"""wmm-qp's service: the control daemon, its Zenoh transport and protocol, and the CLI.

This package is the only one that imports zenoh (the sim's Zenoh node is its driver
``drivers/sim_node.py``); it may import ``wmm_qp_sim`` and ``wmm_qp``, never the reverse
(``tools/check_layers.py``).
"""
