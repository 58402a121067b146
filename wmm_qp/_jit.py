"""The compiled kernels of the hot path: numba's ``njit`` with the settings they all share.

Every tick runs a handful of small kernels (bounds (13), the kinematics assembly of eqs. (2)
and (5), the DM of eqs. (8)–(10), σ_min and the closed-form QP optimum). Written as numpy
expressions each was several numpy calls of ~0.3–2 µs; compiled, one call of ~0.3–1 µs.

* ``cache=True``: compiled once per machine (into ``__pycache__``, or numba's user cache when
  the package folder is read-only; ``NUMBA_CACHE_DIR`` chooses another place), loaded in ~ms
  afterwards. Where no cache location is writable at all (a service user without a home, a
  read-only container), the kernels are compiled in memory at each start instead.
* numba invalidates a kernel's cache only when the kernel's own file changes, and ours call
  each other across files (``linalg3``); so when any source file of the package changed since
  the caches were written, :func:`_drop_stale_caches` drops them all (an editable install being
  edited; a reinstall rewrites every file, which numba notices by itself).
* ``error_model="numpy"``: a division by zero gives inf/NaN like numpy, never an exception
  (the callers' checks turn non-finite results into a safe stop);
* no ``fastmath``: IEEE semantics, so NaN fails every comparison the checks rely on. (Python's
  ``min``/``max``, which the kernels use, drop a NaN in their second argument; no kernel
  depends on them to propagate one.)
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

from numba import njit

F = TypeVar("F", bound=Callable[..., Any])

_PACKAGE = Path(__file__).resolve().parent
_STAMP = "numba-sources.sha256"


def _drop_stale_caches(package: Path = _PACKAGE) -> bool:
    """Delete the package's numba cache files if any of its sources changed; True if it did.

    The stamp (a hash of every ``*.py`` of the package) lives next to the caches in
    ``__pycache__``. Read-only installs (no writable ``__pycache__``) are left alone.
    """
    try:
        digest = hashlib.sha256()
        for p in sorted(package.rglob("*.py")):
            digest.update(p.relative_to(package).as_posix().encode() + b"\0" + p.read_bytes())
        stamp = package / "__pycache__" / _STAMP
        if stamp.is_file() and stamp.read_text() == digest.hexdigest():
            return False
        dropped = False
        for f in package.rglob("__pycache__/*.nb[ic]"):
            f.unlink(missing_ok=True)
            dropped = True
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
        return dropped
    except OSError:
        return False


_drop_stale_caches()


def jit(fn: F) -> F:
    """Compile ``fn`` lazily (on its first call) with the shared settings."""
    try:
        return cast(F, njit(cache=True, nogil=True, error_model="numpy")(fn))
    except RuntimeError:  # "cannot cache function …: no locator available" (nothing writable)
        return cast(F, njit(cache=False, nogil=True, error_model="numpy")(fn))


def jit_inline(fn: F) -> F:
    """:func:`jit`, and inlined into its compiled callers (numba's ``inline="always"``): a call
    between compiled functions passes each array as a struct with its reference count taken and
    released, which a kernel run once a pair pays every pair; the small per-pair kernels are
    inlined instead (their callers compile longer: GJK inlined took the rows' cold compile from
    35 to 90 s, so GJK itself is not; its own helpers are, into it)."""
    try:
        return cast(F, njit(cache=True, nogil=True, error_model="numpy", inline="always")(fn))
    except RuntimeError:
        return cast(F, njit(cache=False, nogil=True, error_model="numpy", inline="always")(fn))


@jit
def all_finite(a: Any) -> bool:
    """True iff no entry of the array is NaN or ±inf (np.isfinite(a).all() in one call)."""
    for x in a.flat:  # noqa: SIM110 (a loop numba compiles; all() over a generator it does not)
        if not math.isfinite(x):
            return False
    return True
