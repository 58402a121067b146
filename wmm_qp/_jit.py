"""The compiled kernels of the hot path: numba's ``njit`` with the settings they all share.

Every tick runs a handful of small kernels (bounds (13), the kinematics assembly of eqs. (2)
and (5), the DM of eqs. (8)–(9), σ_min and the closed-form QP optimum). Written as numpy
expressions each costs tens of ~0.5 µs numpy calls; compiled, one call of ~0.3–1 µs.

* ``cache=True``: compiled once per machine (into ``__pycache__``, or numba's user cache
  when the package folder is read-only), loaded in ~ms afterwards;
* ``error_model="numpy"``: a division by zero gives inf/NaN like numpy, never an exception
  (the callers' checks turn non-finite results into a safe stop);
* no ``fastmath``: IEEE semantics, so NaN fails every comparison as the checks rely on.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

from numba import njit

F = TypeVar("F", bound=Callable[..., Any])


def jit(fn: F) -> F:
    """Compile ``fn`` lazily (on its first call) with the shared settings."""
    return cast(F, njit(cache=True, nogil=True, error_model="numpy")(fn))


@jit
def all_finite(a: Any) -> bool:
    """True iff no entry of the array is NaN or ±inf (np.isfinite(a).all() in one call)."""
    for x in a.flat:  # noqa: SIM110 (a loop numba compiles; all() over a generator it does not)
        if not math.isfinite(x):
            return False
    return True
