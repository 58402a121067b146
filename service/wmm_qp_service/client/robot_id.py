"""Which robot id a client talks to, from a robot file or an id."""

from __future__ import annotations

from pathlib import Path

from wmm_qp import ConfigError
from wmm_qp.config import read_toml

from ..config import ServiceConfig, check_name, load_service_config


def robot_id(robot: str | Path, svc: ServiceConfig | None = None) -> str:
    """The robot id of a robot file or of an id: a path (a :class:`~pathlib.Path`, or a string
    ending in ``.toml``) gives the file's ``name`` (read without resolving its URDF; a file
    without ``name`` gives ``svc``'s robot id), any other string is the id itself.

    Raises:
        ConfigError: the file is unreadable, or the name is not a key segment.
    """
    if isinstance(robot, Path) or robot.endswith(".toml"):
        path = Path(robot)
        name = read_toml(path).get("name")
        if name is None:
            return (svc or load_service_config()).resolved().robot
        if not isinstance(name, str):
            raise ConfigError(path, "name", f"must be a string, got {name!r}")
        try:
            return check_name(name, "name")
        except ConfigError:
            raise ConfigError(path, "name", f"must be a key segment (letters, digits, _ -), got {name!r}") from None
    return check_name(robot, "robot")
