"""execution.repeat / `carlos run --repeat`: repeats innermost in the index order, their seeds, flaky points
and the determinism check in summary.json, junit.xml and report.html."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from simcore.evaluation.flaky import flag_flaky, repeat_report
from simcore.evaluation.report import junit_xml
from simcore.plan import Plan
from simcore.spec import SimulationRunSpec
from tests.test_cli import ROOT, carlos


def _plan(policy: str) -> Plan:
    return Plan(
        SimulationRunSpec.model_validate(
            {
                "scenarios": [{"name": "a", "openscenario": "x.xosc"}],
                "sweep": {"matrix": {"v": [1, 2]}, "repetitions": 2},
                "execution": {"repeat": 3, "seedPolicy": policy},
                "simulation": {"seed": 10},
            }
        )
    )


def test_repeats_are_innermost_with_the_same_seed_or_distinct_seeds() -> None:
    same, vary = _plan("same"), _plan("vary")
    assert len(same) == 2 * 2 * 3
    rows = [(p.sweep_values["v"], p.repetition, p.repeat, p.seed) for p in same]
    assert rows[:6] == [
        (1, 0, 0, 10),
        (1, 0, 1, 10),
        (1, 0, 2, 10),
        (1, 1, 0, 11),
        (1, 1, 1, 11),
        (1, 1, 2, 11),
    ]
    assert [same.point_of(i) for i in range(12)] == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]
    seeds = [p.seed for p in vary]
    assert seeds[:6] == [10, 12, 14, 11, 13, 15] and len(set(seeds[:6])) == 6
    assert [p.sweep_values for p in vary] == [p.sweep_values for p in same]


def _s(index: int, status: str, seed: int = 0) -> dict[str, object]:
    return {"index": index, "scenario": "s", "parameters": {}, "seed": seed, "status": status}


def test_a_point_whose_verdict_changes_is_flaky_and_different_messages_are_nondeterministic() -> None:
    runs = [_s(0, "passed"), _s(1, "failed"), _s(2, "passed"), _s(3, "passed")]
    report = repeat_report(runs, lambda i: i // 2, 2, {0: "a", 1: "a", 2: "b", 3: "c"})
    assert (report["points"], report["flaky"], report["determinismChecked"], report["nondeterministic"]) == (
        2,
        1,
        2,
        1,
    )
    assert [(p["indexes"], p["flaky"], p["deterministic"]) for p in report["flakyPoints"]] == [
        ([0, 1], True, True),
        ([2, 3], False, False),
    ]
    # different seeds (seedPolicy vary): determinism is not checked
    vary = repeat_report([_s(0, "passed", 1), _s(1, "passed", 2)], lambda i: 0, 2, {0: "a", 1: "b"})
    assert vary["determinismChecked"] == 0 and vary["flakyPoints"] == []
    flagged = list(flag_flaky(runs, report))
    assert [s.get("flaky") for s in flagged] == [True, True, None, None]
    cases = ET.fromstring(junit_xml("r", flagged)).iter("testcase")
    flaky = [
        c.get("name")
        for c in cases
        if c.find("properties/property[@name='flaky'][@value='true']") is not None
    ]
    assert flaky == ["s[0]", "s[1]"]


def test_carlos_run_repeat_checks_determinism_and_reports_it(tmp_path: Path) -> None:
    scenario = ROOT / "examples" / "scenarios" / "cut-in.xosc"
    manifest = tmp_path / "rep.yaml"
    manifest.write_text(
        "\n".join(
            [
                "apiVersion: carlos.dev/v1alpha1",
                "kind: SimulationRun",
                "metadata: {name: rep}",
                "spec:",
                f"  scenarios: [{{name: cut-in, openscenario: {json.dumps(str(scenario))}}}]",
                "  sweep: {matrix: {EgoSpeed: [20.0, 26.0]}}",
                "  simulation: {stepSeconds: 0.1, maxSeconds: 5, seed: 4}",
                f"  output: {{url: {json.dumps((tmp_path / 'results').as_uri())}}}",
            ]
        )
        + "\n"
    )
    done = carlos("run", manifest, "--repeat", "2", "-q", "-j", "2")
    assert done.returncode == 0, done.stderr + done.stdout
    run_dir = tmp_path / "results" / "rep"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["counts"]["total"] == 4
    assert summary["repeats"] == {
        "repeat": 2,
        "points": 2,
        "flaky": 0,
        "determinismChecked": 2,
        "nondeterministic": 0,
        "flakyPoints": [],
    }
    seeds = [json.loads((run_dir / str(i) / "summary.json").read_text())["seed"] for i in range(4)]
    assert seeds == [4, 4, 4, 4]
    assert "every point run 2 times · 0 of 2 points flaky" in (run_dir / "report.html").read_text()
    assert (
        "0 of 2 points recorded different messages with the same seed"
        in (run_dir / "report.html").read_text()
    )
