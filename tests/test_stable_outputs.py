"""Results a CI pipeline can trust (issue 27): the same outputs for the same results whether a run is fresh,
resumed or done in parts (`-i`), a partial run merges into the run's results, `carlos validate` rejects what
`carlos run` rejects, a lockstep closed loop without a transport fails at once."""

from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from simcore.checks import check_controller_reachable
from simcore.cli_app import plural
from simcore.errors import BadInput
from simcore.evaluation.criteria import format_measured
from simcore.evaluation.report import in_manifest_order, summary_json
from simcore.manifest import load_manifest
from tests.inprocess import carlos_in_process

ROOT = Path(__file__).resolve().parents[1]
CUT_IN = ROOT / "examples" / "scenarios" / "cut-in.xosc"
#: matrix keys deliberately not in alphabetical order (a resumed run used to sort them)
MANIFEST = """apiVersion: carlos.dev/v1alpha1
kind: SimulationRun
metadata: {{name: stable}}
spec:
  scenarios: [{{name: cut-in, openscenario: {scenario}}}]
  parameters: {{StopDelay: 1.0}}
  sweep:
    matrix: {{EgoSpeed: [20, 22], AdversaryEndSpeed: [14, 16]}}
  evaluation:
    criteria: ["minDistance >= 5.5"]
  simulation: {{stepSeconds: 0.1, maxSeconds: 2, seed: 3}}
  recording: {{enabled: false}}
  output: {{url: {url}}}
"""


def _manifest(folder: Path) -> Path:
    path = folder / "stable.yaml"
    path.write_text(MANIFEST.format(scenario=json.dumps(str(CUT_IN)), url=(folder / "unused").as_uri()))
    return path


def _run(manifest: Path, out: Path, *args: str) -> int:
    result = carlos_in_process("run", manifest, "-o", out.as_uri(), "-q", "-j", "1", *args)
    assert result.exception is None, result.exception
    return result.exit_code


def _outputs(out: Path) -> dict[str, Any]:
    """What must not depend on how the results came about: summary.json (without its URL), junit.xml
    (without times), every index's summary.json (without its wall time)."""
    run = out / "stable"
    summary = json.loads((run / "summary.json").read_text())
    summary.pop("outputUrl")
    junit = re.sub(r' time="[0-9.]+"', "", (run / "junit.xml").read_text())
    indexes = {}
    for path in sorted(run.glob("*/summary.json")):
        index = json.loads(path.read_text())
        index.pop("wallSeconds")
        indexes[path.parent.name] = index
    return {"summary": summary, "junit": junit, "indexes": indexes}


def test_fresh_resumed_and_partial_runs_write_the_same_outputs(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path)
    fresh, resumed, halves = tmp_path / "fresh", tmp_path / "resumed", tmp_path / "halves"
    assert _run(manifest, fresh) == 1
    expected = _outputs(fresh)
    names = [c.get("name") for c in ET.fromstring(expected["junit"]).iter("testcase")]
    assert len(names) == 4
    for i, name in enumerate(names):
        assert re.fullmatch(rf"cut-in\[{i}\] StopDelay=1,EgoSpeed=2[02],AdversaryEndSpeed=1[46]", name), name
    assert list(expected["indexes"]["1"]["parameters"]) == ["StopDelay", "EgoSpeed", "AdversaryEndSpeed"]
    assert expected["summary"]["counts"]["total"] == 4

    # resumed: every index already there; and as results written before the order was kept (sorted)
    shutil.copytree(fresh, resumed)
    for path in (resumed / "stable").glob("*/summary.json"):
        path.write_text(json.dumps(json.loads(path.read_text()), indent=2, sort_keys=True) + "\n")
    (resumed / "stable" / "junit.xml").unlink()
    assert _run(manifest, resumed) == 1
    got = _outputs(resumed)
    assert got["summary"] == expected["summary"]
    assert got["junit"] == expected["junit"]

    # in two halves: the second merges into the first
    assert _run(manifest, halves, "-i", "0", "-i", "1") in (0, 1)
    first = json.loads((halves / "stable" / "summary.json").read_text())
    assert first["counts"]["total"] == 2
    assert _run(manifest, halves, "-i", "2", "-i", "3") in (0, 1)
    assert _outputs(halves) == expected


def test_a_partial_run_never_shrinks_the_results(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path)
    out = tmp_path / "out"
    _run(manifest, out)
    before = json.loads((out / "stable" / "summary.json").read_text())
    assert _run(manifest, out, "-i", "2", "--fresh") in (0, 1)  # rerun one index (its verdict: exit code)
    after = json.loads((out / "stable" / "summary.json").read_text())
    assert after["counts"] == before["counts"] and after["counts"]["total"] == 4
    junit = ET.parse(out / "stable" / "junit.xml").getroot()
    assert junit.get("tests") == "4"
    assert "cut-in[3]" in (out / "stable" / "report.html").read_text()


def test_manifest_order_and_summary_bytes() -> None:
    old = {"index": 0, "parameters": {"a": 1, "c": 2, "b": 3, "z": 4}}
    assert list(in_manifest_order(old, ["c", "b", "a"])["parameters"]) == ["c", "b", "a", "z"]
    text = summary_json({"status": "passed", "parameters": {"b": 1, "a": 2}, "metrics": {"y": 1, "x": 2}})
    assert text.decode().index('"b"') < text.decode().index('"a"')  # parameters keep their order
    assert text.decode().index('"x"') < text.decode().index('"y"')  # everything else sorted
    assert text.decode().index('"metrics"') < text.decode().index('"status"')


# --- validate = run ---------------------------------------------------------------------------------------

_RUN = """apiVersion: carlos.dev/v1alpha1
kind: SimulationRun
metadata: {{name: {name}}}
spec:
  scenarios: [{{name: s, openscenario: {scenario}}}]
  simulation: {{stepSeconds: 0.1, maxSeconds: 2{simulation}}}
  recording: {{enabled: false}}
  output: {{url: {url}}}
"""


def _broken(tmp_path: Path, case: str) -> tuple[Path, str]:
    """A manifest with one kind of bad input, and a fragment of the one line both commands must print."""
    scenario = CUT_IN.read_text().replace('filepath="../maps/', f'filepath="{CUT_IN.parent.parent}/maps/')
    simulation = ""
    expected = {
        "lane": "lane.xosc:96: LanePosition: ",
        "ego": "ego entity 'Nobody' is not in the scenario",
        "param": "parameter(s) Nope not declared",
        "entity": "not declared in <Entities>",
    }[case]
    if case == "lane":
        scenario = scenario.replace('laneId="-2" s="$EgoStartS"', 'laneId="-7" s="$EgoStartS"')
    elif case == "ego":
        simulation = ", ego: Nobody"
    elif case == "entity":
        scenario = scenario.replace('<EntityRef entityRef="Adversary"/>', '<EntityRef entityRef="Ghost"/>', 1)
    xosc = tmp_path / f"{case}.xosc"
    xosc.write_text(scenario)
    text = _RUN.format(
        name=case, scenario=json.dumps(str(xosc)), simulation=simulation, url=(tmp_path / "out").as_uri()
    )
    if case == "param":
        text = text.replace("  simulation:", "  parameters: {Nope: 1}\n  simulation:")
    path = tmp_path / f"{case}.yaml"
    path.write_text(text)
    return path, expected


@pytest.mark.parametrize("case", ["lane", "ego", "param", "entity"])
def test_validate_rejects_what_run_rejects(case: str, tmp_path: Path) -> None:
    manifest, expected = _broken(tmp_path, case)
    validated = carlos_in_process("validate", manifest)
    ran = carlos_in_process("run", manifest, "-q")
    assert validated.exception is None and ran.exception is None
    assert (validated.exit_code, ran.exit_code) == (2, 2)
    said = validated.stderr.strip()
    assert said.count("\n") == 0 and expected in said, said
    assert expected in ran.stdout + ran.stderr
    if case == "lane":
        assert "no lane id=-7 at s=50.000" in said
    index = tmp_path / "out" / case / "0" / "summary.json"
    if index.exists():  # rejected by the run itself: an error of bad input, never a test failure
        summary = json.loads(index.read_text())
        assert summary["status"] == "error" and summary["badInput"] is True


def test_validate_passes_every_example() -> None:
    for manifest in sorted((ROOT / "examples" / "runs").glob("*.yaml")):
        result = carlos_in_process("validate", manifest)
        assert result.exit_code == 0, (manifest.name, result.stderr)


# --- closed loop without a transport -------------------------------------------------------------------


def test_lockstep_closed_loop_without_a_transport_fails_at_once(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "run", str(ROOT / "examples/runs/closed-loop.yaml")],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert result.returncode == 2
    line = result.stderr.strip()
    assert line.count("\n") == 0
    assert "closed-loop.yaml: spec.control: drives Ego in lockstep" in line
    assert "--transport dds" in line and "spec.systemUnderTest.module" in line
    assert not (tmp_path / "results").exists()  # nothing started


def test_when_a_controller_can_reach_the_run() -> None:
    spec = load_manifest(ROOT / "examples/runs/closed-loop.yaml").spec
    for transport in ("dds", "loopback"):
        check_controller_reachable(spec, transport, "m.yaml")
    with pytest.raises(BadInput):
        check_controller_reachable(spec, "none", "m.yaml")
    in_process = spec.model_copy(
        update={
            "system_under_test": spec.model_validate(
                {"systemUnderTest": {"module": "a:B"}, "scenarios": [{"name": "x", "openscenario": "x.xosc"}]}
            ).system_under_test
        }
    )
    check_controller_reachable(in_process, "none", "m.yaml")
    free = spec.model_copy(update={"control": spec.control.model_copy(update={"mode": "freeRunning"})})  # type: ignore[union-attr]
    check_controller_reachable(free, "none", "m.yaml")


# --- smaller ------------------------------------------------------------------------------------------------


def test_measured_values_are_shown_to_sensible_precision() -> None:
    assert format_measured(0.9705480511215439) == "0.9705"
    assert format_measured(12.3456789) == "12.35"
    assert format_measured(3.0) == "3"
    assert format_measured(1.99996, 2.0) == "1.99996"  # never reads as the threshold it fails
    assert format_measured(2.0, 2.0) == "2"


def test_plural() -> None:
    assert [plural(n, "run") for n in (0, 1, 2)] == ["0 runs", "1 run", "2 runs"]


def test_v2x_is_spelled_as_the_topics_and_the_old_spelling_still_reads() -> None:
    crd = (ROOT / "crds" / "simulationrun.yaml").read_text()
    assert "v2X" not in crd and "v2x:" in crd
    assert "spec.v2X" not in (ROOT / "docs" / "simulationrun.md").read_text()
    manifest = load_manifest(ROOT / "examples/runs/cooperative-perception.yaml")
    dumped = manifest.model_dump(mode="json", by_alias=True, exclude_none=True)
    assert "v2x" in dumped["spec"] and "v2X" not in dumped["spec"]
    again = type(manifest).model_validate(
        {
            **dumped,
            "spec": {**{k: v for k, v in dumped["spec"].items() if k != "v2x"}, "v2X": dumped["spec"]["v2x"]},
        }
    )
    assert again.spec.v2x == manifest.spec.v2x


def test_cli_and_cli_app_do_not_import_each_other() -> None:
    """simcore.cli imports simcore.cli_app lazily (its commands); simcore.cli_app imports nothing of
    simcore.cli, not even inside a function."""
    tree = ast.parse((ROOT / "simcore" / "cli_app.py").read_text())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            imported.add(node.module or "")
            imported.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            imported.update(a.name for a in node.names)
    assert "simcore.cli" not in imported


def test_an_entity_selection_is_reported_on_its_own_line(tmp_path: Path) -> None:
    text = CUT_IN.read_text()
    at = text.index("</Entities>")
    text = (
        text[:at] + '  <EntitySelection name="all">\n      <Members/>\n    </EntitySelection>\n  ' + text[at:]
    )
    line = text[: text.index("<EntitySelection")].count("\n") + 1
    scenario = tmp_path / "selection.xosc"
    scenario.write_text(text.replace('filepath="../maps/', f'filepath="{CUT_IN.parent.parent}/maps/'))
    manifest = tmp_path / "selection.yaml"
    manifest.write_text(
        _RUN.format(
            name="sel", scenario=json.dumps(str(scenario)), simulation="", url=(tmp_path / "o").as_uri()
        )
    )
    result = carlos_in_process("validate", manifest)
    assert result.exit_code == 2
    assert f"selection.xosc:{line}: EntitySelection: EntitySelection is not supported yet" in result.stderr
