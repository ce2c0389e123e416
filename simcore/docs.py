"""The SimulationRun field reference (docs/simulationrun.md), generated from the spec models.

`carlos docs > docs/simulationrun.md` writes it; a test fails when the checked-in file drifts from the models.
"""

from __future__ import annotations

import types
import typing
from typing import Any, Union, get_args, get_origin

from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from simcore.spec import SimulationRun


def _type_name(annotation: Any) -> str:
    origin = get_origin(annotation)
    args = get_args(annotation)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin in (Union, types.UnionType):
        names = [_type_name(a) for a in args if a is not type(None)]
        return " \\| ".join(dict.fromkeys(names))
    if origin is typing.Literal:
        return " \\| ".join(f"`{a}`" for a in args)
    if origin in (list, tuple):
        return f"list of {_type_name(args[0])}" if args else "list"
    if origin is dict:
        return f"map of {_type_name(args[0])} → {_type_name(args[1])}"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation.__name__
    if annotation is Any:
        return "any"
    return {str: "string", int: "integer", float: "number", bool: "boolean"}.get(annotation, str(annotation))


def _models(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    out: list[type[BaseModel]] = []
    for arg in get_args(annotation):
        out.extend(_models(arg))
    return out


def _default(field: FieldInfo) -> str:
    if field.is_required():
        return "required"
    if field.default_factory is not None:
        return ""
    if field.default is PydanticUndefined or field.default is None:
        return ""
    value = field.default
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    return f"`{value}`"


def _rows(
    model: type[BaseModel], prefix: str, rows: list[str], seen: set[tuple[type[BaseModel], str]]
) -> None:
    if (model, prefix) in seen:
        return
    seen.add((model, prefix))
    model.model_rebuild()  # the spec's models are built on first use: resolves forward references (ScenarioRef)
    for name, field in model.model_fields.items():
        alias = field.alias or name
        path = f"{prefix}.{alias}" if prefix else alias
        description = (field.description or "").replace("|", "\\|").replace("\n", " ")
        rows.append(f"| `{path}` | {_type_name(field.annotation)} | {_default(field)} | {description} |")
        for sub in _models(field.annotation):
            is_list = get_origin(field.annotation) is list or any(
                get_origin(a) is list for a in get_args(field.annotation)
            )
            _rows(sub, f"{path}[]" if is_list else path, rows, seen)


def reference() -> str:
    rows: list[str] = []
    _rows(SimulationRun, "", rows, set())
    return (
        "# SimulationRun reference\n\n"
        "Generated from the spec models (`simcore/spec.py`) by `carlos docs`; do not edit by hand.\n"
        "Unknown fields are rejected. `[]` marks list items.\n\n"
        "| field | type | default | description |\n|---|---|---|---|\n" + "\n".join(rows) + "\n"
    )
