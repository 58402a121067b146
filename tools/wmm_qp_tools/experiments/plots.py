"""Plots in the spirit of the paper's Figs. 5, 6, 8 and 9 (matplotlib, an optional extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wmm_qp.exceptions import WmmQpError
from wmm_qp_tools.experiments.trace import Trace


def _plt() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise WmmQpError("--plots needs matplotlib: pip install 'wmm-qp[plots]'") from None
    return plt


def _save(plt: Any, fig: Any, out: Path, name: str, tag: str) -> Path:
    """Title, lay out, write ``<out>/<name>_<tag>.png`` and close the figure."""
    fig.suptitle(f"{name} — {tag}")
    fig.tight_layout()
    path = out / f"{name}_{tag}.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def plot_circle(trace: Trace, out: Path, tag: str, moving: float = 1e-4) -> list[Path]:
    """Fig. 5 (a: EE trajectory, b: tracking error) and Fig. 6 (a: base position over time, the
    ticks whose commanded base twist exceeds ``moving`` shaded; b: base trajectory in x–y)."""
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    a = ax.ravel()
    a[0].plot(trace.ee_des[:, 0], trace.ee_des[:, 1], "k--", label="desired")
    a[0].plot(trace.ee_true[:, 0], trace.ee_true[:, 1], label="true (mocap)")
    a[0].set(xlabel="x [m]", ylabel="y [m]", title="Fig. 5a: EE trajectory", aspect="equal")
    a[0].legend(fontsize=8)
    err = (trace.ee_des - trace.ee_true) * 100
    a[1].plot(trace.t, err[:, 0], label="x")
    a[1].plot(trace.t, err[:, 1], label="y")
    a[1].set(xlabel="t [s]", ylabel="error [cm]", title="Fig. 5b: EE tracking error (ground truth)")
    a[1].legend(fontsize=8)
    a[2].plot(trace.t, trace.base_true[:, 0], label="x (true)")
    a[2].plot(trace.t, trace.base_true[:, 1], label="y (true)")
    a[2].plot(trace.t, trace.base_odom[:, 0], "k:", lw=0.8, label="x, y (odometry)")
    a[2].plot(trace.t, trace.base_odom[:, 1], "k:", lw=0.8)
    on = np.abs(trace.base_twist_cmd).max(axis=1) > moving
    if on.any():
        a[2].fill_between(trace.t, 0, 1, where=on, color="0.85", transform=a[2].get_xaxis_transform(),
                          label="base commanded to move")
    a[2].set(xlabel="t [s]", ylabel="[m]", title="Fig. 6a: base position")
    a[2].legend(fontsize=8)
    a[3].plot(trace.base_odom[:, 0], trace.base_odom[:, 1], "k--", label="odometry")
    a[3].plot(trace.base_true[:, 0], trace.base_true[:, 1], label="true")
    a[3].set(xlabel="x [m]", ylabel="y [m]", title="Fig. 6b: base trajectory")
    a[3].legend(fontsize=8)
    return [_save(plt, fig, out, "circle", tag)]


def plot_circle_comparison(traces: dict[str, Trace], out: Path, tag: str) -> list[Path]:
    """Table I as curves: commanded base twist (v_x, v_y, θ̇) and the EE error norm of several
    runs of one circle (e.g. every controller), one line per run."""
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(11, 7))
    a = ax.ravel()
    for name, tr in traces.items():
        for i, (label, unit) in enumerate((("v_xb", "cm/s"), ("v_yb", "cm/s"), ("θ̇_b", "rad/s"))):
            scale = 100.0 if i < 2 else 1.0
            a[i].plot(tr.t, tr.base_twist_cmd[:, i] * scale, lw=0.9, label=name)
            a[i].set(xlabel="t [s]", ylabel=f"{label} [{unit}]", title=f"commanded {label}")
        a[3].plot(tr.t, np.linalg.norm(tr.ee_des[:, :2] - tr.ee_true[:, :2], axis=1) * 100, lw=0.9, label=name)
    a[3].set(xlabel="t [s]", ylabel="[cm]", title="EE error in x-y (ground truth)")
    for x in a:
        x.legend(fontsize=7)
    return [_save(plt, fig, out, "circle_compare", tag)]


def plot_dm(trace: Trace, out: Path, tag: str) -> list[Path]:
    """Fig. 9a: DM over time, and the EE height."""
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(trace.t, trace.dm)
    ax[0].set(xlabel="t [s]", ylabel="H2", title="directional manipulability")
    ax[1].plot(trace.t, trace.ee_true[:, 2])
    ax[1].set(xlabel="t [s]", ylabel="z [m]", title="EE height (true)")
    return [_save(plt, fig, out, "dm", tag)]


def plot_push(
    runs: dict[str, tuple[Trace, int]], W: np.ndarray, limits: np.ndarray, out: Path, tag: str
) -> list[Path]:
    """Fig. 8 (joint torques) and Fig. 9b (weighted torque norm), with and without DM."""
    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for k, (name, (tr, i0)) in enumerate(runs.items()):
        t = tr.t[i0:] - tr.t[i0]
        for j in range(tr.tau.shape[1]):  # one line per joint of the robot
            ax[k].plot(t, tr.tau[i0:, j], label=f"τ{j + 1}")
        ax[k].axhline(limits[0], color="r", ls=":", lw=0.8)
        ax[k].axhline(limits[-1], color="m", ls=":", lw=0.8)
        ax[k].set(xlabel="push time [s]", ylabel="τ [N·m]", title=f"joint torques, {name}")
        ax[2].plot(t, np.linalg.norm(tr.tau[i0:] * W, axis=1), label=name)
        ax[2].plot(t, tr.box_displacement[i0:] * 100, "--", label=f"box [cm], {name}")
    ax[0].legend(fontsize=7, ncol=2)
    ax[2].set(xlabel="push time [s]", title="‖W τ‖ [N·m], box displacement [cm]")
    ax[2].legend(fontsize=7)
    return [_save(plt, fig, out, "push", tag)]
