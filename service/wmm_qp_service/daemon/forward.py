"""An attribute of one of an object's parts under the object's own name (a descriptor)."""

from __future__ import annotations

from typing import Any, Generic, TypeVar, overload

T = TypeVar("T")


class Forward(Generic[T]):
    """``owner.<attr>`` reads (and, when ``writable``, writes) ``owner.<part>.<name>``.

    Args:
        part: the attribute of the owner that holds the part.
        name: the part's attribute.
        writable: assignments go through to the part (else they raise AttributeError).
    """

    def __init__(self, part: str, name: str, writable: bool = False) -> None:
        self.part, self.name, self.writable = part, name, writable
        self.attr = name

    def __set_name__(self, owner: type, attr: str) -> None:
        self.attr = attr

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> Forward[T]: ...

    @overload
    def __get__(self, obj: object, owner: type | None = None) -> T: ...

    def __get__(self, obj: object | None, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return getattr(getattr(obj, self.part), self.name)

    def __set__(self, obj: object, value: T) -> None:
        if not self.writable:
            raise AttributeError(f"{self.attr} is {self.part}.{self.name}, read only here")
        setattr(getattr(obj, self.part), self.name, value)
