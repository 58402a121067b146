"""Errors raised by wmm_qp.

One root class, subclasses that carry the offending values. Nothing here is ever raised
out of a controller's ``step``: the control loop turns every failure into a safe stop and
a reason (see :mod:`wmm_qp.controllers.base`). These errors are for start-up (configs,
solver choice) and for the library's direct callers.
"""

from __future__ import annotations

from pathlib import Path


class WmmQpError(Exception):
    """Root of every error raised by wmm_qp."""


class ConfigError(WmmQpError):
    """A config file is missing, malformed or holds an invalid value.

    Attributes:
        path: the file.
        key: the dotted key that is wrong ("" for the whole file).
        reason: what is wrong with it.
    """

    def __init__(self, path: Path | str, key: str, reason: str) -> None:
        self.path = Path(path)
        self.key = key
        self.reason = reason
        where = f"{self.path}: {key}" if key else f"{self.path}"
        super().__init__(f"{where}: {reason}")


class SolverNotFound(WmmQpError):
    """The configured QP solver is unknown or its package is not installed.

    Attributes:
        name: the requested solver.
        available: names of the solvers that can be used here.
        hint: what to install.
    """

    def __init__(self, name: str, available: list[str], hint: str) -> None:
        self.name = name
        self.available = available
        self.hint = hint
        super().__init__(f"QP solver {name!r} is not available ({hint}); available: {', '.join(available) or 'none'}")


class SolverFailed(WmmQpError):
    """A QP backend did not return a usable solution.

    Attributes:
        solver: backend name.
        status: the backend's own status string.
    """

    def __init__(self, solver: str, status: str) -> None:
        self.solver = solver
        self.status = status
        super().__init__(f"{solver}: {status}")


class InvalidInput(WmmQpError):
    """A state or reference handed to the library is malformed.

    Attributes:
        field: the offending field.
        reason: what is wrong with it.
    """

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")
