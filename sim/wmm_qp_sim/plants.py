"""The plants a simulated robot can drive, by name (``[physics] plant`` in ``configs/sim.toml``).

``kinematic`` is always there; ``mujoco`` needs the ``physics`` extra (``pip install
'wmm-qp[physics]'``). An unknown or uninstalled name is a :class:`PlantNotAvailable` that says what
to install.
"""

from __future__ import annotations

import importlib.util

import wmm_qp
from wmm_qp.exceptions import WmmQpError

from .config import PLANTS, SimConfig
from .kinematic_plant import KinematicPlant
from .plant import Plant

HINTS = {"mujoco": "pip install 'wmm-qp[physics]' (or: pip install mujoco)"}
"""What to install for each optional plant."""


class PlantNotAvailable(WmmQpError):
    """The named plant is unknown or its package is not installed.

    Attributes:
        name: the requested plant.
        available: the plants that can be used here.
    """

    def __init__(self, name: str, available: list[str], hint: str) -> None:
        self.name = name
        self.available = available
        super().__init__(f"plant {name!r} is not available ({hint}); available: {', '.join(available)}")


def available_plants() -> list[str]:
    """The plants whose packages are installed."""
    return [p for p in PLANTS if p == "kinematic" or importlib.util.find_spec(p) is not None]


def make_plant(name: str, model: wmm_qp.WmmModel, config: SimConfig, seed: int,
               scene: wmm_qp.scene.Scene | None = None) -> Plant:
    """The plant called ``name`` for this robot.

    Args:
        name: "kinematic" or "mujoco".
        model: the robot's model.
        config: the sim's config (slip for the kinematic plant, ``physics`` and ``dt`` for MuJoCo).
        seed: the slip noise's seed (kinematic).
        scene: its obstacles become static bodies of the physics plant.

    Raises:
        PlantNotAvailable: unknown name, or its package is not installed.
    """
    if name == "kinematic":
        return KinematicPlant(model, config.slip, seed)
    if name not in available_plants():
        raise PlantNotAvailable(name, available_plants(), HINTS.get(name, f"one of {', '.join(PLANTS)}"))
    from .mujoco_plant import MujocoPlant

    return MujocoPlant(model, config.physics, config.dt, scene.obstacles if scene is not None else ())
