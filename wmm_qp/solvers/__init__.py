"""QP backends behind one registry: a solver choice is a config string.

Every backend whose package imports is registered; an unknown or missing one is a
:class:`~wmm_qp.exceptions.SolverNotFound` that says what to install.
"""

from __future__ import annotations

import importlib

from ..exceptions import SolverNotFound
from .base import QPBackend
from .problem import INF, QPProblem, QPSolution

# name → (module, class, pip package)
_BACKENDS: dict[str, tuple[str, str, str]] = {
    "proxsuite": ("proxsuite_backend", "ProxsuiteBackend", "proxsuite"),
    "osqp": ("osqp_backend", "OsqpBackend", "osqp"),
    "daqp": ("daqp_backend", "DaqpBackend", "daqp"),
}
SOLVER_NAMES: tuple[str, ...] = tuple(_BACKENDS)


def _load(name: str) -> type[QPBackend] | None:
    mod, cls, _pkg = _BACKENDS[name]
    try:
        module = importlib.import_module(f"{__name__}.{mod}")
    except ImportError:
        return None
    backend: type[QPBackend] = getattr(module, cls)
    return backend


def available_solvers() -> list[str]:
    """Names of the backends whose packages import here."""
    return [n for n in SOLVER_NAMES if _load(n) is not None]


def make_backend(name: str, eps_abs: float = 1e-9) -> QPBackend:
    """A fresh backend instance (with its own workspace).

    Raises:
        SolverNotFound: unknown name, or its package is not installed (says what to install).
    """
    if name not in _BACKENDS:
        raise SolverNotFound(name, available_solvers(), f"unknown solver; choose one of {', '.join(SOLVER_NAMES)}")
    cls = _load(name)
    if cls is None:
        raise SolverNotFound(name, available_solvers(), f"install it with: pip install {_BACKENDS[name][2]}")
    return cls(eps_abs=eps_abs)


__all__ = ["INF", "SOLVER_NAMES", "QPBackend", "QPProblem", "QPSolution", "available_solvers", "make_backend"]
