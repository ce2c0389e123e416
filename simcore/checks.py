"""Checks of a manifest that need more than its schema, run by `carlos validate` and before `carlos run`
starts any worker (bad input, exit 2, instead of a run that fails every index)."""

from __future__ import annotations

import difflib
from pathlib import Path

from simcore.errors import BadInput
from simcore.evaluation.metrics import KNOWN_METRICS
from simcore.spec import SimulationRunSpec

#: metrics the runner adds besides `KNOWN_METRICS` (the perception loop's)
_RUNNER_METRICS = frozenset({"systemUnderTest.failed"})
#: V2X metrics measured per distance band
_V2X_BANDED = "v2x.packetDeliveryRatio."


def unknown_metric(metric: str, detection: bool, v2x: bool = False) -> str | None:
    """Why `metric` can never be measured (None when it can), with the closest known names (pure)."""
    if metric.startswith("v2x.") and not v2x:
        return f"metric {metric!r} needs spec.v2x"
    if metric in KNOWN_METRICS or metric in _RUNNER_METRICS:
        return None
    if metric.startswith(_V2X_BANDED):
        return None  # per distance band (`v2x.packetDeliveryRatio.0-100m`): the bands depend on the spec
    if metric.startswith("detection."):
        if detection:
            return None  # per class and distance band: the names depend on the data
        return f"metric {metric!r} needs spec.evaluation.detection"
    close = difflib.get_close_matches(metric, sorted(KNOWN_METRICS | _RUNNER_METRICS), n=3, cutoff=0.6)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    return f"unknown metric {metric!r}: {hint}known: {', '.join(sorted(KNOWN_METRICS))}, detection.*"


def check_criteria_metrics(spec: SimulationRunSpec, file: str) -> None:
    """Every criterion names a metric that a run can measure."""
    detection = spec.evaluation.detection is not None
    v2x = spec.v2x is not None
    named = [(f"spec.evaluation.criteria[{i}]", c) for i, c in enumerate(spec.evaluation.criteria)]
    for p, scenario in enumerate(spec.scenarios):
        named += [(f"spec.scenarios[{p}].criteria[{i}]", c) for i, c in enumerate(scenario.criteria)]
    for field, criterion in named:
        problem = unknown_metric(criterion.metric, detection, v2x)
        if problem is not None:
            raise BadInput(problem, file=file, field=field)


def check_system_under_test(spec: SimulationRunSpec, base_dir: Path, file: str) -> None:
    """A local system under test (`module`) can be imported and has its class (it is not constructed)."""
    sut = spec.system_under_test
    if sut is None or sut.module is None:
        return
    from simcore.sensors.loop import system_under_test_class  # numpy and the sensors: only for a system

    try:
        system_under_test_class(sut, base_dir)
    except BadInput as exc:
        raise BadInput(exc.detail, file=file, field=exc.field) from None


def check_controller_reachable(spec: SimulationRunSpec, transport: str, file: str) -> None:
    """A lockstep closed loop (`spec.control`) needs a controller that can answer: one in this process
    (`spec.systemUnderTest.module`) or one in another process over `--transport dds` / `loopback`. Without
    either, every step would wait for a command nobody can send (`startupTimeoutSeconds`, then retries): bad
    input at once instead."""
    control = spec.control
    if control is None or control.mode != "lockstep" or transport != "none":
        return
    sut = spec.system_under_test
    if sut is not None and sut.module is not None:
        return
    driven = ", ".join(control.entities) or "its externally controlled entities"
    raise BadInput(
        f"drives {driven} in lockstep, but no controller can reach this run: add --transport dds "
        "(or --transport loopback) and start your controller in another process (e.g. `python -m "
        "examples.controller --transport dds`), or set spec.systemUnderTest.module to run it in this process",
        file=file,
        field="spec.control",
    )
