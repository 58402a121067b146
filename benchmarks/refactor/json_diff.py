"""Compare two JSON documents: numbers within a tolerance, everything else equal.

The comparison of :mod:`same_results` (one command's JSON from the tree before a change and from
the tree after it). Standard library only: it must not import either tree's code.

Rules, applied recursively:

* two numbers (``int`` or ``float``, not ``bool``) are equal when ``|a − b| ≤ tol`` or
  ``|a − b| ≤ tol · max(|a|, |b|)`` (absolute or relative), or when both are NaN;
* strings, booleans and ``None`` are equal only when identical (``True`` is not ``1``);
* lists must have the same length, element by element;
* objects must have the same keys (a key on one side only is a difference), except the keys of
  :data:`SKIPPED_KEYS`, which are ignored wherever they occur.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

TOL = 1e-9
"""Absolute or relative tolerance on every number."""

SKIPPED_KEYS: dict[str, str] = {
    # No in-process command of docs/results.md prints a timing field: every key of every
    # command's JSON (same_results.py --out lists them, "key_names") is a result of the deterministic
    # simulation. Timing lives only in the outputs of the excluded realtime runs (their
    # "realtime" block: ticks, deadline misses, state age), in `wmm-qp bench` (tick_us, …) and
    # on stderr (progress lines, "13 s"). Add a key here, with why, only if it is timing.
}
"""Keys ignored wherever they occur → why (only timing may be skipped)."""

MISSING = "<missing>"
"""The stand-in value of a key absent on one side."""


@dataclass(frozen=True)
class Difference:
    """One place where the two documents differ.

    Attributes:
        path: the JSON path, e.g. ``with_dm.max_abs_torque[5]`` (``""``: the document itself).
        before: the value in the first document (:data:`MISSING` if the key is not there).
        after: the value in the second document (:data:`MISSING` if the key is not there).
    """

    path: str
    before: Any
    after: Any

    def __str__(self) -> str:
        return f"{self.path or '<document>'}: before {self.before!r}, after {self.after!r}"


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def numbers_equal(a: float, b: float, tol: float = TOL) -> bool:
    """``|a − b| ≤ tol`` or ``|a − b| ≤ tol · max(|a|, |b|)``; NaN equals NaN, ±inf only itself."""
    if a == b:
        return True
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return False
    d = abs(a - b)
    return d <= tol or d <= tol * max(abs(a), abs(b))


def _key_path(path: str, key: str) -> str:
    plain = key and not any(c in key for c in '.[]"')
    return (f"{path}.{key}" if path else key) if plain else f"{path}[{key!r}]"


def differences(
    before: Any, after: Any, tol: float = TOL, skip: Mapping[str, str] | None = None, path: str = ""
) -> Iterator[Difference]:
    """Every difference between two JSON values, in document order (depth first).

    Args:
        before: a parsed JSON value (dict, list, str, int, float, bool or None).
        after: the other one.
        tol: absolute or relative tolerance on numbers (module docstring).
        skip: keys to ignore wherever they occur (default :data:`SKIPPED_KEYS`).
        path: the path of ``before``/``after`` in their documents (for the report).
    """
    skip = SKIPPED_KEYS if skip is None else skip
    if _is_number(before) and _is_number(after):
        if not numbers_equal(float(before), float(after), tol):
            yield Difference(path, before, after)
    elif isinstance(before, dict) and isinstance(after, dict):
        for k in list(before) + [k for k in after if k not in before]:
            if k in skip:
                continue
            kp = _key_path(path, k)
            if k not in after:
                yield Difference(kp, before[k], MISSING)
            elif k not in before:
                yield Difference(kp, MISSING, after[k])
            else:
                yield from differences(before[k], after[k], tol, skip, kp)
    elif isinstance(before, list) and isinstance(after, list):
        if len(before) != len(after):
            yield Difference(f"{path} (length)", len(before), len(after))
            return
        for i, (a, b) in enumerate(zip(before, after, strict=True)):
            yield from differences(a, b, tol, skip, f"{path}[{i}]")
    elif type(before) is not type(after) or before != after:
        yield Difference(path, before, after)


def count_numbers(doc: Any, skip: Mapping[str, str] | None = None) -> int:
    """How many numbers ``doc`` holds outside skipped keys (what a comparison covered)."""
    skip = SKIPPED_KEYS if skip is None else skip
    if _is_number(doc):
        return 1
    if isinstance(doc, dict):
        return sum(count_numbers(v, skip) for k, v in doc.items() if k not in skip)
    if isinstance(doc, list):
        return sum(count_numbers(v, skip) for v in doc)
    return 0


def key_names(doc: Any) -> set[str]:
    """Every object key in ``doc``, at any depth (to see that none of them is timing)."""
    if isinstance(doc, dict):
        return set(doc).union(*(key_names(v) for v in doc.values()))
    if isinstance(doc, list):
        return set().union(*(key_names(v) for v in doc))
    return set()


def max_deviation(diffs: list[Difference]) -> tuple[float, float]:
    """The largest absolute and relative difference among the numeric ones (0, 0 if none)."""
    abs_max = rel_max = 0.0
    for d in diffs:
        if _is_number(d.before) and _is_number(d.after):
            a, b = float(d.before), float(d.after)
            if math.isfinite(a) and math.isfinite(b):
                abs_max = max(abs_max, abs(a - b))
                rel_max = max(rel_max, abs(a - b) / max(abs(a), abs(b)))
    return abs_max, rel_max
