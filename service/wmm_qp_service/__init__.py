"""wmm-qp's service: the control daemon, its Zenoh transport and protocol, and the CLI.

This package and the sim's adapter are the only places that import zenoh.
"""
