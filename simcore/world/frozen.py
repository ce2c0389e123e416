"""Fast construction of frozen dataclasses built on every simulation step (world frames, road coordinates).

A frozen dataclass's `__init__` sets each field through `object.__setattr__`: five times slower than a plain
one for a 15-field `EntityState`, built for every entity at every step. `builder(cls)` gives a positional
constructor (every field, in order) that makes an empty unfrozen twin with the same fields (the same memory
layout), stores the fields plainly, then makes it a `cls`: the very object `cls(...)` gives, still frozen
afterwards. The constructor is one generated function (no `*values` tuple, no second call for the twin's
`__init__`): it is called ~2,000 times per run.
"""

from __future__ import annotations

import keyword
from collections.abc import Callable
from dataclasses import fields, is_dataclass, make_dataclass
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
