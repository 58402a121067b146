"""Constraint-satisfaction referee and random state sampler (``wmm-qp verify``): the rules
(:mod:`.referee`, the collisions' :mod:`.collision`), the states (:mod:`.sampling`) and the run
(:mod:`.run`)."""

from .collision import COLLISION_TOL, CollisionJudge
from .referee import KINDS, TOL, check_command, check_ee_box
from .run import SATURATION_NOTE, VerifyReport, cut_kind, verify_controller
from .sampling import Sample, sample_states

__all__ = [
    "COLLISION_TOL",
    "KINDS",
    "SATURATION_NOTE",
    "TOL",
    "CollisionJudge",
    "Sample",
    "VerifyReport",
    "check_command",
    "check_ee_box",
    "cut_kind",
    "sample_states",
    "verify_controller",
]
