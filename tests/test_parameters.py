"""OpenSCENARIO parameter declarations, references and expressions."""

from __future__ import annotations

import pytest

from simcore.scenario.parameters import Declaration, ParameterError, declare, evaluate_expression, resolve


def test_references_and_expressions() -> None:
    values = {"Speed": 20.0, "Lane": "-2", "N": 3, "On": True}
    assert resolve("$Speed", values) == "20.0"
    assert resolve("$Lane", values) == "-2"
    assert resolve("${$Speed / 3.6 * 2}", values) == repr(20.0 / 3.6 * 2)
    assert resolve("${$N * 2 + 1}", values) == "7"
    assert resolve("${-$Speed}", values) == "-20.0"
    assert resolve("${$Speed > 10 and not $On}", values) == "false"
    assert (
        resolve("${round(2.5) + floor(1.7) + ceil(1.2) + sqrt(16) + pow(2, 3)}", values) == "18.0"
    )  # round half up: 3
    assert resolve("plain", values) == "plain"


@pytest.mark.parametrize(
    "expression",
    [
        "${__import__('os').system('true')}",
        "${$Speed.real}",
        "${[1, 2]}",
        "${lambda: 1}",
        "${$Missing + 1}",
        "${1 / 0}",
    ],
)
def test_unsafe_or_bad_expressions_are_refused(expression: str) -> None:
    with pytest.raises(ParameterError):
        resolve(expression, {"Speed": 1.0})


def test_declarations_are_typed_ordered_and_overridable() -> None:
    decls = [
        Declaration("A", "double", "2"),
        Declaration("B", "double", "${$A * 2}"),
        Declaration("C", "integer", "5"),
        Declaration("D", "boolean", "true"),
    ]
    assert declare(decls, {}) == {"A": 2.0, "B": 4.0, "C": 5, "D": True}
    assert declare(decls, {}, {"A": 10}) == {"A": 10.0, "B": 20.0, "C": 5, "D": True}
    with pytest.raises(ParameterError, match="'C' \\(integer\\)"):
        declare(decls, {}, {"C": 2.5})
    with pytest.raises(ParameterError, match="not true or false"):
        declare(decls, {}, {"D": "maybe"})


def test_expression_result_types() -> None:
    assert evaluate_expression("1 + 2", {}) == 3
    assert evaluate_expression("1 / 2", {}) == 0.5
    assert evaluate_expression("2 == 2", {}) is True
