"""The spec models, manifest loading and the lazy index → run mapping."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from simcore.errors import BadInput
from simcore.manifest import load_manifest, parse_manifest
from simcore.plan import Plan, permutation
from simcore.spec import SimulationRunSpec


def _spec(**extra: object) -> SimulationRunSpec:
    return SimulationRunSpec.model_validate({"scenarios": [{"name": "a", "openscenario": "a.xosc"}], **extra})


def test_permutation_is_mixed_radix_last_key_fastest() -> None:
    matrix = [("a", [1, 2]), ("b", ["x", "y", "z"])]
    assert [permutation(matrix, k) for k in range(6)] == [
        {"a": 1, "b": "x"},
        {"a": 1, "b": "y"},
        {"a": 1, "b": "z"},
        {"a": 2, "b": "x"},
        {"a": 2, "b": "y"},
        {"a": 2, "b": "z"},
    ]
    with pytest.raises(IndexError):
        permutation(matrix, 6)


@given(
    st.lists(st.integers(min_value=1, max_value=4), min_size=0, max_size=4),
    st.integers(1, 3),
    st.integers(1, 3),
)
def test_plan_enumerates_scenarios_then_product_then_repetitions(
    radices: list[int], scenarios: int, reps: int
) -> None:
    matrix = {f"p{i}": list(range(n)) for i, n in enumerate(radices)}
    spec = SimulationRunSpec.model_validate(
        {
            "scenarios": [{"name": f"s{i}", "openscenario": "x.xosc"} for i in range(scenarios)],
            "sweep": {"matrix": matrix, "repetitions": reps},
            "simulation": {"seed": 7},
        }
    )
    expected = [
        (f"s{s}", dict(zip(matrix, values, strict=True)), 7 + r)
        for s in range(scenarios)
        for values in itertools.product(*matrix.values())
        for r in range(reps)
    ]
    plan = Plan(spec)
    assert len(plan) == len(expected)
    assert [(p.scenario.name, p.sweep_values, p.seed) for p in plan] == expected
    assert [p.index for p in plan] == list(range(len(expected)))


def test_large_sweep_is_never_materialised() -> None:
    spec = _spec(sweep={"matrix": {"a": list(range(50)), "b": list(range(40)), "c": list(range(25))}})
    plan = Plan(spec)
    assert len(plan) == 50_000
    assert plan[49_999].sweep_values == {"a": 49, "b": 39, "c": 24}
    assert plan[12_345].sweep_values == {"a": 12, "b": 13, "c": 20}  # 12345 = 12*1000 + 13*25 + 20
    with pytest.raises(IndexError):
        plan[50_000]


def test_parameter_precedence_spec_scenario_matrix() -> None:
    spec = SimulationRunSpec.model_validate(
        {
            "scenarios": [{"name": "a", "openscenario": "a.xosc", "parameters": {"X": 2, "Y": 2}}],
            "parameters": {"X": 1, "Y": 1, "Z": 1},
            "sweep": {"matrix": {"Y": [3]}},
        }
    )
    assert Plan(spec)[0].parameters == {"X": 2, "Y": 3, "Z": 1}


def test_yaml_types_are_kept() -> None:
    spec = _spec(parameters={"b": True, "i": 3, "f": 2.5, "s": "-2"})
    assert spec.parameters == {"b": True, "i": 3, "f": 2.5, "s": "-2"}
    assert [type(v) for v in spec.parameters.values()] == [bool, int, float, str]


def _manifest(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run.yaml"
    path.write_text(text)
    return path


GOOD = """
apiVersion: carlos.dev/v1alpha1
kind: SimulationRun
metadata: {name: demo}
spec:
  scenarios:
    - {name: a, openscenario: a.xosc}
  evaluation:
    criteria: ["minDistance >= 2", {metric: collision, operator: "==", value: 0, optional: true}]
"""


def test_manifest_loads_with_criteria_in_both_forms(tmp_path: Path) -> None:
    run = load_manifest(_manifest(tmp_path, GOOD))
    first, second = run.spec.evaluation.criteria
    assert (first.metric, first.operator, first.value, first.label) == (
        "minDistance",
        ">=",
        2.0,
        "minDistance >= 2",
    )
    assert (second.metric, second.optional) == ("collision", True)
    assert run.spec.output.url == "file://./results"
    assert run.spec.simulation.step_seconds == 0.05


def test_unknown_field_is_named_with_its_path(tmp_path: Path) -> None:
    bad = GOOD.replace("{name: a, openscenario: a.xosc}", "{name: a, openscenario: a.xosc, optinal: true}")
    with pytest.raises(BadInput) as info:
        load_manifest(_manifest(tmp_path, bad))
    message = str(info.value)
    assert "run.yaml" in message
    assert "spec.scenarios[0].optinal: unknown field" in message


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("apiVersion: [", "invalid YAML at line 1"),
        ("- a\n- b\n", "must be a YAML mapping"),
        (GOOD.replace("minDistance >= 2", "minDistance >> 2"), "is not a criterion"),
        (GOOD.replace("name: a,", "name: A_b,"), "not a DNS-1123 label"),
        (GOOD.replace("carlos.dev/v1alpha1", "carlos.dev/v1"), "apiVersion"),
        (GOOD + "  sensors: [{type: lidar}]\n", "spec.sensors"),
        (
            GOOD.replace("{name: a, openscenario: a.xosc}", "{name: a}"),
            "exactly one of 'openscenario' and 'configMapRef'",
        ),
        (
            GOOD.replace(
                "- {name: a, openscenario: a.xosc}",
                "- {name: a, openscenario: a.xosc}\n    - {name: a, openscenario: b.xosc}",
            ),
            "used twice",
        ),
        (
            GOOD + "  systemUnderTest: {image: x, env: [{name: ROS_DOMAIN_ID, value: '7'}]}\n",
            "ROS_DOMAIN_ID is set by CARLOS",
        ),
        (
            GOOD
            + "  systemUnderTest: {image: x, env: [{name: K, value: a, secretKeyRef: {name: s, key: k}}]}\n",
            "spec.systemUnderTest.env[0]: K: set exactly one of 'value' and 'secretKeyRef'",
        ),
        (
            GOOD + "  systemUnderTest: {image: x, env: [{name: K, value: a}, {name: K, value: b}]}\n",
            "env names must be unique: K given more than once",
        ),
    ],
)
def test_bad_manifests_give_one_clear_message(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(BadInput) as info:
        load_manifest(_manifest(tmp_path, text))
    assert expected in str(info.value)
    assert "Traceback" not in str(info.value)


def test_missing_manifest_file(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="file not found"):
        load_manifest(tmp_path / "nope.yaml")


def test_name_defaults_to_file_name(tmp_path: Path) -> None:
    path = tmp_path / "My Run.yaml"
    path.write_text(GOOD.replace("metadata: {name: demo}", "metadata: {}"))
    assert load_manifest(path).name == "my-run"


def test_spec_is_immutable_and_round_trips_camel_case() -> None:
    run = parse_manifest(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": "x"},
            "spec": {
                "scenarios": [{"name": "a", "openscenario": "a.xosc"}],
                "simulation": {"stepSeconds": 0.1},
            },
        },
        source="inline",
    )
    dumped = run.model_dump(mode="json", by_alias=True, exclude_none=True)
    assert dumped["spec"]["simulation"]["stepSeconds"] == 0.1
    assert parse_manifest(dumped, source="again") == run
    with pytest.raises(ValidationError):
        run.spec.simulation.step_seconds = 1.0  # type: ignore[misc]


def test_selected_indexes_run_the_whole_sweeps_points_in_their_order() -> None:
    body = {
        "scenarios": [{"name": "a", "openscenario": "a.xosc"}, {"name": "b", "openscenario": "b.xosc"}],
        "sweep": {"matrix": {"v": [1, 2, 3]}, "repetitions": 2},
        "simulation": {"seed": 7},
    }
    whole = Plan(SimulationRunSpec.model_validate(body))
    chosen = [11, 0, 5]
    part = Plan(SimulationRunSpec.model_validate({**body, "sweep": {**body["sweep"], "indexes": chosen}}))
    assert len(part) == 3 and len(whole) == 12
    for k, index in enumerate(chosen):
        assert part[k].index == k
        assert (part[k].scenario.name, part[k].parameters, part[k].seed) == (
            whole[index].scenario.name,
            whole[index].parameters,
            whole[index].seed,
        )
    with pytest.raises(BadInput, match="index 12 is out of range"):
        Plan(SimulationRunSpec.model_validate({**body, "sweep": {**body["sweep"], "indexes": [12]}}))
