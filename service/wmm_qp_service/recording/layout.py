"""One tick as a row of float64, and the recording's configuration as JSON.

The control thread writes a tick into a row of :class:`Layout` (named slices of a float64 vector:
no allocation, no encoding); the writer process reads the same row. A field that does not apply
to a tick (no state yet, no controller call) is NaN.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

import wmm_qp as w

MODES = tuple(w.Mode)
STATUSES = tuple(w.Status)

SCALARS = ("t_wall", "t", "tick", "seq", "call", "latches", "latency", "tick_us", "step_us", "mode",
           "status", "state_seq", "ee_error", "dm", "sigma_min", "task_error", "alpha", "reason_changed")
"""The row's scalars: [s] wall stamp and time since the loop's start, the tick's index, the sent
command's seq (-1: none went out), the controller call (``ControlCore.ctl_call``), re-latches so
far, [s] bounds (13)'s latency margin, [µs] the tick's work and the controller's step, the mode's
and the command's status's index, the state's seq, [m] the truth's EE error, DM, σ_min, [m/s] the
task error and α of the command, 1 when the command's reason changed."""


class Layout:
    """Where each field of a tick lies in its row, for a robot of ``n_arm`` joints and ``n_wheels``
    wheels.

    Attributes:
        width: the row's length.
        slices: field name → slice of the row.
    """

    def __init__(self, n_arm: int, n_wheels: int) -> None:
        self.n_arm, self.n_wheels = n_arm, n_wheels
        sizes: list[tuple[str, int]] = [(k, 1) for k in SCALARS]
        for prefix in ("meas", "ctl"):  # the measured state; the state handed to the controller
            sizes += [(f"{prefix}_q_base", 3), (f"{prefix}_q_arm", n_arm), (f"{prefix}_v_arm", n_arm),
                      (f"{prefix}_wheels", n_wheels)]
        sizes += [("x_d", 3), ("xd_d", 3), ("direction", 3), ("quat_d", 4), ("omega_d", 3),  # the reference
                  ("cmd_wheels", n_wheels), ("cmd_arm", n_arm), ("cmd_x", 3)]  # the command
        self.slices: dict[str, slice] = {}
        at = 0
        for name, n in sizes:
            self.slices[name] = slice(at, at + n)
            at += n
        self.width = at
        self.index = {k: self.slices[k].start for k in SCALARS}

    def field(self, rows: np.ndarray, name: str) -> np.ndarray:
        """Column(s) ``name`` of ``rows`` (2-D: one row per tick)."""
        return rows[:, self.slices[name]]


def _jsonable(v: Any) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: _jsonable(getattr(v, f.name)) for f in dataclasses.fields(v) if f.name != "path"}
    if isinstance(v, np.ndarray):
        return [_jsonable(float(x)) for x in v.tolist()]
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)  # "inf", "-inf", "nan": JSON has no such numbers
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    if isinstance(v, Path):
        return str(v)
    return v


def config_to_dict(cfg: w.ControllerConfig) -> dict[str, Any]:
    """Every field of the controller config (as the host ran it), JSON-able (±inf as strings)."""
    out = _jsonable(cfg)
    assert isinstance(out, dict)
    return out


def _restore(default: Any, v: Any) -> Any:
    if dataclasses.is_dataclass(default) and not isinstance(default, type) and isinstance(v, dict):
        names = {f.name for f in dataclasses.fields(default)}
        return dataclasses.replace(default, **{k: _restore(getattr(default, k), x) for k, x in v.items()
                                               if k in names and k != "path"})
    if isinstance(v, list) and (isinstance(default, np.ndarray) or default is None):
        a = np.array([float(x) for x in v], dtype=float)
        a.setflags(write=False)
        return a
    if isinstance(v, str) and isinstance(default, float):
        return float(v)
    if isinstance(default, tuple) and isinstance(v, list):
        return tuple(v)
    return v


def config_from_dict(d: dict[str, Any]) -> w.ControllerConfig:
    """The controller config :func:`config_to_dict` wrote (fields it does not know keep the defaults)."""
    cfg = _restore(w.ControllerConfig(), d)
    assert isinstance(cfg, w.ControllerConfig)
    return cfg
