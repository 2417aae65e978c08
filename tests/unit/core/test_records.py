"""``mission.core.records.replace`` returns what ``dataclasses.replace`` returns, for every kind of dataclass."""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import InitVar, dataclass, field

import numpy as np
import pytest

from mission.core.records import _plain_fields, replace
from mission.phases.types import MissionState


@dataclass(frozen=True)
class Plain:
    a: int
    b: tuple[int, ...] = ()
    c: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class Checked:
    a: int
    doubled: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "doubled", 2 * self.a)


@dataclass
class NotInInit:
    a: int
    n: int = field(init=False, default=7)


@dataclass
class WithInitVar:
    a: int
    scale: InitVar[int] = 1

    def __post_init__(self, scale: int) -> None:
        self.a *= scale


@dataclass(slots=True)
class Slotted:
    a: int


@dataclass(frozen=True)
class Cached:
    a: int

    @functools.cached_property
    def square(self) -> int:
        return self.a * self.a


@dataclass
class OwnInit:
    a: int

    def __init__(self, a: int) -> None:
        self.a = a + 1


@dataclass(frozen=True)
class Child(Checked):
    extra: int = 0


def _same(obj: object, **changes: object) -> None:
    ours, theirs = replace(obj, **changes), dataclasses.replace(obj, **changes)  # type: ignore[type-var]
    assert type(ours) is type(theirs)
    assert ours == theirs
    assert getattr(ours, "__dict__", None) == getattr(theirs, "__dict__", None)
    assert ours is not obj


@pytest.mark.parametrize("obj, changes", [
    (Plain(1, (2,), [3]), {"a": 5}), (Plain(1), {}), (Checked(3), {"a": 4}), (Child(3, extra=1), {"a": 5}),
    (NotInInit(1), {"a": 2}), (WithInitVar(2, 3), {"a": 4, "scale": 5}), (Slotted(1), {"a": 2}), (OwnInit(1), {"a": 4}),
])
def test_every_kind_gives_what_dataclasses_replace_gives(obj: object, changes: dict) -> None:
    _same(obj, **changes)


def test_a_cached_value_is_not_carried_over() -> None:
    old = Cached(2)
    assert old.square == 4
    assert replace(old, a=3).square == 9


def test_the_fast_path_is_taken_only_for_plain_classes() -> None:
    assert _plain_fields(Plain) == {"a", "b", "c"}
    assert _plain_fields(MissionState) is not None
    for cls in (Checked, Child, NotInInit, WithInitVar, OwnInit):
        assert _plain_fields(cls) is None, cls


def test_errors_are_those_of_dataclasses_replace() -> None:
    with pytest.raises(TypeError):
        replace(Plain(1), nope=2)
    with pytest.raises(ValueError):
        replace(NotInInit(1), n=3)
    with pytest.raises(TypeError):
        replace(object())


def test_the_mission_state_is_replaced_field_for_field() -> None:
    state = MissionState()
    new = replace(state, tick_s=1.5, x_ref=np.ones(3))
    assert new.tick_s == 1.5 and new.x_ref is not None and state.tick_s is None
    assert {k: v for k, v in vars(new).items() if k not in ("tick_s", "x_ref")} == \
        {k: v for k, v in vars(state).items() if k not in ("tick_s", "x_ref")}
