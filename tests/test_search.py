"""spec.search: adaptive search in rounds (optuna) through the sweep pipeline, on the real cut-in scenario."""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import yaml

from simcore.executor import Events, execute
from simcore.manifest import load_manifest
from simcore.search.driver import run_search
from simcore.search.objective import margin
from simcore.search.space import declarations, dimensions
from simcore.spec import CriterionModel, Search

ROOT = Path(__file__).resolve().parents[1]
CUT_IN = ROOT / "examples" / "scenarios" / "cut-in.xosc"


def _manifest(tmp_path: Path, search: dict[str, Any], *, max_seconds: float = 45, name: str = "s") -> Path:
    document = {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name},
        "spec": {
            "scenarios": [
                {"name": "cut-in", "openscenario": str(CUT_IN), "parameters": {"AdversaryEndSpeed": 5.0}}
            ],
            "search": search,
            "evaluation": {"criteria": ["collision == 0", "minTimeToCollision >= 1.0"]},
            "simulation": {"maxSeconds": max_seconds},
            "recording": {"enabled": False},
        },
    }
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


SPACE = [
    {"name": "CutInGap", "min": 0.5, "max": 20.0},
    {"name": "AdversaryDeceleration", "min": 1.0, "max": 9.0},
    {"name": "LaneChangeTime", "min": 1.0, "max": 4.0},
]


def _search(manifest: Path, out: Path, **kwargs: Any) -> Any:
    run = load_manifest(manifest)
    return run_search(
        run, base_dir=manifest.parent, scenario_file=CUT_IN, output_url=f"file://{out}", parallel=2, **kwargs
    )


def _points(document: dict[str, Any]) -> list[tuple[int, dict[str, Any], str]]:
    return [(p["index"], p["parameters"], p["status"]) for p in document["points"]]


def test_margin_is_the_smallest_distance_to_violating_a_required_criterion() -> None:
    criteria = [
        CriterionModel(metric="collision", operator="==", value=0),
        CriterionModel(metric="minTimeToCollision", operator=">=", value=1.0),
        CriterionModel(metric="maxDeceleration", operator="<", value=5.0, optional=True),
    ]
    assert margin(criteria, {"collision": 0.0, "minTimeToCollision": 3.5, "maxDeceleration": 9}) == 2.5
    assert margin(criteria, {"collision": 1.0, "minTimeToCollision": 0.5}) == -1.0
    assert margin(criteria, {"collision": 0.0, "minTimeToCollision": 0.25}) == -0.75
    assert margin(criteria, {"collision": 0.0}) == -1.0  # absent metric: violated by 1


def test_default_space_from_the_declarations_value_constraints() -> None:
    root = ET.fromstring(
        """<OpenSCENARIO><ParameterDeclarations>
        <ParameterDeclaration name="Gap" parameterType="double" value="5">
          <ConstraintGroup><ValueConstraint rule="greaterOrEqual" value="1"/>
          <ValueConstraint rule="lessThan" value="30"/></ConstraintGroup></ParameterDeclaration>
        <ParameterDeclaration name="Lanes" parameterType="int" value="2">
          <ConstraintGroup><ValueConstraint rule="greaterThan" value="0"/>
          <ValueConstraint rule="lessOrEqual" value="4"/></ConstraintGroup></ParameterDeclaration>
        <ParameterDeclaration name="Free" parameterType="double" value="1"/>
        </ParameterDeclarations></OpenSCENARIO>"""
    )
    declared = declarations(root)
    space = dimensions(Search(), declared, source="x.xosc")
    assert [(d.name, d.low, d.high, d.integer) for d in space] == [
        ("Gap", 1, 30, False),
        ("Lanes", 0, 4, True),
    ]
    listed = dimensions(
        Search.model_validate({"parameters": [{"name": "Gap", "max": 10}]}), declared, source="x"
    )
    assert [(d.low, d.high) for d in listed] == [(1, 10)]


@pytest.mark.parametrize(
    ("search", "message"),
    [
        ({"parameters": [{"name": "CutInGap", "min": 5, "max": 5}]}, "is empty"),
        ({"parameters": [{"name": "NoSuchParameter", "min": 0, "max": 1}]}, "NoSuchParameter"),
        ({"parameters": SPACE, "objective": {"metric": "minTimeToColision"}}, "unknown metric"),
        ({"parameters": [{"name": "StopDelay"}]}, "has no range"),
    ],
)
def test_bad_search_specs_are_bad_input(tmp_path: Path, search: dict[str, Any], message: str) -> None:
    manifest = _manifest(tmp_path, search)
    result = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "validate", str(manifest)],
        capture_output=True,
        text=True,
        check=False,
        env={"COLUMNS": "300", "PATH": ""},
    )
    assert result.returncode == 2, result.stderr
    assert message in result.stderr and "spec.search" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.slow
def test_search_is_deterministic_and_resumes_between_and_within_rounds(tmp_path: Path) -> None:
    search = {"parameters": SPACE, "strategy": "tpe", "budget": 8, "batchSize": 4, "seed": 3}
    manifest = _manifest(tmp_path, search, max_seconds=4)
    whole = _search(manifest, tmp_path / "a").document
    assert len(whole["points"]) == 8 and [r["runs"] for r in whole["rounds"]] == [4, 4]
    assert _search(manifest, tmp_path / "b").document["points"] == whole["points"]

    # killed between rounds: round 0 is stored, round 1 runs on resume
    def stop_after_first(document: dict[str, Any]) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _search(manifest, tmp_path / "c", on_round=stop_after_first)
    state = json.loads((tmp_path / "c" / "s" / "search" / "state.json").read_text())
    assert len(state["points"]) == 4
    assert _points(_search(manifest, tmp_path / "c").document) == _points(whole)

    # killed mid-round: two runs of round 1 finished; they are kept and the round asks the same points
    finished: list[int] = []

    def stop_mid_round(outcome: Any) -> None:
        finished.append(outcome.index)
        if len(finished) == 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _search(manifest, tmp_path / "d", events=Events(on_done=stop_mid_round))
    kept = sorted(int(p.parent.name) for p in (tmp_path / "d" / "s").glob("*/summary.json"))
    assert len(kept) >= 6
    resumed = _search(manifest, tmp_path / "d")
    assert resumed.document["points"] == whole["points"]
    assert resumed.run.summary["counts"]["total"] == 8


def test_failing_points_export_reproduces_their_verdict_when_run_alone(tmp_path: Path) -> None:
    hard = [
        {"name": "CutInGap", "min": 0.5, "max": 3.0},
        {"name": "AdversaryDeceleration", "min": 4.0, "max": 9.0},
    ]
    manifest = _manifest(tmp_path, {"parameters": hard, "strategy": "lhs", "budget": 4, "batchSize": 4})
    document = yaml.safe_load(manifest.read_text())
    fixed = {"EgoSpeed": 30.0, "AdversarySpeed": 31.0, "LaneChangeTime": 1.0}
    document["spec"]["scenarios"][0]["parameters"].update(fixed)
    manifest.write_text(yaml.safe_dump(document))
    result = _search(manifest, tmp_path / "out")
    document = result.document
    failing = document["failing"]
    assert failing, document["points"]
    assert document["verdict"] == "failed" and result.run.exit_code == 1
    saved = json.loads((tmp_path / "out" / "s" / "search.json").read_text())
    assert saved["failing"] == failing and saved["failureShare"]["samples"] == 4
    exported = tmp_path / "out" / "s" / "search" / "failing.xosc"
    suite = yaml.safe_load(manifest.read_text())
    del suite["spec"]["search"]
    suite["metadata"]["name"] = "regression"
    suite["spec"]["sweep"] = {"distribution": str(exported)}
    regression = tmp_path / "regression.yaml"
    regression.write_text(yaml.safe_dump(suite))
    rerun = execute(
        load_manifest(regression), base_dir=tmp_path, output_url=f"file://{tmp_path / 'out'}", parallel=2
    )
    assert len(rerun.outcomes) == len(failing)
    assert all(o["status"] == "failed" for o in rerun.outcomes.values())
    by_index = {p["index"]: p for p in document["points"]}
    for k, index in enumerate(failing):
        assert {
            n: float(v)
            for n, v in rerun.outcomes[k]["parameters"].items()
            if n in by_index[index]["parameters"]
        } == by_index[index]["parameters"]


def _optimise(strategy: str, seed: int) -> list[dict[str, Any]]:
    """Three rounds of 8 asks against a known loss, reloading the journal study each round."""
    from simcore.search.optimizer import Study
    from simcore.search.space import Dimension

    space = [Dimension("x", 0.0, 1.0), Dimension("n", 0, 5, integer=True), Dimension("c", choices=("a", "b"))]
    log: list[dict[str, Any]] = []
    asked: list[dict[str, Any]] = []
    for round_number in range(3):
        study = Study(log, strategy, seed, round_number, startup=8)
        points = study.ask(space, 8)
        for position, point in enumerate(points):
            study.tell(position, (point["x"] - 0.2) ** 2 + point["n"] + (point["c"] == "b"))
        asked.extend(points)
        assert study.completed() == 8 * (round_number + 1)
    return asked


@pytest.mark.parametrize("strategy", ["random", "lhs", "tpe", "cmaes", "boundary"])
def test_every_strategy_asks_valid_points_deterministically(strategy: str) -> None:
    first = _optimise(strategy, 7)
    assert first == _optimise(strategy, 7)
    assert first != _optimise(strategy, 8)
    assert len({json.dumps(p, sort_keys=True) for p in first}) > 20  # no round repeats an earlier one
    for point in first:
        assert 0 <= point["x"] <= 1 and point["n"] in range(6) and point["c"] in ("a", "b")


def test_strategy_gp_without_pytorch_is_bad_input() -> None:
    from simcore.errors import BadInput
    from simcore.search.optimizer import check_strategy

    pytest.importorskip("optuna")
    try:
        import torch  # noqa: F401
    except ImportError:
        with pytest.raises(BadInput, match="PyTorch"):
            check_strategy("gp")
    else:
        check_strategy("gp")


@pytest.mark.slow
def test_carlos_run_of_a_search_prints_its_rounds_and_exit_code(tmp_path: Path) -> None:
    search = {"parameters": SPACE, "strategy": "random", "budget": 4, "batchSize": 2, "seed": 1}
    manifest = _manifest(tmp_path, search, max_seconds=3)
    command = [
        sys.executable,
        "-m",
        "simcore.cli",
        "run",
        str(manifest),
        "-o",
        f"file://{tmp_path}/out",
        "-j",
        "2",
    ]
    result = subprocess.run(command, capture_output=True, text=True, check=False, cwd=ROOT)
    assert result.returncode == 1, (
        result.stderr
    )  # 3 s ends before Ego closes in: minTimeToCollision is absent, every run fails
    assert "round 1: 4 runs" in result.stderr and "search: 4 runs in 2 rounds · 4 failing" in result.stdout
    assert (
        "(0 resumed)" in result.stdout
    )  # a first search resumed nothing (each round resumes the ones before)
    document = json.loads((tmp_path / "out" / "s" / "search.json").read_text())
    assert [p["index"] for p in document["points"]] == [0, 1, 2, 3]
    assert (tmp_path / "out" / "s" / "search" / "failing.xosc").is_file()
    again = subprocess.run([*command, "--index", "1"], capture_output=True, text=True, check=False, cwd=ROOT)
    assert again.returncode == 2 and "--index" in again.stderr
