"""Reading TOML configs: typed access whose every error names the file and the dotted key.

Shared by every config loader of the project (robot, controller, scene, and the sim's and the
service's). A frozen dataclass declares each of its keys once, on its field
(``field(default=..., metadata=toml_key(number(lo=0.0)))``): :func:`toml_keys` derives the keys a
table allows from the fields, :func:`load` reads every field that names its reader.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import Field, dataclass, fields
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from .._typing import FloatArray, readonly
from ..exceptions import ConfigError

T = TypeVar("T")


class TomlTable:
    """Typed access to a TOML table, with errors that name the file and the dotted key.

    Args:
        path: the file the table was read from (named in every error).
        data: the table.
        prefix: the table's dotted key with a trailing dot ("" for the file's root table).
    """

    def __init__(self, path: Path, data: dict[str, Any], prefix: str = "") -> None:
        self.path, self.data, self.prefix = path, data, prefix

    def key(self, k: str) -> str:
        """The dotted key of ``k`` in this table, as the errors name it (``qp.solver``)."""
        return f"{self.prefix}{k}"

    def has(self, k: str) -> bool:
        return k in self.data

    def table(self, k: str, required: bool = True) -> TomlTable:
        v = self.data.get(k, None if required else {})
        if not isinstance(v, dict):
            raise ConfigError(self.path, self.key(k), "missing table" if v is None else "must be a table")
        return TomlTable(self.path, v, f"{self.key(k)}.")

    def get(self, k: str, default: Any = ...) -> Any:
        if k not in self.data:
            if default is ...:
                raise ConfigError(self.path, self.key(k), "missing")
            return default
        return self.data[k]

    def number(
        self, k: str, default: Any = ..., *, positive: bool = False, lo: float | None = None, hi: float | None = None
    ) -> float:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(self.path, self.key(k), f"must be a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise ConfigError(self.path, self.key(k), f"must be finite, got {v}")
        if positive and v <= 0:
            raise ConfigError(self.path, self.key(k), f"must be > 0, got {v}")
        if lo is not None and v < lo:
            raise ConfigError(self.path, self.key(k), f"must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise ConfigError(self.path, self.key(k), f"must be <= {hi}, got {v}")
        return v

    def integer(self, k: str, default: Any = ..., *, lo: int | None = None) -> int:
        v = self.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(self.path, self.key(k), f"must be an integer, got {v!r}")
        if lo is not None and v < lo:
            raise ConfigError(self.path, self.key(k), f"must be >= {lo}, got {v}")
        return v

    def vector(self, k: str, n: int, default: Any = ..., *, positive: bool = False, finite: bool = True) -> FloatArray:
        v = self.get(k, default)
        if not isinstance(v, list | tuple | np.ndarray) or len(v) != n:
            raise ConfigError(self.path, self.key(k), f"must be a list of {n} numbers, got {v!r}")
        if any(isinstance(x, bool) or not isinstance(x, int | float) for x in v):
            raise ConfigError(self.path, self.key(k), f"must hold numbers only, got {v!r}")
        a = np.array(v, dtype=float)
        if np.isnan(a).any() or (finite and not np.isfinite(a).all()):
            raise ConfigError(self.path, self.key(k), f"must be finite, got {v!r}")
        if positive and (a <= 0).any():
            raise ConfigError(self.path, self.key(k), f"every entry must be > 0, got {v!r}")
        return readonly(a)

    def per_joint(self, k: str, n: int, default: Any = ..., *, positive: bool = False) -> FloatArray:
        """One number (the same for all n entries) or a list of n numbers."""
        v = self.get(k, default)
        if isinstance(v, int | float) and not isinstance(v, bool):
            v = [v] * n
        elif not isinstance(v, list | tuple | np.ndarray) or len(v) != n:
            raise ConfigError(self.path, self.key(k), f"must be one number or a list of {n} numbers, got {v!r}")
        return TomlTable(self.path, {k: list(v)}, self.prefix).vector(k, n, positive=positive)

    def string(self, k: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str):
            raise ConfigError(self.path, self.key(k), f"must be a string, got {v!r}")
        if choices is not None and v not in choices:
            raise ConfigError(self.path, self.key(k), f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, k: str, default: Any = ...) -> bool:
        v = self.get(k, default)
        if not isinstance(v, bool):
            raise ConfigError(self.path, self.key(k), f"must be true or false, got {v!r}")
        return v

    def unknown(self, allowed: set[str]) -> None:
        """Raise on the first key (in sorted order) that is not in ``allowed``, listing those."""
        extra = sorted(set(self.data) - allowed)
        if extra:
            raise ConfigError(self.path, self.key(extra[0]), f"unknown key (allowed: {', '.join(sorted(allowed))})")


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; every failure is a :class:`ConfigError` naming the file."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(path, "", "file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "", f"not valid TOML: {e}") from None
    except OSError as e:
        raise ConfigError(path, "", f"cannot read: {e.strerror}") from None


# --------------------------------------------------------------------------- keys declared on fields
Reader = Callable[[TomlTable, str, Any], Any]
"""Reads and checks one key: (its table, the key, the default or ``...`` if the key is required)."""


@dataclass(frozen=True)
class TomlKey:
    """Where a dataclass field comes from in a TOML file (its field's ``metadata["toml"]``).

    Attributes:
        read: reads and checks the value; None: the loader reads the key itself (a value that
            needs more than its own table, e.g. the URDF's limits).
        table: the sub-table the key sits in ("": the dataclass's own table).
        key: the key's name when it is not the field's.
    """

    read: Reader | None = None
    table: str = ""
    key: str = ""


def toml_key(read: Reader | None = None, *, table: str = "", key: str = "") -> dict[str, TomlKey]:
    """The metadata of a field that a TOML key sets: ``field(default=..., metadata=toml_key(...))``."""
    return {"toml": TomlKey(read, table, key)}


def number(*, positive: bool = False, lo: float | None = None, hi: float | None = None) -> Reader:
    """A finite number (:meth:`TomlTable.number`)."""
    return lambda t, k, d: t.number(k, d, positive=positive, lo=lo, hi=hi)


def boolean() -> Reader:
    """true or false."""
    return lambda t, k, d: t.boolean(k, d)


def choice(options: tuple[str, ...]) -> Reader:
    """One of ``options``."""
    return lambda t, k, d: t.string(k, d, options)


def section(cls: type[Any]) -> dict[str, Any]:
    """The metadata of a field that a whole sub-table sets, read into the dataclass ``cls`` by
    :func:`load` (absent: the default): ``field(default_factory=cls, metadata=section(cls))``."""

    def read(t: TomlTable, k: str, default: Any) -> Any:
        return load(t.table(k, required=False), cls, default)

    return {"toml": TomlKey(read), "toml_section": cls}


def _declared(cls: type[Any]) -> list[tuple[Field[Any], TomlKey]]:
    return [(f, f.metadata["toml"]) for f in fields(cls) if "toml" in f.metadata]


def toml_keys(cls: type[Any], table: str = "") -> set[str]:
    """The keys ``cls``'s fields declare in its ``table`` ("": its own, which also holds its sub-tables)."""
    keys = {spec.key or f.name for f, spec in _declared(cls) if spec.table == table}
    if not table:
        keys |= {spec.table for _, spec in _declared(cls) if spec.table}
    return keys


def check_keys(t: TomlTable, cls: type[Any]) -> None:
    """Raise on the first key of ``t`` that ``cls`` does not declare, in ``t``, in its sub-tables
    and in its sections (the sub-tables read into nested dataclasses), before any value is read."""
    t.unknown(toml_keys(cls))
    seen = set()
    for f, spec in _declared(cls):
        if spec.table and spec.table not in seen:
            seen.add(spec.table)
            t.table(spec.table, required=False).unknown(toml_keys(cls, spec.table))
        nested = f.metadata.get("toml_section")
        if nested is not None:
            check_keys(t.table(spec.key or f.name, required=False), nested)


def load(t: TomlTable, cls: type[T], defaults: T | None = None, **given: Any) -> T:
    """An instance of the dataclass ``cls`` from the table ``t``.

    Unknown keys are errors (:func:`check_keys`, first); then every field with a reader is read,
    in the fields' order, its default ``defaults``' value (``...``: required when there is none);
    ``given`` holds the fields the caller read itself.

    Raises:
        ConfigError: naming the file and the dotted key of the first problem found.
    """
    check_keys(t, cls)
    tables = {"": t}
    values = dict(given)
    for f, spec in _declared(cls):
        if spec.read is not None:
            if spec.table not in tables:
                tables[spec.table] = t.table(spec.table, required=False)
            default = getattr(defaults, f.name) if defaults is not None else ...
            values[f.name] = spec.read(tables[spec.table], spec.key or f.name, default)
    return cls(**values)
