"""No base: the arm alone (its root fixed in the world). The base block of J (5) is empty."""

from __future__ import annotations

import numpy as np

from ...config import BaseConfig
from .base import Base


class FixedBase(Base):
    """A base that does not move: no wheels, M is 3 × 0."""

    kind = "fixed"
    wheel_names = ()

    def __init__(self, config: BaseConfig) -> None:
        super().__init__(config, np.zeros((3, 0)))
