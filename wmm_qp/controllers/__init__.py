"""Controllers behind one entry point ``step(state, reference) → command``."""

from __future__ import annotations

from ..config import CONTROLLER_KINDS, ControllerConfig
from ..model.wmm import WmmModel
from .base import Controller
from .paper import PaperController
from .qp import QpController
from .traditional import TraditionalController

__all__ = [
    "CONTROLLER_KINDS",
    "Controller",
    "PaperController",
    "QpController",
    "TraditionalController",
    "make_controller",
]


def make_controller(kind: str, model: WmmModel, config: ControllerConfig) -> Controller:
    """The controller named ``kind`` ("qp", "paper" or "traditional").

    Raises:
        ValueError: unknown kind.
        SolverNotFound: kind "qp" with a solver that cannot be used here.
    """
    classes: dict[str, type[Controller]] = {
        "qp": QpController,
        "paper": PaperController,
        "traditional": TraditionalController,
    }
    if kind not in classes:
        raise ValueError(f"unknown controller {kind!r}; choose one of {', '.join(CONTROLLER_KINDS)}")
    return classes[kind](model, config)
