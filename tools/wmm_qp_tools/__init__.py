"""wmm-qp's tools, apart from the runtime: benchmarks (``wmm-qp bench``), the paper's experiments
(``wmm-qp experiment``), the stress, fuzz and fault drills, and the driver contract kit.

Layers, lowest first: ``wmm_qp`` ← ``wmm_qp_sim`` ← ``wmm_qp_service`` ← ``wmm_qp_tools``: a robot
process (``wmm-qp sim``, ``serve``, ``driver``) never imports this package.
"""
