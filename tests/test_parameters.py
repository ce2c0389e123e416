"""OpenSCENARIO parameter declarations, references and expressions."""

from __future__ import annotations

from pathlib import Path

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


@pytest.mark.parametrize(
    ("expression", "expected"),
    [
        ("${10**10**10}", "out of range"),
        ("${2 ** 1000000}", "out of range"),
        ("${9e308*10}", "not a finite number"),
        ("${1e999}", "not a finite number"),
        ("${pow(10, 400)}", "out of range"),
        ("${(-8) ** 0.5}", "math domain error"),
        ("${" + "9" * 900 + "}", "out of range"),
        ("${" + "(" * 600 + "1" + ")" * 600 + "}", "longer than"),
    ],
)
def test_hostile_expressions_fail_fast_with_a_short_message(expression: str, expected: str) -> None:
    import time

    started = time.monotonic()
    with pytest.raises(ParameterError, match=expected) as info:
        resolve(expression, {})
    assert time.monotonic() - started < 1.0
    assert len(str(info.value)) < 300  # the expression is shortened, never echoed whole


def test_integer_powers_stay_exact_while_in_range() -> None:
    assert resolve("${2 ** 62}", {}) == str(2**62)
    assert resolve("${3 ** 39}", {}) == str(3**39)
    assert resolve("${2 ** -1}", {}) == "0.5"
    assert resolve("${(-1) ** 1000001}", {}) == "-1"


def test_declared_values_must_be_finite() -> None:
    with pytest.raises(ParameterError, match=r"'X' \(double\).*finite"):
        declare([Declaration("X", "double", "inf")], {})
    with pytest.raises(ParameterError, match=r"'N' \(integer\).*finite"):
        declare([Declaration("N", "integer", "nan")], {})


def test_an_integer_parameter_with_a_decimal_value_is_read_as_the_number_with_one_warning(
    tmp_path: Path,
) -> None:
    """Generators write `parameterType="integer" value="330.91…"` (used as a position): esmini reads the
    number, so the engine does, with one warning naming the file and the parameter; the strict schema check
    (`carlos validate --schema`) still reports it."""
    from typer.testing import CliRunner

    from simcore.cli_app import app
    from simcore.scenario.xosc import load_scenario
    from tests.xosc_fixtures import openscenario, private_actions, scenario_object, vehicle, write_scenario

    text = openscenario(
        minor=1,
        parameters='<ParameterDeclarations><ParameterDeclaration name="StartX" parameterType="integer" '
        'value="3.91248879161475"/></ParameterDeclarations>',
        entities=scenario_object("Car", vehicle(z=0.8, width=2, max_speed=50, track_width=1.8)),
        init=private_actions(
            "Car",
            '<PrivateAction><TeleportAction><Position><WorldPosition x="$StartX" y="0"/></Position>'
            "</TeleportAction></PrivateAction>",
        ),
    )
    path = write_scenario(tmp_path, text, "generated.xosc")
    scenario = load_scenario(path, {})
    assert scenario.parameters["StartX"] == pytest.approx(3.91248879161475)
    warnings = [w for w in scenario.warnings if "StartX" in w]
    assert len(warnings) == 1
    assert str(path) in warnings[0] and "not an integer" in warnings[0]
    done = CliRunner().invoke(app, ["validate", "--schema", str(path)])
    assert done.exit_code != 0
    assert "StartX" in done.output and "not an integer" in done.output
