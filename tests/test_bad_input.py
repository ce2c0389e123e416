"""Hostile or careless manifests: one line naming the file and the field, exit code 2, never a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.inprocess import carlos_in_process

ROOT = Path(__file__).resolve().parents[1]
BRAKING = ROOT / "examples" / "scenarios" / "braking.xosc"
HEAD = "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\n"
SCENARIO = f"spec:\n  scenarios: [{{name: a, openscenario: {BRAKING}}}]\n"


def _validate(tmp_path: Path, text: str) -> tuple[int, str]:
    manifest = tmp_path / "m.yaml"
    manifest.write_text(text)
    outcome = carlos_in_process("validate", manifest)
    assert outcome.exception is None, repr(outcome.exception)
    return outcome.exit_code, outcome.stderr.strip()


def _alias_bomb() -> str:
    lines = ["a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for level in range(1, 9):
        previous, name = chr(96 + level), chr(97 + level)
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{previous}"] * 10) + "]")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("a: " + "[" * 5000 + "]" * 5000 + "\n", "m.yaml: nested more than 64 levels deep"),
        (_alias_bomb(), "m.yaml: more than 1000000 values (counting aliases)"),
        ('a: 1\nb: "\x01"\n', "m.yaml: invalid YAML at line 2, column 5: character #x0001"),
        ("a: !!python/object:os.system x\n", "m.yaml: invalid YAML at line 1, column 4: could not determine"),
        (
            HEAD + "metadata: {generateName: ../../x-}\n" + SCENARIO,
            "m.yaml: metadata.generateName: '../../x-' is not a name prefix",
        ),
        (
            HEAD + "metadata: {name: t}\n" + SCENARIO + "  simulation: {stepSeconds: true}\n",
            "m.yaml: spec.simulation: stepSeconds: true is a boolean, not a number",
        ),
        (
            HEAD + "metadata: {name: t}\n" + SCENARIO + "  execution: {retries: false}\n",
            "m.yaml: spec.execution: retries: false is a boolean, not a number",
        ),
        (
            HEAD + "metadata: {name: '" + "x" * 300_000 + "'}\n" + SCENARIO,
            "m.yaml: metadata.name: 'xxxxxxxx",
        ),
    ],
    ids=[
        "deep",
        "alias-bomb",
        "control-char",
        "python-tag",
        "generate-name",
        "bool-step",
        "bool-int",
        "huge",
    ],
)
def test_bad_manifests_end_in_one_line(tmp_path: Path, text: str, expected: str) -> None:
    code, stderr = _validate(tmp_path, text)
    assert code == 2
    assert stderr.startswith(f"error: {tmp_path / 'm.yaml'}")
    assert expected in stderr.replace(str(tmp_path) + "/", "")
    assert len(stderr.splitlines()) == 1
    assert len(stderr) < 1000  # a 300 KB value is not echoed back


@pytest.mark.parametrize("name", ["[/x]", ":100:", "[bold]x"])
def test_user_text_is_printed_literally(tmp_path: Path, name: str) -> None:
    scenario = tmp_path / "s.xosc"
    scenario.write_text(BRAKING.read_text().replace('entityRef="Ego"', f'entityRef="{name}"'))
    (tmp_path / "maps").mkdir()
    text = HEAD + f"metadata: {{name: t}}\nspec:\n  scenarios: [{{name: a, openscenario: {scenario}}}]\n"
    code, stderr = _validate(tmp_path, text.replace("../maps/", str(ROOT / "examples" / "maps") + "/"))
    assert code == 2
    assert f"entity '{name}' is not declared" in stderr


def _scenario_with(tmp_path: Path, old: str, new: str) -> Path:
    scenario = tmp_path / "s.xosc"
    text = BRAKING.read_text().replace("../maps/", str(ROOT / "examples" / "maps") + "/")
    assert old in text
    scenario.write_text(text.replace(old, new))
    return scenario


def _run_manifest(scenario: Path, extra: str = "") -> str:
    return (
        HEAD + f"metadata: {{name: t}}\nspec:\n  scenarios: [{{name: a, openscenario: {scenario}}}]\n" + extra
    )


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (
            "  sweep: {matrix: {Gap: [40, 30, abc]}}\n",
            "m.yaml: spec.sweep.matrix.Gap[2]: parameter 'Gap' (double): could not convert",
        ),
        (
            "  parameters: {Speed: true}\n",
            "m.yaml: spec.parameters.Speed: parameter 'Speed' (double): a boolean is not a number",
        ),
    ],
)
def test_parameter_type_errors_name_the_manifest_field(tmp_path: Path, extra: str, expected: str) -> None:
    code, stderr = _validate(tmp_path, _run_manifest(BRAKING, extra))
    assert code == 2
    assert expected in stderr.replace(str(tmp_path) + "/", "")


def test_an_undeclared_entity_in_a_condition_is_caught_by_validate(tmp_path: Path) -> None:
    text = BRAKING.read_text()
    # the first entityRef inside the Storyboard's Story (a condition or action), not Init's
    story = text.index("<Story ")
    ref = text.index('entityRef="', story)
    end = text.index('"', ref + len('entityRef="'))
    scenario = tmp_path / "s.xosc"
    scenario.write_text(
        (text[: ref + len('entityRef="')] + "Nobody" + text[end:]).replace(
            "../maps/", str(ROOT / "examples" / "maps") + "/"
        )
    )
    code, stderr = _validate(tmp_path, _run_manifest(scenario))
    assert code == 2
    assert "s.xosc: Story[" in stderr and "entity 'Nobody' is not declared in <Entities>" in stderr


@pytest.mark.parametrize(
    ("road", "content", "expected"),
    [
        (
            "xxe.xodr",
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]><OpenDRIVE>&x;</OpenDRIVE>',
            "xxe.xodr: unsafe XML rejected",
        ),
        (
            "laughs.xodr",
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa"><!ENTITY b "&a;&a;&a;">]><OpenDRIVE>&b;</OpenDRIVE>',
            "laughs.xodr: unsafe XML rejected",
        ),
        (
            "bomb.net.xml",
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa"><!ENTITY b "&a;&a;&a;">]><net>&b;</net>',
            "bomb.net.xml: SUMO network uses forbidden XML constructs",
        ),
        ("many.xodr", "<OpenDRIVE>" + "<geometry/>" * 100_001 + "</OpenDRIVE>", "100001 <geometry> records"),
        ("../../../../../../../../etc/passwd", None, "is neither OpenDRIVE (.xodr) nor SUMO (.net.xml)"),
        ("broken.xodr", "<OpenDRIVE><road>", "broken.xodr: not well-formed XML"),
    ],
    ids=["xxe", "billion-laughs", "net-xml-entities", "geometries", "passwd", "broken"],
)
def test_road_files_are_untrusted_input(
    tmp_path: Path, road: str, content: str | None, expected: str
) -> None:
    if content is not None:
        (tmp_path / road).write_text(content)
    scenario = _scenario_with(tmp_path, str(ROOT / "examples" / "maps" / "highway.xodr"), road)
    scenario.write_text(scenario.read_text().replace(f'"{road}"', f'"{tmp_path / road}"'))
    code, stderr = _validate(tmp_path, _run_manifest(scenario))
    assert code == 2, stderr
    assert expected in stderr
    assert len(stderr.splitlines()) == 1


def test_a_parameter_road_path_gets_the_bucket_check(tmp_path: Path) -> None:
    from simcore.errors import BadInput
    from simcore.runner import _fetch_from_s3
    from simcore.store import FileStore

    bucket = tmp_path / "bucket"
    (bucket / "scenarios").mkdir(parents=True)
    text = BRAKING.read_text().replace('filepath="../maps/highway.xodr"', 'filepath="$Road"')
    text = text.replace(
        "<ParameterDeclarations>",
        '<ParameterDeclarations><ParameterDeclaration name="Road" parameterType="string" value="x.xodr"/>',
        1,
    )
    (bucket / "scenarios" / "s.xosc").write_text(text)
    with pytest.raises(BadInput, match=r"road file '\.\./\.\./etc/passwd' lies outside the bucket"):
        _fetch_from_s3(
            "s3://b/scenarios/s.xosc",
            tmp_path / "scratch",
            lambda url: FileStore(bucket),
            "f",
            {"Road": "../../etc/passwd"},
        )


def test_a_road_path_the_file_system_refuses_is_one_line(tmp_path: Path) -> None:
    scenario = _scenario_with(tmp_path, str(ROOT / "examples" / "maps" / "highway.xodr"), "x" * 300 + ".xodr")
    code, stderr = _validate(tmp_path, _run_manifest(scenario))
    assert code == 2
    assert "m.yaml: cannot read" in stderr and "File name too long" in stderr
    assert len(stderr) < 600


def test_an_unknown_xml_encoding_is_one_line(tmp_path: Path) -> None:
    scenario = tmp_path / "s.xosc"
    scenario.write_text('<?xml version="1.0" encoding="true"?>\n<OpenSCENARIO/>\n')
    code, stderr = _validate(tmp_path, _run_manifest(scenario))
    assert code == 2 and "s.xosc: OpenSCENARIO file declares an unknown encoding" in stderr
    outcome = carlos_in_process("validate", scenario, "--schema")
    assert outcome.exception is None and outcome.exit_code == 2


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        (
            "{speed: fast}",
            "spec.systemUnderTest.parameters.speed: examples.controller:CruiseController takes speed as float, not 'fast'",
        ),
        ("{speed: true}", "takes speed as float, not True"),
        ("{stop_after: 1.5}", "takes stop_after as int | None, not 1.5"),
        (
            "{sped: 1}",
            "spec.systemUnderTest.parameters: examples.controller:CruiseController does not take these parameters",
        ),
    ],
)
def test_system_under_test_parameters_are_checked_by_validate(
    tmp_path: Path, parameters: str, expected: str
) -> None:
    sut = (
        "  systemUnderTest: {module: 'examples.controller:CruiseController', "
        f"pythonPath: ['{ROOT}'], parameters: {parameters}}}\n"
    )
    code, stderr = _validate(tmp_path, _run_manifest(BRAKING, sut))
    assert code == 2, stderr
    assert expected in stderr.replace(str(tmp_path) + "/", "")
    assert stderr.startswith(f"error: {tmp_path / 'm.yaml'}")


def test_an_output_url_without_a_scheme_gets_the_hint_of_the_command_line(tmp_path: Path) -> None:
    code, message = _validate(
        tmp_path, HEAD + "metadata: {name: r}\n" + SCENARIO + "  output: {url: ./results}\n"
    )
    assert code == 2 and len(message.splitlines()) == 1
    assert "spec.output.url: './results' is not a results URL" in message and "file://./results" in message
    assert "^(file|s3)" not in message  # not the raw pattern


def test_a_missing_scenario_path_is_printed_normalised(tmp_path: Path) -> None:
    (tmp_path / "runs").mkdir()
    text = (
        HEAD + "metadata: {name: r}\nspec:\n  scenarios: [{name: a, openscenario: ../scenarios/nope.xosc}]\n"
    )
    manifest = tmp_path / "runs" / "m.yaml"
    manifest.write_text(text)
    outcome = carlos_in_process("validate", manifest)
    assert outcome.exit_code == 2
    assert f"scenario file '{tmp_path / 'scenarios' / 'nope.xosc'}' not found" in outcome.stderr
    assert "/../" not in outcome.stderr
