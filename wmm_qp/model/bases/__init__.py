"""The base kinds, one file each, behind one interface (:class:`Base`): P(q_b) of eq. (3)."""

from ...config import BaseConfig
from .base import Base
from .diff_drive import DiffDriveBase
from .fixed import FixedBase
from .mecanum import MecanumBase
from .omni import OmniBase

BASES: dict[str, type[Base]] = {
    "mecanum": MecanumBase,
    "omni": OmniBase,
    "diff_drive": DiffDriveBase,
    "fixed": FixedBase,
}


def make_base(config: BaseConfig) -> Base:
    """The base of ``config.kind``."""
    return BASES[config.kind](config)  # type: ignore[call-arg]  # each kind builds its own M


__all__ = ["BASES", "Base", "DiffDriveBase", "FixedBase", "MecanumBase", "OmniBase", "make_base"]
