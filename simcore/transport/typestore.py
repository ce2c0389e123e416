"""CARLOS' ROS 2 type store, built type by type as the types are first used.

The definitions (:data:`simcore.transport.msgdefs.FIELDDEFS`) are rosbags' ROS 2 jazzy store plus the
`.msg` files under `simcore/transport/msg/<pkg>/` (vision_msgs, ackermann_msgs, the V2X packages). They are
generated into a plain data module by `make msgdefs` (:func:`definitions_from_sources`), and
tests/test_typestore.py fails when the module and its sources drift apart.

Why: building the whole store at import (importing rosbags' jazzy store, which imports every earlier
distribution's, and parsing 315 `.msg` files) took ~0.4 s of every `carlos run`, while a run uses ~20 types.
:class:`LazyTypestore` is a rosbags :class:`~rosbags.typesys.store.Typestore` whose `types` and `fielddefs`
generate a type (and the types it nests) on first access; membership, iteration and `len` see every
known type, so it behaves as the fully built store.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Mapping
from functools import cache
from importlib.util import module_from_spec, spec_from_loader
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Msgdef, Nodetype
from rosbags.typesys.codegen import generate_python_code
from rosbags.typesys.store import Typestore

if TYPE_CHECKING:
    from _collections_abc import dict_items, dict_keys, dict_values

    from rosbags.interfaces.typing import Typesdict

__all__ = ["MSG_DIR", "LazyTypestore", "definitions_from_sources", "module_source"]

#: Where the extra `.msg` definitions live: `msg/<package>/<Type>.msg`.
MSG_DIR = Path(__file__).with_name("msg")


class _OnDemand(dict[str, Any]):
    """A dict of the store that generates a known type on its first lookup."""

    def __init__(self, store: LazyTypestore) -> None:
        super().__init__()
        self._store = store

    def __missing__(self, key: str) -> Any:
        if not self._store._load(key):
            raise KeyError(key)
        return dict.__getitem__(self, key)

    def __contains__(self, key: object) -> bool:
        return dict.__contains__(self, key) or key in self._store._known

    def get(self, key: str, default: Any = None) -> Any:
        return self[key] if key in self else default  # noqa: SIM401 - this is get()

    def __iter__(self) -> Iterator[str]:
        self._store._load_all()
        return dict.__iter__(self)

    def __len__(self) -> int:
        self._store._load_all()
        return dict.__len__(self)

    def keys(self) -> dict_keys[str, Any]:
        self._store._load_all()
        return dict.keys(self)

    def values(self) -> dict_values[str, Any]:
        self._store._load_all()
        return dict.values(self)

    def items(self) -> dict_items[str, Any]:
        self._store._load_all()
        return dict.items(self)


class _Msgdefs(dict[str, Msgdef[object]]):
    """The store's Msgdefs by type name, each made on its first lookup."""

    def __init__(self, store: LazyTypestore) -> None:
        super().__init__()
        self._store = store

    def __missing__(self, typename: str) -> Msgdef[object]:
        msgdef = self[typename] = self._store._new_msgdef(typename)
        return msgdef


def _nested(desc: Any) -> Iterator[str]:
    """The type names a field description refers to (NAME, or the element of an ARRAY/SEQUENCE)."""
    kind, payload = desc
    if kind == Nodetype.NAME:
        yield payload
    elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        yield from _nested(payload[0])


@cache
def _generators() -> dict[str, Any]:
    """Msgdef field → function(entries, typename, store) that generates it (rosbags' code generators, as in
    `Typestore.get_msgdef`)."""
    from rosbags.serde import cdr, ros1

    return {
        "serialize_cdr_le": lambda e, _n, st: cdr.generate_serialize_cdr(e, st, "le"),
        "serialize_cdr_be": lambda e, _n, st: cdr.generate_serialize_cdr(e, st, "be"),
        "deserialize_cdr_le": lambda e, _n, st: cdr.generate_deserialize_cdr(e, st, "le"),
        "deserialize_cdr_be": lambda e, _n, st: cdr.generate_deserialize_cdr(e, st, "be"),
        "serialize_ros1": lambda e, _n, st: ros1.generate_serialize_ros1(e, st),
        "deserialize_ros1": lambda e, _n, st: ros1.generate_deserialize_ros1(e, st),
        "getsize_ros1_to_cdr": lambda e, n, st: ros1.generate_ros1_to_cdr(e, n, st, copy=False),
        "ros1_to_cdr": lambda e, n, st: ros1.generate_ros1_to_cdr(e, n, st, copy=True),
        "getsize_cdr_to_ros1": lambda e, n, st: ros1.generate_cdr_to_ros1(e, n, st, copy=False),
        "cdr_to_ros1": lambda e, n, st: ros1.generate_cdr_to_ros1(e, n, st, copy=True),
    }


class _LazyMsgdef(Msgdef[object]):
    """rosbags' Msgdef whose (de)serialisers are generated when first used: a recording needs the CDR
    serialiser of ~20 types, not the thirteen functions rosbags generates for each."""

    _store: LazyTypestore

    def __getattr__(self, field: str) -> Any:
        if field in ("size_ros1", "getsize_ros1"):
            from rosbags.serde.ros1 import generate_getsize_ros1

            getsize, size = generate_getsize_ros1(self.fields, self._store)
            object.__setattr__(self, "getsize_ros1", getsize)
            object.__setattr__(self, "size_ros1", size)
            return getattr(self, field)
        generate = _generators().get(field)
        if generate is None or field.startswith("__"):
            raise AttributeError(field)
        function = generate(self.fields, self.name, self._store)
        object.__setattr__(self, field, function)
        return function


class LazyTypestore(Typestore):
    """A rosbags type store over `definitions` that generates each type's class when it is first used."""

    def __init__(self, definitions: Mapping[str, Any]) -> None:
        """`definitions`: type name → (consts, fields), in rosbags' form or compact (msgdefs.FIELDDEFS)."""
        super().__init__()
        self._known = definitions
        self._complete = False
        self.types = _OnDemand(self)
        self.fielddefs = _OnDemand(self)
        self.cache: dict[str, Msgdef[object]] = _Msgdefs(self)
        object.__setattr__(self, "get_msgdef", self.cache.__getitem__)  # see get_msgdef

    def _load(self, typename: str) -> bool:
        """Generate `typename` and the known types it nests that are not generated yet; False if unknown."""
        if typename not in self._known:
            return False
        wanted: Typesdict = {}
        todo = [typename]
        while todo:
            name = todo.pop()
            if name in wanted or dict.__contains__(self.fielddefs, name):
                continue
            wanted[name] = definition = _restore(self._known[name])
            todo.extend(n for _, desc in definition[1] for n in _nested(desc))
        self._add(wanted)
        return True

    def _load_all(self) -> None:
        """Generate every known type; both dicts then list the known types in the definitions' order (then
        any registered later), so iterating the store is the same whatever was used before."""
        if self._complete:
            return
        missing = {n: _restore(d) for n, d in self._known.items() if not dict.__contains__(self.fielddefs, n)}
        if missing:
            self._add(missing)
        tables: tuple[dict[str, Any], ...] = (self.fielddefs, self.types)
        for table in tables:
            entries: dict[str, Any] = dict(dict.items(table))
            dict.clear(table)
            dict.update(table, {n: entries.pop(n) for n in self._known})
            dict.update(table, entries)
        self._complete = True

    def _add(self, typs: Typesdict) -> None:
        """Generate the classes of `typs` (rosbags' code generator) and store them, as `Typestore.register`."""
        name = "rosbags.usertypes"
        spec = spec_from_loader(name, loader=None)
        assert spec is not None
        module = module_from_spec(spec)
        sys.modules[name] = module
        exec(generate_python_code(typs), module.__dict__)
        generated: Typesdict = module.FIELDDEFS
        for typename in typs:
            dict.__setitem__(self.fielddefs, typename, generated[typename][:2])
            dict.__setitem__(self.types, typename, getattr(module, typename.replace("/", "__")))

    def get_msgdef(self, typename: str) -> Msgdef[object]:
        """As `Typestore.get_msgdef`, with each (de)serialiser generated when first used. (An instance's
        `get_msgdef` is its cache's `__getitem__`: rosbags' generated serialisers look up the Msgdef of every
        nested type, a dozen lookups per message, so a lookup is a dict's, without a Python call.)"""
        return self.cache[typename]

    def _new_msgdef(self, typename: str) -> Msgdef[object]:
        """The Msgdef of `typename` (KeyError for an unknown type), its (de)serialisers generated lazily."""
        from rosbags.serde.cdr import generate_getsize_cdr
        from rosbags.typesys.base import normalize_fieldname

        entries = [(normalize_fieldname(name), desc) for name, desc in self.fielddefs[typename][1]]
        msgdef = object.__new__(_LazyMsgdef)
        for field, value in (("name", typename), ("fields", entries), ("cls", self.types[typename])):
            object.__setattr__(msgdef, field, value)
        object.__setattr__(msgdef, "_store", self)
        getsize, size = generate_getsize_cdr(entries, self)
        object.__setattr__(msgdef, "getsize_cdr", getsize)
        object.__setattr__(msgdef, "size_cdr", size)
        return msgdef

    def register(self, typs: Typesdict) -> None:
        """Add types (as `Typestore.register`): a known name must have the same fields, else TypesysError."""
        from rosbags.typesys.base import TypesysError

        new: Typesdict = {}
        for typename, (consts, fields) in typs.items():
            have = self.fielddefs.get(typename)
            if have is None:
                new[typename] = (consts, fields)
            elif [(f[0].lower(), f[1]) for f in have[1]] != [(f[0].lower(), f[1]) for f in fields]:
                raise TypesysError(f"Type {typename!r} is already present with different definition.")
        if new:
            # a new type may nest known ones: generate those first so the code generator finds them
            for _, fields in new.values():
                for _, desc in fields:
                    for nested in _nested(desc):
                        if nested not in new:
                            self._load(nested)
            self._add(new)


# --- the generated definitions module ------------------------------------------------------------------


def definitions_from_sources() -> Typesdict:
    """The definitions from their sources: rosbags' ROS 2 jazzy store, then every `msg/<pkg>/<Type>.msg`
    (sorted by path). Slow (~0.4 s): for `make msgdefs` and the drift test only."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    definitions: Typesdict = dict(get_typestore(Stores.ROS2_JAZZY).fielddefs)
    paths = sorted(MSG_DIR.glob("*/*.msg"))
    if not paths:
        raise RuntimeError(f"no message definitions under {MSG_DIR}")
    for path in paths:
        typename = f"{path.parent.name}/msg/{path.stem}"
        for name, (consts, fields) in get_types_from_msg(path.read_text(encoding="utf-8"), typename).items():
            if name in definitions and definitions[name][1] != fields:
                raise RuntimeError(f"{path}: {name} differs from the jazzy store's definition")
            definitions[name] = (consts, fields)
    return definitions


def _compact(value: Any) -> Any:
    """`value` with every list a tuple and every Nodetype its int: all constants, so the generated module
    loads from its bytecode without building anything (:func:`_restore` undoes it)."""
    if isinstance(value, list | tuple):
        return tuple(_compact(v) for v in value)
    if isinstance(value, Nodetype):
        return int(value)
    return value


def _restore_desc(desc: Any) -> Any:
    kind, payload = desc
    kind = Nodetype(kind)
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return (kind, (_restore_desc(payload[0]), payload[1]))
    return (kind, payload)


def _restore(definition: Any) -> Any:
    """A compact definition in rosbags' form: ([consts], [(name, (Nodetype, payload))])."""
    consts, fields = definition
    return ([tuple(c) for c in consts], [(name, _restore_desc(desc)) for name, desc in fields])


def module_source(definitions: Typesdict) -> str:
    """The text of `simcore/transport/msgdefs.py` for `definitions`."""
    lines = [
        '"""GENERATED by `make msgdefs` (simcore.transport.typestore.module_source): do not edit.',
        "",
        "The ROS 2 message definitions of CARLOS' type store: rosbags' ROS 2 jazzy store and",
        "simcore/transport/msg/<pkg>/<Type>.msg, as (constants, fields) per type name.",
        '"""',
        "",
        "# ruff: noqa",
        "# fmt: off",
        "# (consts, fields) as nested tuples, node types as ints (rosbags.interfaces.Nodetype):",
        "# simcore.transport.typestore restores rosbags' form per type when the type is first used.",
        "FIELDDEFS = {",
    ]
    lines.extend(f"    {name!r}: {_compact(definition)!r}," for name, definition in definitions.items())
    lines.append("}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.stdout.write(module_source(definitions_from_sources()))
