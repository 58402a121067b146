"""Plots in the spirit of the paper's Figs. 5, 6, 8 and 9 (matplotlib, an optional extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wmm_qp.exceptions import WmmQpError

from .runner import Trace


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


def plot_circle(trace: Trace, out: Path, tag: str) -> list[Path]:
    """Fig. 5 (EE trajectory, tracking error) and Fig. 6 (base trajectory)."""
    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(13, 4))
    ax[0].plot(trace.ee_des[:, 0], trace.ee_des[:, 1], "k--", label="desired")
    ax[0].plot(trace.ee_true[:, 0], trace.ee_true[:, 1], label="true (mocap)")
    ax[0].set(xlabel="x [m]", ylabel="y [m]", title="EE trajectory", aspect="equal")
    ax[0].legend()
    err = (trace.ee_des - trace.ee_true) * 100
    ax[1].plot(trace.t, err[:, 0], label="x")
    ax[1].plot(trace.t, err[:, 1], label="y")
    ax[1].set(xlabel="t [s]", ylabel="error [cm]", title="EE tracking error (ground truth)")
    ax[1].legend()
    ax[2].plot(trace.base_odom[:, 0], trace.base_odom[:, 1], "k--", label="odometry")
    ax[2].plot(trace.base_true[:, 0], trace.base_true[:, 1], label="true")
    ax[2].set(xlabel="x [m]", ylabel="y [m]", title="base trajectory")
    ax[2].legend()
    return [_save(plt, fig, out, "circle", tag)]


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
