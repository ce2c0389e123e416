"""`@record`: a frozen dataclass, defined at a fraction of `@dataclass(frozen=True)`'s start-up cost.

`@dataclass(frozen=True)` compiles six methods per class (`__init__`, `__repr__`, `__eq__`, `__hash__`,
`__setattr__`, `__delattr__`), each its own `exec` of generated source: for the scenario model's ~85 classes
that is some 500 compilations, 40-60 ms of every `carlos run` and of every worker's first run. `@record` makes
the same class compiling at most one: the dataclass machinery without generated methods (fields, `__doc__`,
`__match_args__`; `dataclasses.fields`, `replace`, `asdict` work as on any dataclass), the `__init__` compiled
from the same source dataclasses would write (the same per-call cost) when it is first needed (a scenario
uses a few of the classes), and the other five as closures over the class's field names with the behaviour
of the generated ones (Python 3.11's): equality and hash over the tuple of compared fields,
`Name(field=value, …)` as repr, FrozenInstanceError on assignment and deletion.

Supported: fields with a default or a default_factory, `field(compare=…, hash=…, repr=…)`, no inheritance
between records, no `__post_init__`, `InitVar`, `kw_only` or `init=False` fields (refused with TypeError,
where dataclasses would accept them).
"""

from __future__ import annotations

import inspect
import operator
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import MISSING, Field, FrozenInstanceError, dataclass, field, fields
from typing import Any, TypeVar, dataclass_transform

_T = TypeVar("_T")


class _FactoryMarker:
    """The default of a default_factory field in `__init__`'s signature (dataclasses' is also `<factory>`)."""

    def __repr__(self) -> str:
        return "<factory>"


_HAS_DEFAULT_FACTORY = _FactoryMarker()


@dataclass_transform(frozen_default=True, field_specifiers=(field, Field))
def record(cls: type[_T]) -> type[_T]:
    """`cls` as `@dataclass(frozen=True)` would make it (see the module's docstring)."""
    if any(hasattr(base, "__dataclass_fields__") for base in cls.__mro__[1:]):
        raise TypeError(f"{cls.__name__}: @record does not support inheriting from a dataclass")
    if "__post_init__" in cls.__dict__:
        raise TypeError(f"{cls.__name__}: @record does not support __post_init__")
    documented = bool(cls.__dict__.get("__doc__"))
    if not documented:
        cls.__doc__ = cls.__name__  # not None, so that dataclass() does not build one from a signature
    made: Any = dataclass(init=False, repr=False, eq=False)(cls)
    own = fields(made)
    for f in own:
        if not f.init or f.kw_only is True:
            raise TypeError(f"{cls.__name__}.{f.name}: @record supports only positional init fields")
    if "__init__" in made.__dict__:
        raise TypeError(f"{cls.__name__} defines __init__: not a @record")
    made.__init__ = _LazyInit(made, *_init_source(own))
    _install(made, "__repr__", _repr_fn(made, [f.name for f in own if f.repr]))
    _install(made, "__eq__", _eq_fn([f.name for f in own if f.compare]))
    made.__hash__ = _hash_fn([f.name for f in own if (f.compare if f.hash is None else f.hash)])
    _set_qualname(made, made.__hash__)
    names = tuple(f.name for f in own)
    _install(made, "__setattr__", _frozen_setattr(made, names))
    _install(made, "__delattr__", _frozen_delattr(made, names))
    params = made.__dataclass_params__
    params.init = params.repr = params.eq = params.frozen = True
    if not documented:
        made.__doc__ = made.__name__ + _text_signature(own)
    made_class: type[_T] = made
    return made_class


def _install(cls: type, name: str, fn: Callable[..., Any]) -> None:
    if name in cls.__dict__:
        raise TypeError(f"{cls.__name__} defines {name}: not a @record")
    fn.__name__ = name
    _set_qualname(cls, fn)
    setattr(cls, name, fn)


def _set_qualname(cls: type, fn: Callable[..., Any]) -> None:
    fn.__qualname__ = f"{cls.__qualname__}.{fn.__name__}"


def _init_source(own: Sequence[Field[Any]]) -> tuple[str, dict[str, Any]]:
    """The source of the `__init__` dataclasses compiles for a frozen class (parameters with their annotations
    and defaults, each field set through object.__setattr__) and the names it refers to."""
    scope: dict[str, Any] = {
        "__dataclass_builtins_object__": object,
        "__dataclass_HAS_DEFAULT_FACTORY__": _HAS_DEFAULT_FACTORY,
        "__dataclass_return_type__": None,
    }
    parameters = ["self"]
    body = []
    for f in own:
        scope[f"__dataclass_type_{f.name}__"] = f.type
        annotation = f"{f.name}:__dataclass_type_{f.name}__"
        if f.default_factory is not MISSING:
            scope[f"__dataclass_dflt_{f.name}__"] = f.default_factory
            parameters.append(f"{annotation}=__dataclass_HAS_DEFAULT_FACTORY__")
            value = f"__dataclass_dflt_{f.name}__() if {f.name} is __dataclass_HAS_DEFAULT_FACTORY__ else {f.name}"
        elif f.default is not MISSING:
            scope[f"__dataclass_dflt_{f.name}__"] = f.default
            parameters.append(f"{annotation}=__dataclass_dflt_{f.name}__")
            value = f.name
        else:
            if len(parameters) > 1 and "=" in parameters[-1]:
                raise TypeError(f"non-default argument {f.name!r} follows default argument")
            parameters.append(annotation)
            value = f.name
        body.append(f"  __dataclass_builtins_object__.__setattr__(self,{f.name!r},{value})")
    source = (
        f"def __create_fn__({', '.join(scope)}):\n"
        f" def __init__({', '.join(parameters)}) -> __dataclass_return_type__:\n"
        + ("\n".join(body) or "  pass")
        + "\n return __init__"
    )
    return source, scope


class _LazyInit:
    """A record's `__init__` until it is first looked up (an instance made, inspect.signature, …): compiled
    then, as dataclasses would have compiled it, and put in its place on the class. A scenario uses a few of
    the model's classes; the others' `__init__` is never compiled."""

    def __init__(self, cls: type, source: str, scope: dict[str, Any]) -> None:
        self._cls = cls
        self._source = source
        self._scope = scope

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        cls = self._cls
        namespace: dict[str, Any] = {}
        # not inheriting this module's `from __future__ import annotations`: the annotations are the types
        code = compile(self._source, "<string>", "exec", dont_inherit=True)
        exec(code, sys.modules[cls.__module__].__dict__, namespace)  # generated source, as dataclasses does
        init: Callable[..., None] = namespace["__create_fn__"](**self._scope)
        _set_qualname(cls, init)
        type.__setattr__(cls, "__init__", init)  # from now on the class's own, as a dataclass's
        return init.__get__(obj, owner)


def _values(names: list[str]) -> Callable[[Any], tuple[Any, ...]]:
    """A function giving the tuple of an object's `names` attributes (a tuple also for one name or none)."""
    if len(names) >= 2:
        return operator.attrgetter(*names)
    if names:
        get = operator.attrgetter(names[0])
        return lambda obj: (get(obj),)
    return lambda obj: ()


def _eq_fn(names: list[str]) -> Callable[[Any, Any], Any]:
    values = _values(names)

    def eq(self: Any, other: Any) -> Any:
        if other.__class__ is self.__class__:
            return values(self) == values(other)
        return NotImplemented

    return eq


def _hash_fn(names: list[str]) -> Callable[[Any], int]:
    values = _values(names)

    def hash_(self: Any) -> int:
        return hash(values(self))

    hash_.__name__ = "__hash__"
    return hash_


def _repr_fn(cls: type, names: list[str]) -> Callable[[Any], str]:
    """`Name(a=…, b=…)` with the class's qualified name, and `...` for an object met again while its own repr
    is being made (as dataclasses' recursion guard)."""
    running: set[tuple[int, int]] = set()

    def repr_(self: Any) -> str:
        key = (id(self), threading.get_ident())
        if key in running:
            return "..."
        running.add(key)
        try:
            shown = ", ".join(f"{name}={getattr(self, name)!r}" for name in names)
            return f"{self.__class__.__qualname__}({shown})"
        finally:
            running.discard(key)

    return repr_


def _frozen_setattr(cls: type[Any], names: tuple[str, ...]) -> Callable[[Any, str, Any], None]:
    def setattr_(self: Any, name: str, value: Any) -> None:
        if type(self) is cls or name in names:
            raise FrozenInstanceError(f"cannot assign to field {name!r}")
        super(cls, self).__setattr__(name, value)

    return setattr_


def _frozen_delattr(cls: type[Any], names: tuple[str, ...]) -> Callable[[Any, str], None]:
    def delattr_(self: Any, name: str) -> None:
        if type(self) is cls or name in names:
            raise FrozenInstanceError(f"cannot delete field {name!r}")
        super(cls, self).__delattr__(name)

    return delattr_


def _text_signature(own: Sequence[Field[Any]]) -> str:
    """`(a: 'float', b: 'int' = 0, c: dict = <factory>)`: the text dataclasses puts in the docstring of a
    class without one (str(inspect.signature(cls)) without the return annotation)."""
    shown = []
    for f in own:
        text = f"{f.name}: {inspect.formatannotation(f.type)}"
        if f.default_factory is not MISSING:
            text += f" = {_HAS_DEFAULT_FACTORY!r}"
        elif f.default is not MISSING:
            text += f" = {f.default!r}"
        shown.append(text)
    return f"({', '.join(shown)})"
