"""Per-tick time of the QP controller, state in → command out, per solver and mode.

Two passes over the same trajectory for each (solver, mode):

1. clean: only ``ctl.step`` is timed (these are the headline figures);
2. breakdown: the controller's pieces are wrapped with stopwatches from outside —
   ``model.kinematics``, the DM and its gradient (``dm_gradient``), σ_min, the bounds (13)
   (``ctl.bounds``), the ``QpController.build_*`` methods, and the solve: the closed-form
   optimum (``closed_form``) and every ``backend.solve`` — and "other" is the rest of the step
   (the checks of state, reference and command, ẋ_ref, the diagnostics; the wrappers add
   ~1 µs per piece, so this pass is a little slower).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

import wmm_qp as w
import wmm_qp.controllers.base as ctl_base
from wmm_qp.solvers import QPBackend, QPProblem, QPSolution
from wmm_qp_tools.bench.stats import PieceTimer, Summary, now_ns, summarize_ns
from wmm_qp_tools.bench.trajectory import IdealRobot, circle

MODES: tuple[str, ...] = ("hold", "track", "dm_cartesian", "dm_nullspace")
PIECES: tuple[str, ...] = ("kinematics", "dm", "sigma", "bounds", "qp_build", "solve", "other")


def reference_at(mode: w.Mode, x0: np.ndarray, t: float, quat0: np.ndarray | None = None) -> w.Reference:
    """The reference of each mode at time t [s]: the circle, or x0 for HOLD; with ``quat0`` (the
    pose task) the EE also holds that orientation."""
    if mode == w.Mode.HOLD:
        return w.Reference(mode=mode, x_d=x0, xd_d=np.zeros(3), quat_d=quat0)
    x_d, xd_d = circle(x0, t)
    return w.Reference(mode=mode, x_d=x_d, xd_d=xd_d, quat_d=quat0)


class _TimedBackend(QPBackend):
    """A backend whose solve time goes to a :class:`PieceTimer`."""

    def __init__(self, inner: QPBackend, timer: PieceTimer) -> None:
        super().__init__(inner.eps_abs, inner.max_iter)
        self.inner, self.timer = inner, timer

    def solve(self, problem: QPProblem) -> QPSolution:
        t0 = now_ns()
        sol = self.inner.solve(problem)
        self.timer.add("solve", now_ns() - t0)
        return sol

    def reset(self) -> None:
        self.inner.reset()


def _timed(fn: Callable[..., Any], timer: PieceTimer, piece: str) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = now_ns()
        out = fn(*args, **kwargs)
        timer.add(piece, now_ns() - t0)
        return out

    return wrapper


@contextmanager
def instrumented(ctl: w.QpController, timer: PieceTimer) -> Iterator[None]:
    """Wrap the controller's pieces with stopwatches (restored on exit).

    The controller must own its model (the model's ``kinematics`` is wrapped on the instance).
    """
    patched = {
        "dm_gradient": "dm",
        "directional_manipulability": "dm",
        "sigma_min": "sigma",
    }
    saved = {name: getattr(ctl_base, name) for name in patched if hasattr(ctl_base, name)}
    # Whatever stages the controller has: every backend attribute and every build* method.
    backends = {k: v for k, v in vars(ctl).items() if isinstance(v, QPBackend)}
    bounds = ctl.bounds
    builders = [k for k in dir(type(ctl)) if k.startswith("build") and callable(getattr(ctl, k))]
    try:
        for name, fn in saved.items():
            setattr(ctl_base, name, _timed(fn, timer, patched[name]))
        setattr(ctl.model, "kinematics", _timed(ctl.model.kinematics, timer, "kinematics"))  # noqa: B010
        ctl.bounds = _timed(bounds, timer, "bounds")  # type: ignore[assignment]
        setattr(ctl, "closed_form", _timed(ctl.closed_form, timer, "solve"))  # noqa: B010
        for name in builders:
            setattr(ctl, name, _timed(getattr(ctl, name), timer, "qp_build"))
        for name, b in backends.items():
            setattr(ctl, name, _TimedBackend(b, timer))
        yield
    finally:
        for name, fn in saved.items():
            setattr(ctl_base, name, fn)
        for name, b in backends.items():
            setattr(ctl, name, b)
        for name in builders:
            ctl.__dict__.pop(name, None)
        ctl.model.__dict__.pop("kinematics", None)
        ctl.__dict__.pop("closed_form", None)
        ctl.bounds = bounds


def run_case(
    robot: w.RobotConfig,
    cfg: w.ControllerConfig,
    solver: str,
    mode: str,
    ticks: int,
    breakdown: bool = True,
    max_seconds: float = 60.0,
) -> dict[str, Any]:
    """Time ``ticks`` controller steps of one (solver, mode) along the moving reference.

    Args:
        robot: robot config (any robot: the start is its ``arm.start``).
        cfg: controller config (its solver is replaced by ``solver``; its task kind is used).
        solver: backend name.
        mode: a :class:`wmm_qp.Mode` value.
        ticks: number of ticks per pass.
        breakdown: also run the instrumented pass.
        max_seconds: [s] wall-clock budget per pass (the pass stops early; ``n`` says how many).

    Returns:
        {"tick_us": summary, "pieces_us": {piece: summary}, "stages": counts, "status": counts,
        "track_rms_m": RMS of |x − x_d| after the first second, "max_rate_excess": …}.
    """
    m = w.Mode(mode)
    out: dict[str, Any] = {}
    for pass_name in ("clean", "breakdown") if breakdown else ("clean",):
        model = w.WmmModel(robot)
        ctl = w.make_controller("qp", model, cfg.with_(qp={"solver": solver}))
        assert isinstance(ctl, w.QpController)
        ctl.warm_up()  # compiled kernels loaded before timing, as the daemon does
        dt = ctl.dt
        bot = IdealRobot.at_start(model)
        x0 = bot.ee()
        quat0 = bot.ee_quat() if ctl.pose else None
        timer = PieceTimer(PIECES)
        samples: list[int] = []
        stages: dict[str, int] = {}
        status: dict[str, int] = {}
        err2: list[float] = []
        excess = 0.0
        vmax = robot.arm.velocity_max
        wmax = robot.base.wheel_speed_max
        deadline = now_ns() + int(max_seconds * 1e9)
        ctx = instrumented(ctl, timer) if pass_name == "breakdown" else _null()
        with ctx:
            for k in range(ticks):
                ref = reference_at(m, x0, k * dt, quat0)
                state = bot.state()
                t0 = now_ns()
                cmd = ctl.step(state, ref)
                dt_ns = now_ns() - t0
                samples.append(dt_ns)
                bot.apply(cmd, dt)
                if now_ns() > deadline:
                    print(
                        f"  {solver}/{mode}: time budget reached after {k + 1} ticks",
                        file=sys.stderr,
                    )
                    break
                if pass_name == "breakdown":
                    timer.add("other", max(dt_ns - timer.pending(), 0))
                    timer.flush()
                    continue
                stages[ctl.last_stage] = stages.get(ctl.last_stage, 0) + 1
                status[str(cmd.status)] = status.get(str(cmd.status), 0) + 1
                excess = max(
                    excess,
                    float(np.max(np.abs(cmd.arm_rates) - vmax)),
                    float(np.max(np.abs(cmd.wheel_speeds) - wmax, initial=-np.inf)),
                )
                if k * dt >= 1.0 and m != w.Mode.DM_CARTESIAN:
                    x_d = x0 if m == w.Mode.HOLD else circle(x0, (k + 1) * dt)[0]
                    err2.append(float(np.sum((bot.ee() - x_d) ** 2)))
                if k % 5000 == 4999:
                    print(f"  {solver}/{mode}: {k + 1}/{ticks}", file=sys.stderr, flush=True)
        if pass_name == "clean":
            out["tick_us"] = summarize_ns(samples)
            out["stages"] = stages
            out["status"] = status
            out["track_rms_m"] = float(np.sqrt(np.mean(err2))) if err2 else None
            out["max_rate_excess"] = excess
        else:
            out["breakdown_tick_us"] = summarize_ns(samples)
            out["pieces_us"] = timer.summaries()
    return out


@contextmanager
def _null() -> Iterator[None]:
    yield


class CleanCase:
    """The clean pass of :func:`run_case` in blocks: :meth:`run` times the next ``n`` ticks of the
    same trajectory, so that several cases can take turns (the ``robots`` section interleaves its
    cases, so that a slow spell of a shared machine falls on all of them alike)."""

    def __init__(self, robot: w.RobotConfig, cfg: w.ControllerConfig, solver: str, mode: str = "track") -> None:
        self.robot, self.solver, self.mode = robot, solver, w.Mode(mode)
        model = w.WmmModel(robot)
        ctl = w.make_controller("qp", model, cfg.with_(qp={"solver": solver}))
        assert isinstance(ctl, w.QpController)
        ctl.warm_up()  # compiled kernels loaded before timing, as the daemon does
        self.ctl, self.bot = ctl, IdealRobot.at_start(model)
        self.x0 = self.bot.ee()
        self.quat0 = self.bot.ee_quat() if ctl.pose else None
        self.k = 0
        self.samples: list[int] = []
        self.stages: dict[str, int] = {}
        self.status: dict[str, int] = {}
        self.err2: list[float] = []
        self.excess = 0.0

    def run(self, n: int) -> None:
        """The next n ticks."""
        ctl, bot, m, dt = self.ctl, self.bot, self.mode, self.ctl.dt
        vmax, wmax = self.robot.arm.velocity_max, self.robot.base.wheel_speed_max
        for _ in range(n):
            k = self.k
            ref = reference_at(m, self.x0, k * dt, self.quat0)
            state = bot.state()
            t0 = now_ns()
            cmd = ctl.step(state, ref)
            self.samples.append(now_ns() - t0)
            bot.apply(cmd, dt)
            self.stages[ctl.last_stage] = self.stages.get(ctl.last_stage, 0) + 1
            self.status[str(cmd.status)] = self.status.get(str(cmd.status), 0) + 1
            self.excess = max(
                self.excess,
                float(np.max(np.abs(cmd.arm_rates) - vmax)),
                float(np.max(np.abs(cmd.wheel_speeds) - wmax, initial=-np.inf)),
            )
            if k * dt >= 1.0 and m != w.Mode.DM_CARTESIAN:
                x_d = self.x0 if m == w.Mode.HOLD else circle(self.x0, (k + 1) * dt)[0]
                self.err2.append(float(np.sum((bot.ee() - x_d) ** 2)))
            self.k += 1

    def result(self) -> dict[str, Any]:
        """:func:`run_case`'s clean-pass keys."""
        return {
            "tick_us": summarize_ns(self.samples),
            "stages": self.stages,
            "status": self.status,
            "track_rms_m": float(np.sqrt(np.mean(self.err2))) if self.err2 else None,
            "max_rate_excess": self.excess,
        }


def run(
    robot: w.RobotConfig,
    cfg: w.ControllerConfig,
    solvers: list[str],
    modes: list[str],
    ticks: int,
    breakdown: bool = True,
    max_seconds: float = 60.0,
) -> dict[str, dict[str, Any]]:
    """Every (solver, mode) case: {solver: {mode: run_case(...)}}."""
    res: dict[str, dict[str, Any]] = {}
    for s in solvers:
        res[s] = {}
        for mode in modes:
            print(f"controller: {s} / {mode} ({ticks} ticks)", file=sys.stderr, flush=True)
            res[s][mode] = run_case(robot, cfg, s, mode, ticks, breakdown, max_seconds)
    return res


def tick_table(res: dict[str, dict[str, Any]], mode: str = "track") -> dict[str, Summary]:
    """{solver: {p50, p99, max}} of the clean pass in one mode (the --json ``tick_us``)."""
    return {
        s: {k: v for k, v in r[mode]["tick_us"].items() if k in ("p50", "p99", "max")}
        for s, r in res.items()
        if mode in r
    }
