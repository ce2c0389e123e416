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
