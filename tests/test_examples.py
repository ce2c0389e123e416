"""The shipped examples: run manifests, OpenSCENARIO scenarios and OpenDRIVE roads.

Manifests validate against the spec models and reference existing scenarios and declared parameters;
scenarios and roads validate against the official ASAM XSDs (from the PyPI packages
asam-qc-openscenarioxml and asam-qc-opendrive) and keep to the OpenSCENARIO subset the engine supports;
roads convert with SUMO's netconvert; examples/generate.py reproduces the roads byte for byte.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import yaml

from simcore.spec import SimulationRun

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
RUNS = sorted((EXAMPLES / "runs").glob("*.yaml"))
SCENARIOS = sorted((EXAMPLES / "scenarios").glob("*.xosc"))
MAPS = sorted((EXAMPLES / "maps").glob("*.xodr"))

PARAM_REF = re.compile(r"^\$([A-Za-z_][A-Za-z0-9_]*)$")
PARAM_TYPES = {"double", "integer", "string", "boolean"}

# The OpenSCENARIO elements the engine supports (see the scenario engine's docs); anything else is an
# example that the engine cannot run.
SUPPORTED_ELEMENTS = {
    "OpenSCENARIO", "FileHeader", "ParameterDeclarations", "ParameterDeclaration", "CatalogLocations",
    "RoadNetwork", "LogicFile", "Entities", "ScenarioObject", "Vehicle", "MiscObject", "BoundingBox",
    "Center", "Dimensions", "Performance", "Axles", "FrontAxle", "RearAxle", "Properties", "Property",
    "ObjectController", "Controller", "Storyboard", "Init", "Actions", "Private", "PrivateAction",
    "TeleportAction", "Position", "LanePosition", "WorldPosition", "LongitudinalAction", "SpeedAction",
    "SpeedActionDynamics", "SpeedActionTarget", "AbsoluteTargetSpeed", "RelativeTargetSpeed",
    "LateralAction", "LaneChangeAction", "LaneChangeActionDynamics", "LaneChangeTarget",
    "AbsoluteTargetLane", "RelativeTargetLane", "Story", "Act", "ManeuverGroup", "Actors", "EntityRef",
    "Maneuver", "Event", "Action", "StartTrigger", "StopTrigger", "ConditionGroup", "Condition",
    "ByValueCondition", "SimulationTimeCondition", "StoryboardElementStateCondition", "ByEntityCondition",
    "TriggeringEntities", "EntityCondition", "RelativeDistanceCondition", "SpeedCondition",
    "TraveledDistanceCondition", "ReachPositionCondition", "TimeHeadwayCondition", "StandStillCondition",
    "CollisionCondition",
}  # fmt: skip


def _id(path: Path) -> str:
    return path.name


def _load_manifest(path: Path) -> SimulationRun:
    return SimulationRun.model_validate(yaml.safe_load(path.read_text(encoding="utf-8")))


def _package_dir(name: str) -> Path | None:
    """The directory of an installed package, without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def _scenariogeneration_copy(filename: str) -> Path | None:
    """scenariogeneration ships copies of the ASAM XSDs (top-level `schemas/`)."""
    try:
        files = importlib.metadata.files("scenariogeneration") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for file in files:
        if file.parts == ("schemas", filename):
            return Path(str(file.locate()))
    return None


@functools.cache
def _schema(kind: str) -> Any:
    """The official XSD ('xosc': OpenSCENARIO 1.2, 'xodr': OpenDRIVE 1.7) as an xmlschema object.

    From ASAM's quality-checker packages; else from the copy scenariogeneration ships (asam-qc-opendrive
    pins numpy<2, so an environment may lack it)."""
    xmlschema = pytest.importorskip("xmlschema", reason="xmlschema is not installed (pip install xmlschema)")
    package, relative, pypi, copy = {
        "xosc": (
            "qc_openscenario",
            "schema/1.2.0/OpenSCENARIO.xsd",
            "asam-qc-openscenarioxml",
            "OpenSCENARIO_1_2.xsd",
        ),
        "xodr": (
            "qc_opendrive",
            "schema/1.7.0/opendrive_17_core.xsd",
            "asam-qc-opendrive",
            "opendrive_17_core.xsd",
        ),
    }[kind]
    directory = _package_dir(package)
    path = directory / relative if directory is not None else None
    if path is None or not path.is_file():
        path = _scenariogeneration_copy(copy)
    if path is None or not path.is_file():
        pytest.skip(
            f"the official XSD is not installed: pip install {pypi} (it ships {package}/{relative}) "
            "or scenariogeneration (it ships a copy)"
        )
    return xmlschema.XMLSchema(str(path))


def _xml(path: Path) -> ET.Element:
    return ET.parse(path).getroot()


def _declared(root: ET.Element) -> dict[str, tuple[str, str]]:
    """Top-level ParameterDeclarations: name → (type, default)."""
    out = {}
    for decl in root.iterfind("ParameterDeclarations/ParameterDeclaration"):
        out[decl.attrib["name"]] = (decl.attrib["parameterType"], decl.attrib["value"])
    return out


def _resolve(value: str, declared: dict[str, tuple[str, str]]) -> str:
    match = PARAM_REF.match(value)
    return declared[match.group(1)][1] if match else value


# -- manifests ---------------------------------------------------------------------------------------


def test_examples_exist() -> None:
    assert {p.name for p in RUNS} >= {
        "prototyping.yaml",
        "data-generation.yaml",
        "automated-testing.yaml",
        "automated-testing-failing.yaml",
    }
    assert {p.name for p in SCENARIOS} >= {"cut-in.xosc", "braking.xosc", "curve-following.xosc"}
    assert len(SCENARIOS) >= 4
    assert {p.name for p in MAPS} == {"highway.xodr", "rural.xodr"}


@pytest.mark.parametrize("path", RUNS, ids=_id)
def test_manifest_validates_and_references_existing_scenarios(path: Path) -> None:
    run = _load_manifest(path)
    assert run.metadata.name == path.stem
    for scenario in run.spec.scenarios:
        assert scenario.openscenario is not None
        target = (path.parent / scenario.openscenario).resolve()
        assert target.is_file(), (
            f"{path.name}: scenario {scenario.name}: {scenario.openscenario} does not exist"
        )
        assert target.suffix == ".xosc"


@pytest.mark.parametrize("path", RUNS, ids=_id)
def test_manifest_header_says_how_to_run_it(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    assert text.startswith("#"), "a manifest starts with a comment saying what it shows"
    assert f"carlos run examples/runs/{path.name}" in text


@pytest.mark.parametrize("path", RUNS, ids=_id)
def test_manifest_parameters_are_declared_by_the_scenarios(path: Path) -> None:
    run = _load_manifest(path)
    for scenario in run.spec.scenarios:
        assert scenario.openscenario is not None
        declared = _declared(_xml(path.parent / scenario.openscenario))
        names = set(run.spec.parameters) | set(run.spec.sweep.matrix) | set(scenario.parameters)
        unknown = names - set(declared)
        assert not unknown, f"{path.name}: {scenario.name} does not declare {sorted(unknown)}"


def test_data_generation_sweeps_at_least_12_permutations() -> None:
    run = _load_manifest(EXAMPLES / "runs" / "data-generation.yaml")
    permutations = math.prod(len(values) for values in run.spec.sweep.matrix.values())
    assert permutations * run.spec.sweep.repetitions * len(run.spec.scenarios) >= 12
    assert run.spec.recording.enabled and run.spec.recording.topics == ["*"]
    assert run.spec.simulation.max_seconds <= 40


def test_automated_testing_manifests() -> None:
    passing = _load_manifest(EXAMPLES / "runs" / "automated-testing.yaml")
    failing = _load_manifest(EXAMPLES / "runs" / "automated-testing-failing.yaml")
    assert len(passing.spec.scenarios) >= 3
    assert any(s.optional for s in passing.spec.scenarios)
    assert passing.spec.evaluation.criteria
    # The failing variant is the passing one plus at least one required criterion of a required scenario.
    assert [s.name for s in failing.spec.scenarios] == [s.name for s in passing.spec.scenarios]
    added = []
    for bad, good in zip(failing.spec.scenarios, passing.spec.scenarios, strict=True):
        assert {c.label for c in good.criteria} <= {c.label for c in bad.criteria}
        extra = [c for c in bad.criteria if c.label not in {g.label for g in good.criteria}]
        added += [c for c in extra if not c.optional and not bad.optional]
    assert added, "automated-testing-failing.yaml adds no required criterion"


# -- scenarios ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", SCENARIOS, ids=_id)
def test_scenario_validates_against_the_openscenario_xsd(path: Path) -> None:
    schema = _schema("xosc")
    errors = [f"{e.path}: {e.reason}" for e in schema.iter_errors(str(path))]
    assert not errors, "\n".join(errors[:10])
    root = _xml(path)
    header = root.find("FileHeader")
    assert header is not None
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "2")


@pytest.mark.parametrize("path", SCENARIOS, ids=_id)
def test_scenario_parameters_are_declared_and_used(path: Path) -> None:
    root = _xml(path)
    declared = _declared(root)
    assert declared, "every scenario declares its sweepable values as parameters"
    used = set()
    for element in root.iter():
        for attribute, value in element.attrib.items():
            if value.startswith("$"):
                match = PARAM_REF.match(value)
                assert match, (
                    f"{element.tag}@{attribute}={value!r}: only plain $Name references are supported"
                )
                assert match.group(1) in declared, f"{element.tag}@{attribute}: {value} is not declared"
                used.add(match.group(1))
    # a run manifest may use a parameter in its spec (`$RsuS` in spec.infrastructure, spec.v2x)
    for run in RUNS:
        text = run.read_text()
        if path.name in text:
            used.update(re.findall(r"\$([A-Za-z_][A-Za-z0-9_]*)", text))
    assert set(declared) <= used, f"declared but never used: {sorted(set(declared) - used)}"
    for name, (kind, default) in declared.items():
        assert kind in PARAM_TYPES, f"{name}: type {kind}"
        if kind == "double":
            float(default)
        elif kind == "integer":
            int(default)
        elif kind == "boolean":
            assert default in ("true", "false")


@pytest.mark.parametrize("path", SCENARIOS, ids=_id)
def test_scenario_keeps_to_the_supported_subset(path: Path) -> None:
    root = _xml(path)
    unsupported = {element.tag for element in root.iter()} - SUPPORTED_ELEMENTS
    assert not unsupported, f"elements the engine does not support: {sorted(unsupported)}"
    entities = {obj.attrib["name"] for obj in root.iterfind("Entities/ScenarioObject")}
    # Ego is the vehicle under test and is driven by SUMO.
    assert "Ego" in entities
    ego = root.find("Entities/ScenarioObject[@name='Ego']")
    assert ego is not None
    drivers = [p.get("value") for p in ego.iterfind("ObjectController/Controller/Properties/Property")]
    assert drivers == ["sumo"]
    # Every entity reference names an entity; every storyboard reference names an element.
    for element in root.iter():
        ref = element.get("entityRef")
        if ref is not None:
            assert ref in entities, f"{element.tag}: unknown entity {ref}"
    names = {
        e.get("name") for e in root.iter() if e.tag in ("Story", "Act", "ManeuverGroup", "Maneuver", "Event")
    }
    names |= {e.get("name") for e in root.iterfind(".//Action")}
    for element in root.iter("StoryboardElementStateCondition"):
        assert element.get("storyboardElementRef") in names
    for event in root.iter("Event"):
        assert event.get("priority") in ("override", "overwrite")
    # Every entity is placed in Init.
    placed = {
        p.get("entityRef")
        for p in root.iterfind("Storyboard/Init/Actions/Private")
        if p.find(".//TeleportAction") is not None
    }
    assert placed == entities
    # The run always ends within 40 s simulated time.
    limits = [
        float(_resolve(c.attrib["value"], _declared(root)))
        for c in root.iterfind(
            "Storyboard/StopTrigger/ConditionGroup/Condition/ByValueCondition/SimulationTimeCondition"
        )
    ]
    assert limits and min(limits) <= 40.0


@pytest.mark.parametrize("path", SCENARIOS, ids=_id)
def test_scenario_road_and_lane_positions_exist(path: Path) -> None:
    root = _xml(path)
    declared = _declared(root)
    logic = root.find("RoadNetwork/LogicFile")
    assert logic is not None
    xodr = (path.parent / logic.attrib["filepath"]).resolve()
    assert xodr.is_file() and xodr.parent == (EXAMPLES / "maps").resolve()
    roads = {}
    for road in _xml(xodr).iterfind("road"):
        lanes = {int(lane.attrib["id"]) for lane in road.iterfind("lanes/laneSection/*/lane")}
        roads[road.attrib["id"]] = (float(road.attrib["length"]), lanes)
    for position in root.iter("LanePosition"):
        road_id = _resolve(position.attrib["roadId"], declared)
        lane_id = int(_resolve(position.attrib["laneId"], declared))
        s = float(_resolve(position.attrib["s"], declared))
        assert road_id in roads, f"road {road_id} is not in {xodr.name}"
        length, lanes = roads[road_id]
        assert lane_id in lanes and lane_id != 0, f"lane {lane_id} is not on road {road_id}"
        assert 0.0 <= s <= length, f"s={s} is outside road {road_id} (length {length})"
    for target in root.iter("AbsoluteTargetLane"):
        assert any(int(_resolve(target.attrib["value"], declared)) in lanes for _, lanes in roads.values())


# -- roads -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", MAPS, ids=_id)
def test_road_validates_against_the_opendrive_xsd(path: Path) -> None:
    schema = _schema("xodr")
    root = _xml(path)
    header = root.find("header")
    assert header is not None
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "7")
    errors = [f"{e.path}: {e.reason}" for e in schema.iter_errors(str(path))]
    assert not errors, "\n".join(errors[:10])


def test_roads_have_the_documented_shape() -> None:
    highway = _xml(EXAMPLES / "maps" / "highway.xodr").find("road")
    assert highway is not None
    assert abs(float(highway.attrib["length"]) - 2000.0) < 1e-6
    kinds = [g[0].tag for g in highway.iterfind("planView/geometry")]
    assert kinds == ["line", "spiral", "arc", "spiral", "line"]
    arc = highway.find("planView/geometry/arc")
    assert arc is not None and abs(1.0 / float(arc.attrib["curvature"]) - 1000.0) < 1e-6
    lanes = {
        int(lane.attrib["id"]): lane.attrib["type"]
        for lane in highway.iterfind("lanes/laneSection/right/lane")
    }
    assert lanes == {-1: "driving", -2: "driving", -3: "driving", -4: "shoulder", -5: "border"}
    assert highway.find("lanes/laneSection/left") is None

    rural = _xml(EXAMPLES / "maps" / "rural.xodr").find("road")
    assert rural is not None
    assert abs(float(rural.attrib["length"]) - 1000.0) < 1e-6
    curvatures = [float(a.attrib["curvature"]) for a in rural.iterfind("planView/geometry/arc")]
    assert sorted(curvatures) == [-1 / 200, 1 / 200]
    driving = {int(lane.attrib["id"]) for lane in rural.iterfind("lanes/laneSection/*/lane[@type='driving']")}
    assert driving == {-1, 1}
    assert len(rural.findall("elevationProfile/elevation")) == 2


def _netconvert() -> Path:
    sumo = pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    binary = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
    if not binary.exists():
        pytest.skip(f"netconvert is not at {binary}")
    return binary


@pytest.mark.parametrize("path", MAPS, ids=_id)
def test_road_converts_with_netconvert(path: Path, tmp_path: Path) -> None:
    binary = _netconvert()
    net = tmp_path / f"{path.stem}.net.xml"
    env = dict(os.environ, SUMO_HOME=str(binary.parent.parent))
    result = subprocess.run(
        [
            str(binary),
            "--opendrive-files",
            str(path),
            "--output.original-names",
            "--no-turnarounds",
            "--offset.disable-normalization",
            "-o",
            str(net),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=False,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "Error" not in output, output
    assert "Warning" not in output, output
    lanes = [lane for lane in _xml(net).iter("lane") if lane.get("type") == "driving"]
    assert len(lanes) == {"highway": 3, "rural": 2}[path.stem]
    # Every driving lane carries the road's speed limit (SUMO's default without a lane <speed> is 50 km/h).
    expected = {"highway": 130 / 3.6, "rural": 100 / 3.6}[path.stem]
    assert all(abs(float(lane.attrib["speed"]) - expected) < 0.01 for lane in lanes)


def test_generate_reproduces_the_roads() -> None:
    pytest.importorskip("scenariogeneration", reason="scenariogeneration is not installed")
    spec = importlib.util.spec_from_file_location("examples_generate", EXAMPLES / "generate.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        assert module.main(["--check"]) == 0, "examples/maps/*.xodr differ from examples/generate.py's output"
    finally:
        del sys.modules[spec.name]


# -- end to end (slow: `make test-slow`) ---------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    ("manifest", "exit_code"),
    [
        ("automated-testing.yaml", 0),
        ("automated-testing-failing.yaml", 1),
        ("prototyping.yaml", 0),
        ("cooperative-perception.yaml", 0),
    ],
)
def test_carlos_run_gives_the_documented_exit_code(manifest: str, exit_code: int, tmp_path: Path) -> None:
    carlos = Path(sys.executable).parent / "carlos"
    if not carlos.exists():
        pytest.skip(f"the carlos CLI is not installed next to {sys.executable}")
    result = subprocess.run(
        [str(carlos), "run", "-q", str(EXAMPLES / "runs" / manifest), "--output", f"file://{tmp_path}"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == exit_code, result.stdout + result.stderr
