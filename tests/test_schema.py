"""OpenSCENARIO files against the official ASAM XSD of their declared revision (simcore/scenario/schema.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from simcore.errors import BadInput
from simcore.scenario import schema
from tests.tooling import corpus_dir
from tests.xosc_fixtures import (
    act,
    event,
    openscenario,
    private_actions,
    road_network,
    scenario_object,
    sim_time,
    speed_action,
    story,
    teleport_world,
    vehicle,
    write_scenario,
)

ROOT = Path(__file__).resolve().parents[1]

# a car, its speed set in Init and changed by one event: valid against the XSD of revisions 1.0 to 1.2
CAR = vehicle(
    z=0.8, width=2, max_speed=50, max_deceleration=10, track_width=1.8, parameters="<ParameterDeclarations/>"
)


def write(
    tmp_path: Path,
    minor: str = "2",
    shape: str = "step",
    extra: str = "",
    priority: str = "override",
    name: str = "s.xosc",
) -> Path:
    """The scenario of revision 1.`minor`, with the Init SpeedAction's `shape` and `extra` attributes and the
    event's `priority`."""
    init_speed = speed_action(shape, "time", 0, 10).replace("<SpeedAction>", f"<SpeedAction{extra}>")
    change = event("e", speed_action("step", "time", 0, 5), sim_time("greaterThan", 1, name="c"), priority)
    text = openscenario(
        minor=minor,
        parameters="<ParameterDeclarations/>",
        catalogs="<CatalogLocations/>",
        road=road_network(),
        entities=scenario_object("Car", CAR),
        init=private_actions("Car", teleport_world(0), init_speed),
        stories=story(act(change, actor="Car", start=sim_time("greaterThan", 0, name="go"))),
    )
    return write_scenario(tmp_path, text, name)


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
    ("inside", "expected"),
    [
        ("<X>" * 300 + "</X>" * 300, "nested more than 256 deep"),
        ("<X " + " ".join(f'a{i}="{i}"' for i in range(50_000)) + "/>", "50000 attributes"),
    ],
    ids=["deep", "wide"],
)
def test_deep_or_wide_xml_is_refused_before_the_schema_check(
    tmp_path: Path, inside: str, expected: str
) -> None:
    import time

    path = tmp_path / "hostile.xosc"
    path.write_text(f'<OpenSCENARIO><FileHeader revMajor="1" revMinor="2"/>{inside}</OpenSCENARIO>')
    started = time.monotonic()
    with pytest.raises(BadInput, match=f"too complex at line 1: .*{expected}"):
        schema.check_openscenario(path)
    assert time.monotonic() - started < 5.0


@pytest.mark.parametrize(
    "path", sorted((ROOT / "examples" / "scenarios").glob("*.xosc")), ids=lambda p: p.name
)
def test_the_example_scenarios_are_valid(path: Path) -> None:
    report = schema.check_openscenario(path)
    assert report.valid, [str(i) for i in report.issues]


def test_every_corpus_file_is_valid_against_its_declared_revision() -> None:
    resources = corpus_dir() / "resources"
    files = sorted(resources.rglob("*.xosc"))
    assert len(files) >= 72
    invalid = {
        str(f.relative_to(resources)): r.issues[:3]
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
    bad = write(tmp_path, shape="wobbly", name="bad.xosc")  # in the Init's SpeedAction
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
