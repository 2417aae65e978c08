"""``replace``: :func:`dataclasses.replace`, the same result, for the records replaced every tick.

The pure step keeps its state in frozen dataclasses and moves on by replacing a few fields of
them, several times a tick. :func:`dataclasses.replace` calls the class's generated
``__init__`` with every field (28 for the mission's state), about 30 us each; for a *plain*
dataclass, whose generated ``__init__`` only stores its arguments, copying the instance's
``__dict__`` and then the changed fields gives the same object, in a tenth of the time. Any
other class (a ``__post_init__``, an ``InitVar``, a field with ``init=False``, slots, a
``__init__`` or ``__new__`` of its own, not a dataclass) goes through :func:`dataclasses.replace`
itself, as does a change naming something that is not a field (its error) and an instance that
holds anything but its fields (a cached property's value).
"""
from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

T = TypeVar("T")

_PLAIN: dict[type, frozenset[str] | None] = {}  # a class -> its fields when plain, else None


def _plain_fields(cls: type) -> frozenset[str] | None:
    """The field names of ``cls`` if its generated ``__init__`` only stores them, else None."""
    params = cls.__dict__.get("__dataclass_params__")
    init = cls.__dict__.get("__init__")
    if params is None or not params.init or init is None or getattr(init, "__code__", None) is None:
        return None
    if init.__code__.co_filename != "<string>" or "__post_init__" in dir(cls):
        return None  # an __init__ written by hand (dataclass keeps it), a check after it
    if cls.__new__ is not object.__new__:
        return None
    fields = dataclasses.fields(cls)  # type: ignore[arg-type]
    if len(fields) != len(cls.__dict__["__dataclass_fields__"]) or not all(f.init for f in fields):
        return None  # an InitVar or ClassVar pseudo-field, or a field __init__ sets itself
    return frozenset(f.name for f in fields)


def replace(obj: T, /, **changes: Any) -> T:
    """A copy of the dataclass instance ``obj`` with ``changes``; what :func:`dataclasses.replace`
    returns (see the module docstring)."""
    cls = type(obj)
    try:
        names = _PLAIN[cls]
    except KeyError:
        names = _PLAIN[cls] = _plain_fields(cls)
    old = getattr(obj, "__dict__", None)  # None with slots; a field in a slot is not in it
    if names is None or old is None or not names.issuperset(changes) or old.keys() != names:
        return dataclasses.replace(obj, **changes)  # type: ignore[type-var]
    new = object.__new__(cls)
    state = new.__dict__
    state.update(old)
    state.update(changes)
    return new
