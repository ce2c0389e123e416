"""OpenSCENARIO parameters: declarations, `$name` references and `${…}` expressions.

Expressions are evaluated by walking a parsed Python AST restricted to OpenSCENARIO's expression grammar
(numbers, parameters, + - * / % **, unary minus, `not`/`and`/`or`, comparisons, round/floor/ceil/sqrt/pow/
min/max): nothing of the scenario file is ever executed.
"""

from __future__ import annotations

import ast
import math
import operator as op
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from simcore.errors import shorten

_REFERENCE = re.compile(r"^\$([A-Za-z_][A-Za-z0-9_]*)$")
_EXPRESSION = re.compile(r"^\$\{(.*)\}$", re.DOTALL)
_PARAM_IN_EXPR = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")

ParamValue = bool | int | float | str


class ParameterError(ValueError):
    """A parameter reference or expression cannot be resolved."""


# Bounds that keep evaluating an untrusted expression cheap: OpenSCENARIO values are doubles, so an integer
# beyond 2**63 or a non-finite float is out of range anyway, and `2 ** 10**10` must fail at once instead of
# computing a number with billions of digits.
MAX_EXPRESSION_CHARS = 1000
MAX_INTEGER = 2**63
SHOWN_EXPRESSION_CHARS = 80


def _in_range(value: Any) -> Any:
    """A number computed from an expression, refused when it is beyond what a double parameter can hold."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        if abs(value) > MAX_INTEGER:
            raise OverflowError("integer out of range (more than 2**63)")
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise OverflowError("result is not a finite number")
        return value
    raise TypeError(f"result {shorten(repr(value))} is not a real number")


def _power(base: Any, exponent: Any) -> Any:
    """`base ** exponent` with integers computed exactly only while the result stays in range (checked from
    the operands' sizes before computing), otherwise as doubles (which overflow at once)."""
    exact = isinstance(base, int) and isinstance(exponent, int) and exponent >= 0
    if exact and (abs(base) <= 1 or exponent * math.log2(abs(base)) <= 63):
        return base**exponent
    try:
        return math.pow(float(base), float(exponent))
    except OverflowError:
        raise OverflowError("result out of range of a double") from None


_BINARY: dict[type[ast.operator], Callable[[Any, Any], Any]] = {
    ast.Add: op.add,
    ast.Sub: op.sub,
    ast.Mult: op.mul,
    ast.Div: op.truediv,
    ast.Mod: math.fmod,
    ast.Pow: _power,
}
_COMPARE: dict[type[ast.cmpop], Callable[[Any, Any], bool]] = {
    ast.Eq: op.eq,
    ast.NotEq: op.ne,
    ast.Lt: op.lt,
    ast.LtE: op.le,
    ast.Gt: op.gt,
    ast.GtE: op.ge,
}
_FUNCTIONS: dict[str, Callable[..., float]] = {
    "round": lambda x: float(math.floor(x + 0.5)),
    "floor": math.floor,
    "ceil": math.ceil,
    "sqrt": math.sqrt,
    "pow": _power,
    "min": min,
    "max": max,
    "abs": abs,
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "asin": math.asin,
    "acos": math.acos,
    "atan": math.atan,
    "sign": lambda x: float((x > 0) - (x < 0)),
}


@dataclass(frozen=True, slots=True)
class Declaration:
    name: str
    type: str  # double, integer, unsignedInt, unsignedShort, int, string, boolean, dateTime
    value: str


def convert(value: ParamValue, type_name: str, *, name: str) -> ParamValue:
    """A value converted to its declared OpenSCENARIO type (raises ParameterError with the name)."""
    try:
        if type_name in ("double",):
            if isinstance(value, bool):
                raise ValueError("a boolean is not a number")
            return float(_in_range(float(value)))
        if type_name in ("integer", "int", "unsignedInt", "unsignedShort"):
            if isinstance(value, bool):
                raise ValueError("a boolean is not a number")
            number = _in_range(float(value))
            if number != int(number):
                raise ValueError(f"{shorten(repr(value))} is not an integer")
            if type_name.startswith("unsigned") and number < 0:
                raise ValueError(f"{shorten(repr(value))} is negative")
            return int(number)
        if type_name == "boolean":
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ("true", "1"):
                return True
            if text in ("false", "0"):
                return False
            raise ValueError(f"{shorten(repr(value))} is not true or false")
        return str(value)
    except (ValueError, OverflowError) as exc:
        raise ParameterError(f"parameter {name!r} ({type_name}): {exc}") from None


def format_value(value: ParamValue) -> str:
    """A value as OpenSCENARIO writes it in an attribute."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isfinite(value) and value == int(value) and abs(value) < 1e15:
        return repr(value)  # keep "30.0" (a double stays a double)
    return str(value)


def evaluate_expression(text: str, values: Mapping[str, ParamValue]) -> ParamValue:
    """Evaluate the inside of `${…}` with parameter values."""

    shown = shorten(text, SHOWN_EXPRESSION_CHARS)
    if len(text) > MAX_EXPRESSION_CHARS:
        raise ParameterError(
            f"expression ${{{shown}}} is longer than {MAX_EXPRESSION_CHARS} characters: split it up"
        )

    def lookup(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in values:
            raise ParameterError(f"expression ${{{shown}}}: parameter ${name} is not declared")
        return f"__p_{name}"

    source = _PARAM_IN_EXPR.sub(lookup, text)
    source = re.sub(r"\bnot\b", " not ", source)
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):  # ValueError: a literal too long
        raise ParameterError(f"expression ${{{shown}}} is not a valid OpenSCENARIO expression") from None

    def walk(node: ast.AST) -> Any:
        if isinstance(node, ast.Expression):
            return walk(node.body)
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, int | float)
            and not isinstance(node.value, bool)
        ):
            return _in_range(node.value)
        if isinstance(node, ast.Name):
            if node.id.startswith("__p_"):
                value = values[node.id[4:]]
                if isinstance(value, str):
                    try:
                        return _in_range(float(value))
                    except ValueError:
                        if value.lower() in ("true", "false"):
                            return value.lower() == "true"
                        raise ParameterError(
                            f"expression ${{{shown}}}: ${node.id[4:]} = {shorten(repr(value))} is not a number"
                        ) from None
                return value
            if node.id in ("true", "false"):
                return node.id == "true"
            if node.id in ("pi", "PI"):  # esmini's constant; not in the standard's grammar
                return math.pi
            raise ParameterError(f"expression ${{{shown}}}: unknown name {node.id!r}")
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return _in_range(_BINARY[type(node.op)](walk(node.left), walk(node.right)))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -walk(node.operand)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return not walk(node.operand)
        if isinstance(node, ast.BoolOp):
            items = [bool(walk(v)) for v in node.values]
            return all(items) if isinstance(node.op, ast.And) else any(items)
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _COMPARE:
            return _COMPARE[type(node.ops[0])](walk(node.left), walk(node.comparators[0]))
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in _FUNCTIONS
            and not node.keywords
        ):
            return _in_range(_FUNCTIONS[node.func.id](*(walk(a) for a in node.args)))
        raise ParameterError(f"expression ${{{shown}}}: unsupported element {type(node).__name__}")

    try:
        result = _in_range(walk(tree))
    except ZeroDivisionError:
        raise ParameterError(f"expression ${{{shown}}}: division by zero") from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise ParameterError(f"expression ${{{shown}}}: {shorten(str(exc))}") from None
    except RecursionError:
        raise ParameterError(f"expression ${{{shown}}} is nested too deeply") from None
    if isinstance(result, bool | int):
        return result
    return float(result)


def resolve(text: str, values: Mapping[str, ParamValue]) -> str:
    """An attribute value with a `$name` reference or a `${…}` expression replaced by its value."""
    if not text or text[0] != "$":
        return text
    match = _REFERENCE.match(text)
    if match:
        name = match.group(1)
        if name not in values:
            raise ParameterError(f"parameter ${name} is not declared")
        return format_value(values[name])
    match = _EXPRESSION.match(text)
    if match:
        return format_value(evaluate_expression(match.group(1), values))
    return text


def declare(
    declarations: list[Declaration],
    outer: Mapping[str, ParamValue],
    overrides: Mapping[str, ParamValue] | None = None,
) -> dict[str, ParamValue]:
    """Values of one ParameterDeclarations scope: each declaration in order (a later one may refer to an
    earlier one or to the outer scope), an override replacing the declared default."""
    values: dict[str, ParamValue] = dict(outer)
    for declaration in declarations:
        if overrides is not None and declaration.name in overrides:
            raw: ParamValue = overrides[declaration.name]
        else:
            raw = resolve(declaration.value, values)
        values[declaration.name] = convert(raw, declaration.type, name=declaration.name)
    return values
