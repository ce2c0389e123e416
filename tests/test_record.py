"""`@record` (simcore.scenario.record) makes each scenario model class what `@dataclass(frozen=True)` makes of
it: every class of simcore.scenario.model is rebuilt with dataclasses from its own fields and compared,
member by member and on instances (init, defaults, repr, equality, hash, frozenness, replace)."""

from __future__ import annotations

import dataclasses
import inspect
import math
from dataclasses import FrozenInstanceError
from typing import Any

import pytest

from simcore.scenario import model
from simcore.scenario.record import record

MODEL_CLASSES = [
    value
    for value in vars(model).values()
    if isinstance(value, type) and value.__module__ == model.__name__ and dataclasses.is_dataclass(value)
]


def reference(cls: type) -> type:
    """The same class made by @dataclass(frozen=True): same name, module, annotations, fields and methods."""
    namespace: dict[str, Any] = {
        "__module__": cls.__module__,
        "__qualname__": cls.__qualname__,
        "__annotations__": dict(cls.__annotations__),
    }
    if cls.__dict__.get("__doc__") and not cls.__doc__.startswith(cls.__name__ + "("):
        namespace["__doc__"] = cls.__doc__
    for f in dataclasses.fields(cls):
        namespace[f.name] = dataclasses.field(
            default=f.default,
            default_factory=f.default_factory,
            repr=f.repr,
            hash=f.hash,
            compare=f.compare,
            metadata=f.metadata,
        )
    for name, value in cls.__dict__.items():  # properties, cached properties, methods
        if name not in namespace and not name.startswith("__") and name not in cls.__dataclass_fields__:
            namespace[name] = value
    return dataclasses.dataclass(frozen=True)(type(cls.__name__, (), namespace))


def sample_values(cls: type, variant: int) -> dict[str, Any]:
    """Field values of the right arity (not of the right types: the classes do not check them)."""
    values: dict[str, Any] = {}
    for i, f in enumerate(dataclasses.fields(cls)):
        values[f.name] = (f.name, i, variant) if i % 2 else float(i + variant)
    return values


def test_every_model_class_is_a_record() -> None:
    assert len(MODEL_CLASSES) > 80
    for cls in MODEL_CLASSES:
        assert cls.__init__.__qualname__ == f"{cls.__qualname__}.__init__"
        assert cls.__dataclass_params__.frozen and cls.__dataclass_params__.eq


@pytest.mark.parametrize("cls", MODEL_CLASSES, ids=lambda c: c.__name__)
def test_record_equals_dataclass(cls: type) -> None:
    ref = reference(cls)
    assert cls.__doc__ == ref.__doc__
    assert str(inspect.signature(cls)) == str(inspect.signature(ref))
    assert cls.__match_args__ == ref.__match_args__
    assert [(f.name, f.type, f.compare, f.repr, f.hash) for f in dataclasses.fields(cls)] == [
        (f.name, f.type, f.compare, f.repr, f.hash) for f in dataclasses.fields(ref)
    ]
    params = ("init", "repr", "eq", "order", "unsafe_hash", "frozen")
    assert [getattr(cls.__dataclass_params__, p) for p in params] == [
        getattr(ref.__dataclass_params__, p) for p in params
    ]
    required = {
        f.name: v
        for f, v in zip(dataclasses.fields(cls), sample_values(cls, 0).values(), strict=True)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    }
    # defaults (shared values and fresh factory products) as the dataclass gives them
    assert repr(cls(**required)) == repr(ref(**required)).replace(ref.__qualname__, cls.__qualname__)
    for variant in (0, 1):
        values = sample_values(cls, variant)
        a, b, other = cls(**values), ref(**values), cls(**sample_values(cls, variant + 1))
        assert repr(a) == repr(b)
        assert a == cls(**values) and a != other and a != b  # a different class is never equal
        assert (a == b) is (b == a) is False
        assert hash(a) == hash(b)
        for name, value in values.items():
            assert getattr(a, name) == value
        assert dataclasses.asdict(a) == dataclasses.asdict(b)
        changed = dataclasses.replace(a, **dict(list(values.items())[:1]))
        assert changed == a and changed is not a
    for field in dataclasses.fields(cls)[:1]:
        obj = cls(**sample_values(cls, 0))
        with pytest.raises(FrozenInstanceError, match=f"cannot assign to field '{field.name}'"):
            setattr(obj, field.name, 1)
        with pytest.raises(FrozenInstanceError, match=f"cannot delete field '{field.name}'"):
            delattr(obj, field.name)
        with pytest.raises(FrozenInstanceError, match="cannot assign to field 'other'"):
            obj.other = 1  # type: ignore[attr-defined]


def test_compare_false_fields_and_nan_identity_as_dataclasses() -> None:
    @record
    class Point:
        x: float
        source: str = dataclasses.field(default="", compare=False)

    @dataclasses.dataclass(frozen=True)
    class Ref:
        x: float
        source: str = dataclasses.field(default="", compare=False)

    nan = math.nan
    assert (Point(1.0, "a") == Point(1.0, "b")) is (Ref(1.0, "a") == Ref(1.0, "b")) is True
    assert hash(Point(1.0, "a")) == hash(Ref(1.0, "b"))
    assert (Point(nan) == Point(nan)) is (
        Ref(nan) == Ref(nan)
    )  # the same NaN object: tuples compare by identity
    assert repr(Point(2.5)) == repr(Ref(2.5)).replace("Ref", "Point")


def test_init_is_compiled_when_first_needed() -> None:
    @record
    class Pair:
        a: int
        b: list[int] = dataclasses.field(default_factory=list)

    assert "__init__" in Pair.__dict__ and not inspect.isfunction(Pair.__dict__["__init__"])
    first = Pair(1)  # the first instance compiles it
    assert inspect.isfunction(Pair.__dict__["__init__"]) and Pair.__init__.__qualname__.endswith(
        "Pair.__init__"
    )
    assert (first.a, first.b, Pair(2, [3]).b) == (1, [], [3]) and first.b is not Pair(1).b
    with pytest.raises(TypeError, match="missing 1 required positional argument: 'a'"):
        Pair()  # type: ignore[call-arg]


def test_recursive_repr_is_cut_like_dataclasses() -> None:
    @record
    class Box:
        items: list[Any]

    box = Box([])
    box.items.append(box)
    assert repr(box) == "test_recursive_repr_is_cut_like_dataclasses.<locals>.Box(items=[...])"


def test_subclass_of_a_record_may_set_its_own_attributes() -> None:
    @record
    class Base:
        x: int

    class Sub(Base):
        pass

    sub = Sub(1)
    sub.note = "kept"  # type: ignore[attr-defined]
    assert sub.note == "kept"  # type: ignore[attr-defined]
    with pytest.raises(FrozenInstanceError):
        sub.x = 2  # type: ignore[misc]


def test_unsupported_definitions_are_refused() -> None:
    with pytest.raises(TypeError, match="__post_init__"):

        @record
        class Post:
            x: int

            def __post_init__(self) -> None:
                pass

    with pytest.raises(TypeError, match="non-default argument 'y' follows default argument"):

        @record
        class Order:
            x: int = 0
            y: int  # type: ignore[misc]

    with pytest.raises(TypeError, match="positional init fields"):

        @record
        class NoInit:
            x: int = dataclasses.field(default=0, init=False)
