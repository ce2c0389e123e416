"""OpenSCENARIO files against the official ASAM XSD of their declared revision (simcore/scenario/schema.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from simcore.errors import BadInput
from simcore.scenario import schema

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus" / "esmini" / "resources"

SCENARIO = """<?xml version="1.0"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="{minor}" date="2024-01-01T00:00:00" description="t" author="t"/>
  <ParameterDeclarations/>
  <CatalogLocations/>
  <RoadNetwork/>
  <Entities>
    <ScenarioObject name="Car">
      <Vehicle name="car" vehicleCategory="car">
        <ParameterDeclarations/>
        <BoundingBox><Center x="1.4" y="0" z="0.8"/><Dimensions width="2" length="4.5" height="1.5"/></BoundingBox>
        <Performance maxSpeed="50" maxAcceleration="5" maxDeceleration="10"/>
        <Axles>
          <FrontAxle maxSteering="0.5" wheelDiameter="0.6" trackWidth="1.8" positionX="2.8" positionZ="0.3"/>
          <RearAxle maxSteering="0" wheelDiameter="0.6" trackWidth="1.8" positionX="0" positionZ="0.3"/>
        </Axles>
        <Properties/>
      </Vehicle>
    </ScenarioObject>
  </Entities>
  <Storyboard>
    <Init><Actions><Private entityRef="Car">
      <PrivateAction><TeleportAction><Position><WorldPosition x="0" y="0" h="0"/></Position></TeleportAction></PrivateAction>
      <PrivateAction><LongitudinalAction><SpeedAction{speed_extra}>
        <SpeedActionDynamics dynamicsShape="{shape}" value="0" dynamicsDimension="time"/>
        <SpeedActionTarget><AbsoluteTargetSpeed value="10"/></SpeedActionTarget>
      </SpeedAction></LongitudinalAction></PrivateAction>
    </Private></Actions></Init>
    <Story name="s">
      <Act name="a">
        <ManeuverGroup name="g" maximumExecutionCount="1">
          <Actors selectTriggeringEntities="false"><EntityRef entityRef="Car"/></Actors>
          <Maneuver name="m">
            <Event name="e" priority="{priority}">
              <Action name="x"><PrivateAction><LongitudinalAction><SpeedAction>
                <SpeedActionDynamics dynamicsShape="step" value="0" dynamicsDimension="time"/>
                <SpeedActionTarget><AbsoluteTargetSpeed value="5"/></SpeedActionTarget>
              </SpeedAction></LongitudinalAction></PrivateAction></Action>
              <StartTrigger><ConditionGroup><Condition name="c" delay="0" conditionEdge="none">
                <ByValueCondition><SimulationTimeCondition value="1" rule="greaterThan"/></ByValueCondition>
              </Condition></ConditionGroup></StartTrigger>
            </Event>
          </Maneuver>
        </ManeuverGroup>
        <StartTrigger><ConditionGroup><Condition name="go" delay="0" conditionEdge="none">
          <ByValueCondition><SimulationTimeCondition value="0" rule="greaterThan"/></ByValueCondition>
        </Condition></ConditionGroup></StartTrigger>
      </Act>
    </Story>
    <StopTrigger/>
  </Storyboard>
</OpenSCENARIO>
"""


def write(
    tmp_path: Path, minor: str = "2", shape: str = "step", extra: str = "", priority: str = "override"
) -> Path:
    path = tmp_path / "s.xosc"
    path.write_text(SCENARIO.format(minor=minor, shape=shape, speed_extra=extra, priority=priority))
    return path


def test_a_valid_scenario_has_no_issues_and_names_the_schema(tmp_path: Path) -> None:
    report = schema.check_openscenario(write(tmp_path))
    assert report.valid, [str(i) for i in report.issues]
    assert (report.version, report.declared, report.note) == ("1.2.0", "1.2", "")


def test_violations_name_the_line_the_element_and_the_reason(tmp_path: Path) -> None:
    path = write(tmp_path, shape="wobbly", extra=' bogus="1"')
    report = schema.check_openscenario(path)
    assert not report.valid
    text = path.read_text().splitlines()
    by_reason = {issue.reason: issue for issue in report.issues}
    bogus = next(i for r, i in by_reason.items() if "'bogus' attribute not allowed" in r)
    assert bogus.line is not None and 'bogus="1"' in text[bogus.line - 1]
    assert bogus.path.endswith("/LongitudinalAction/SpeedAction")
    wobbly = next(i for r, i in by_reason.items() if "wobbly" in r)
    assert wobbly.line is not None and 'dynamicsShape="wobbly"' in text[wobbly.line - 1]
    assert "step" in wobbly.reason  # the allowed values
    assert str(wobbly).startswith(f"line {wobbly.line}: /OpenSCENARIO/")


def test_the_declared_revision_picks_the_schema(tmp_path: Path) -> None:
    # Event priority "override" is 1.2's name; 1.0 and 1.1 call it "overwrite" ("override" is not in their enum)
    assert schema.check_openscenario(write(tmp_path, minor="2", priority="override")).valid
    old = schema.check_openscenario(write(tmp_path, minor="0", priority="override"))
    assert old.version == "1.0.0" and any("override" in i.reason for i in old.issues)
    assert schema.check_openscenario(write(tmp_path, minor="0", priority="overwrite")).valid
    unknown = schema.check_openscenario(write(tmp_path, minor="9"))
    assert unknown.version == "1.3.0" and "1.9 has no published schema" in unknown.note


def test_many_violations_are_capped(tmp_path: Path) -> None:
    report = schema.check_openscenario(write(tmp_path, shape="wobbly", extra=' bogus="1"'), max_issues=1)
    assert len(report.issues) == 1 and report.truncated


def test_unsafe_or_broken_xml_is_bad_input_before_any_schema_work(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.xosc"
    bomb.write_text(
        '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;">]>'
        "<OpenSCENARIO>&b;</OpenSCENARIO>"
    )
    with pytest.raises(BadInput, match="forbidden XML constructs"):
        schema.check_openscenario(bomb)
    broken = tmp_path / "broken.xosc"
    broken.write_text("<OpenSCENARIO><Storyboard></OpenSCENARIO>")
    with pytest.raises(BadInput, match="not well-formed"):
        schema.check_openscenario(broken)


@pytest.mark.parametrize(
    "path", sorted((ROOT / "examples" / "scenarios").glob("*.xosc")), ids=lambda p: p.name
)
def test_the_example_scenarios_are_valid(path: Path) -> None:
    report = schema.check_openscenario(path)
    assert report.valid, [str(i) for i in report.issues]


@pytest.mark.skipif(not CORPUS.is_dir(), reason="esmini corpus not present")
def test_every_corpus_file_is_valid_against_its_declared_revision() -> None:
    files = sorted(CORPUS.rglob("*.xosc"))
    assert len(files) >= 72
    invalid = {
        str(f.relative_to(CORPUS)): r.issues[:3]
        for f in files
        if not (r := schema.check_openscenario(f)).valid
    }
    assert invalid == {}


def _carlos(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "simcore.cli", "validate", *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
        env={**os.environ, "COLUMNS": "300"},
    )


def test_carlos_validate_schema_on_files_lists_violations_and_exits_2(tmp_path: Path) -> None:
    good = write(tmp_path)
    bad = tmp_path / "bad.xosc"
    bad.write_text(
        good.read_text().replace(
            'dynamicsShape="step" value="0" dynamicsDimension="time"/>\n        <SpeedActionTarget><AbsoluteTargetSpeed value="10"',
            'dynamicsShape="wobbly" value="0" dynamicsDimension="time"/>\n        <SpeedActionTarget><AbsoluteTargetSpeed value="10"',
        )
    )
    line = next(n for n, text in enumerate(bad.read_text().splitlines(), 1) if "wobbly" in text)
    proc = _carlos(str(good), str(bad), "--schema")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"{good}: valid against OpenSCENARIO 1.2.0 XSD" in proc.stdout
    assert f"{bad}: 1 violation(s) of the OpenSCENARIO 1.2.0 XSD" in proc.stderr
    assert f"{bad}:{line}: /OpenSCENARIO/Storyboard/Init/" in proc.stderr and "wobbly" in proc.stderr
    assert _carlos(str(good), "--schema").returncode == 0
    refused = _carlos(str(good))  # a scenario file without --schema: the command says how
    assert refused.returncode == 2 and "--schema" in refused.stderr


def test_carlos_validate_schema_checks_a_manifests_scenarios() -> None:
    proc = _carlos("examples/runs/automated-testing.yaml", "--schema")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("valid against OpenSCENARIO 1.2.0 XSD") == 4
    assert "examples/runs/automated-testing.yaml: valid · 4 runs" in proc.stdout
