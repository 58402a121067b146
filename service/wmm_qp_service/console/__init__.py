"""The operator's console (``wmm-qp console``): a viser web page, a client of the daemon."""

from .app import Console, status_markdown
from .link import Attached, ConsoleError, RobotLink, robot_description

__all__ = ["Attached", "Console", "ConsoleError", "RobotLink", "robot_description", "status_markdown"]
