"""``wmm-qp verify``: one step of a controller in every mode for each of many random states, every
command refereed (docs/model.md "`wmm-qp verify`'s report")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .._typing import FloatArray
from ..controllers.base import Controller
from ..model.wmm import WmmModel
from ..scene import Scene
from ..types import Mode, Status
from .collision import CollisionJudge
from .referee import KINDS, check_command
from .sampling import sample_states


@dataclass
class VerifyReport:
    """Violations found by :func:`verify_controller`."""

    samples: int = 0
    steps: int = 0
    violations: int = 0
    by_kind: dict[str, int] = field(default_factory=lambda: dict.fromkeys(KINDS, 0))
    by_mode: dict[str, dict[str, int]] = field(default_factory=dict)
    by_case: dict[str, int] = field(default_factory=dict)
    statuses: dict[str, int] = field(default_factory=dict)
    cut_by: dict[str, int] = field(default_factory=dict)
    """Saturated commands by what cut the task (:func:`cut_kind` of the command's reason)."""
    examples: list[dict[str, object]] = field(default_factory=list)


SATURATION_NOTE = ("saturated is what verify aims at, not a fault: each sample is one tick from a random "
                   "state (at or past a limit, at full speed, near a collision) towards a random target, "
                   "and one tick's acceleration bound (13) changes a rate by a_max*dt only")
"""Why nearly every verify command is ``saturated`` (printed under the statuses)."""


def cut_kind(reason: str) -> str:
    """What cut the task, from a saturated command's reason: its source's label (``collision``,
    ``sigma_min floor``, ...) or ``bounds (13)`` when only the joint bounds did."""
    head = reason.split(":", 1)[0].split(";", 1)[0].strip()
    return "bounds (13)" if not head or head.startswith("the bounds cut") else head


def verify_controller(
    controller: Controller,
    model: WmmModel,
    n: int,
    seed: int,
    progress: Callable[[int, int, int], object] | None = None,
    ee_box: tuple[FloatArray, FloatArray] | None = None,
    scene: Scene | None = None,
) -> VerifyReport:
    """Run one step of ``controller`` for each of n random states in every mode; referee each.

    Args:
        controller: the controller (its ``config`` gives the EE box, the task kind and the safety
            distances).
        model: the robot.
        n: number of random states.
        seed: RNG seed.
        progress: optional callable(i, n, violations) called after each state (violations: so far).
        ee_box: (lower, upper) [m] of eq. (17), refereed in DM_CARTESIAN; default: the controller
            config's (``ee_box_lower``, ``ee_box_upper``).
        scene: obstacles and fence: when given, every command is also refereed for collisions
            (:class:`CollisionJudge`, the safety distances of the controller's ``config.collision``)
            and states near collisions are sampled; the controller is given the scene (the
            baselines have no collision rows: the referee sees them collide).
    """
    rep = VerifyReport(by_mode={m.value: dict.fromkeys(KINDS, 0) for m in Mode})
    cfg = controller.config
    dt = float(controller.dt)
    if ee_box is None:
        ee_box = (cfg.ee_box_lower, cfg.ee_box_upper)
    modes = tuple(Mode)
    params = cfg.collision
    judge = None
    if scene is not None:
        judge = CollisionJudge(model, scene, params.safety_distance, params.floor_margin)
        controller.set_scene(scene)
    samples = sample_states(model, n, seed, modes, pose=cfg.task.kind == "pose", judge=judge,
                            influence=params.influence_distance)
    for k, s in enumerate(samples):
        cmd = controller.step(s.state, s.reference)
        rep.steps += 1
        rep.statuses[cmd.status.value] = rep.statuses.get(cmd.status.value, 0) + 1
        if cmd.status == Status.SATURATED:
            kind = cut_kind(cmd.reason)
            rep.cut_by[kind] = rep.cut_by.get(kind, 0) + 1
        box = ee_box if s.reference.mode == Mode.DM_CARTESIAN else None
        res = check_command(model.config, dt, s.state, cmd, model=model, ee_box=box, collision=judge)
        total = sum(res.values())
        if total:
            rep.violations += total
            rep.by_case[s.case] = rep.by_case.get(s.case, 0) + total
            for kind, c in res.items():
                rep.by_kind[kind] += c
                rep.by_mode[s.reference.mode.value][kind] += c
            if len(rep.examples) < 3:
                ex: dict[str, object] = {"case": s.case, "mode": s.reference.mode.value,
                                         "violations": {k: c for k, c in res.items() if c}}
                if res["collision"] and judge is not None:
                    ex["pair"] = judge.last
                rep.examples.append(ex)
        if (k + 1) % len(modes) == 0:
            rep.samples += 1
            if progress is not None:
                progress(rep.samples, n, rep.violations)
    return rep
