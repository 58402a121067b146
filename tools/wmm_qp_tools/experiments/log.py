"""The per-tick CSV log of an experiment (``--log FILE.csv``). Units SI, angles in radians.

The columns depend on the robot only through its sizes: one ``q``, ``qd_cmd`` and ``tau`` column
per arm joint (numbered from 1, in the order of the robot file's ``arm.joints``), one
``wheel_cmd`` column per wheel (the base kind's wheel order, docs/robots.md; none for a fixed
base). For the Gen3 on its Mecanum base (7 joints, 4 wheels) these are the columns the log had
when it knew one robot only.
"""

from __future__ import annotations

import csv
from pathlib import Path

from wmm_qp_tools.experiments.trace import Trace


def columns(n_arm: int, n_wheels: int) -> tuple[str, ...]:
    """The log's columns, in order, for a robot with ``n_arm`` joints and ``n_wheels`` wheels."""
    return (
        "t",
        "mode",
        *(f"q{i}" for i in range(1, n_arm + 1)),
        *(f"qd_cmd{i}" for i in range(1, n_arm + 1)),
        *(f"wheel_cmd{i}" for i in range(1, n_wheels + 1)),
        "base_odom_x",
        "base_odom_y",
        "base_odom_yaw",
        "base_true_x",
        "base_true_y",
        "base_true_yaw",
        "ee_des_x",
        "ee_des_y",
        "ee_des_z",
        "ee_true_x",
        "ee_true_y",
        "ee_true_z",
        "dm",
        *(f"tau{i}" for i in range(1, n_arm + 1)),
    )


def write_csv(trace: Trace, path: Path | str) -> None:
    """Write one row per control tick, with a header of :func:`columns` for the trace's sizes."""
    n_arm = trace.q.shape[1] if trace.q.ndim == 2 else 0
    n_wheels = trace.wheel_cmd.shape[1] if trace.wheel_cmd.ndim == 2 else 0
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns(n_arm, n_wheels))
        for k in range(len(trace.t)):
            w.writerow(
                [
                    f"{trace.t[k]:.4f}",
                    trace.mode[k],
                    *(f"{v:.9g}" for v in trace.q[k]),
                    *(f"{v:.9g}" for v in trace.qd_cmd[k]),
                    *(f"{v:.9g}" for v in trace.wheel_cmd[k]),
                    *(f"{v:.9g}" for v in trace.base_odom[k]),
                    *(f"{v:.9g}" for v in trace.base_true[k]),
                    *(f"{v:.9g}" for v in trace.ee_des[k]),
                    *(f"{v:.9g}" for v in trace.ee_true[k]),
                    f"{trace.dm[k]:.9g}",
                    *(f"{v:.9g}" for v in trace.tau[k]),
                ]
            )
