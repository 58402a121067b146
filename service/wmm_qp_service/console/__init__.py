"""The operator's console (``wmm-qp console``): a viser web page, a client of the daemon."""

from .app import Console
from .link import Attached, ConsoleError, RobotLink, robot_description
from .status_text import status_markdown

__all__ = ["Attached", "Console", "ConsoleError", "RobotLink", "robot_description", "status_markdown"]
