"""The per-tick CSV log of an experiment (``--log FILE.csv``). Units SI, angles in radians."""

from __future__ import annotations

import csv
from pathlib import Path

from .runner import Trace

COLUMNS: tuple[str, ...] = (
    "t",
    "mode",
    *(f"q{i}" for i in range(1, 8)),
    *(f"qd_cmd{i}" for i in range(1, 8)),
    *(f"wheel_cmd{i}" for i in range(1, 5)),
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
    *(f"tau{i}" for i in range(1, 8)),
)
"""The log's columns, in order (issue 5)."""


def write_csv(trace: Trace, path: Path | str) -> None:
    """Write one row per control tick, with a header of :data:`COLUMNS`."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
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
