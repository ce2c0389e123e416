"""Generated artefacts must not drift from the spec models."""

from __future__ import annotations

from pathlib import Path

from simcore.docs import reference

ROOT = Path(__file__).resolve().parents[1]


def test_field_reference_matches_the_models() -> None:
    checked_in = (ROOT / "docs" / "simulationrun.md").read_text()
    assert checked_in == reference(), (
        "docs/simulationrun.md is stale: run `carlos docs > docs/simulationrun.md`"
    )


def test_reference_documents_every_spec_section() -> None:
    text = reference()
    for path in (
        "spec.scenarios[].openscenario",
        "spec.sweep.matrix",
        "spec.simulation.stepSeconds",
        "spec.evaluation.criteria[].metric",
        "spec.recording.compression",
        "spec.output.url",
        "spec.execution.retries",
    ):
        assert f"| `{path}` |" in text
