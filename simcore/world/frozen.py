"""Immutable value objects built on every simulation step, fast: `builder` for frozen dataclasses (road
coordinates), `freeze` for the world frame's value classes (`simcore.world.state`).

A frozen dataclass's `__init__` sets each field through `object.__setattr__`: five times slower than a plain
one for a 15-field `EntityState`, built for every entity at every step. `builder(cls)` gives a positional
constructor (every field, in order) that makes an empty unfrozen twin with the same fields (the same memory
layout), stores the fields plainly, then makes it a `cls`: the very object `cls(...)` gives, still frozen
afterwards. The constructor is one generated function (no `*values` tuple, no second call for the twin's
`__init__`): it is called ~2,000 times per run.
"""

from __future__ import annotations

import inspect
import keyword
from collections.abc import Callable
from dataclasses import FrozenInstanceError, fields, is_dataclass, make_dataclass
from typing import Any, TypeVar

_T = TypeVar("_T")


def builder(cls: type[_T]) -> Callable[..., _T]:
    """A positional constructor of the frozen dataclass `cls` at the cost of a plain one (`cls` itself
    where its layout does not allow it)."""
    if not is_dataclass(cls):
        return cls
    names = [f.name for f in fields(cls)]
    if not all(n.isidentifier() and not keyword.iskeyword(n) and not n.startswith("_") for n in names):
        return cls  # names the generated source below could not spell (or that clash with its globals)
    slots = "__slots__" in cls.__dict__
    twin = make_dataclass(f"_{cls.__name__}Builder", names, slots=slots)
    arguments = ", ".join(names)
    stores = "".join(f"    obj.{n} = {n}\n" for n in names)
    source = (
        f"def build({arguments}):\n    obj = _new(_twin)\n{stores}    obj.__class__ = _cls\n    return obj\n"
    )
    namespace: dict[str, Any] = {"_new": object.__new__, "_twin": twin, "_cls": cls}
    exec(source, namespace)  # source made above from the dataclass's own field names
    build: Callable[..., _T] = namespace["build"]
    build.__qualname__ = build.__name__ = f"build_{cls.__name__}"
    try:
        probe = build(*range(len(names)))
    except TypeError:
        return cls
    if type(probe) is not cls or [getattr(probe, n) for n in names] != list(range(len(names))):
        return cls
    return build


def freeze(cls: type) -> None:
    """Make the instances of `cls` immutable where it runs interpreted: a compiled class (mypyc) makes its
    `Final` attributes read-only itself. `cls` must have `__slots__` and an `__init__` that takes exactly
    them, in order, and only stores each in its slot; run interpreted, that `__init__` gives way to one that
    stores the same values past the `__setattr__` refusing every assignment and deletion afterwards, with
    dataclasses' FrozenInstanceError. Raises TypeError for any other class."""
    if "__mypyc_attrs__" in cls.__dict__:
        return
    names = tuple(cls.__dict__.get("__slots__", ()))
    own_init = cls.__dict__.get("__init__")
    parameters = list(inspect.signature(own_init).parameters.values())[1:] if own_init else []
    if (
        not names
        or [p.name for p in parameters] != list(names)
        or any(
            p.kind is not p.POSITIONAL_OR_KEYWORD or not p.name.isidentifier() or keyword.iskeyword(p.name)
            for p in parameters
        )
    ):
        raise TypeError(f"{cls.__name__}: freeze needs __slots__ and an __init__ taking exactly them")
    namespace: dict[str, Any] = {f"_set_{n}": cls.__dict__[n].__set__ for n in names}
    arguments = []
    for p in parameters:
        if p.default is p.empty:
            arguments.append(p.name)
        else:
            namespace[f"_default_{p.name}"] = p.default
            arguments.append(f"{p.name}=_default_{p.name}")
    stores = "".join(f"    _set_{n}(self, {n})\n" for n in names)
    exec(f"def __init__(self, {', '.join(arguments)}):\n{stores}", namespace)  # source made from the slots
    init = namespace["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__doc__ = own_init.__doc__

    def __setattr__(self: object, name: str, value: object) -> None:
        raise FrozenInstanceError(f"cannot assign to field {name!r}")

    def __delattr__(self: object, name: str) -> None:
        raise FrozenInstanceError(f"cannot delete field {name!r}")

    for method in (init, __setattr__, __delattr__):
        method.__qualname__ = f"{cls.__qualname__}.{method.__name__}"
        setattr(cls, method.__name__, method)
