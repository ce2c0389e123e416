"""Sensors, the system under test and the detection evaluation of one run, around the simulation loop.

The runner creates a `PerceptionLoop` after its recorder subscribed to the bus, calls `step(frame)` after
publishing each frame and `close()` at the end; `metrics()` gives the `detection.*` metrics.

Order on the bus (synchronous in-process delivery): the evaluator subscribes before the system under
test is constructed, so it sees every detection; a sensor's messages go out in the frame they are due, and
an in-process node reacting to them publishes within the same frame.
"""

from __future__ import annotations

import importlib
import inspect
import sys
from pathlib import Path
from typing import Any

from simcore.errors import BadInput
from simcore.spec import SimulationRunSpec, SystemUnderTest
from simcore.transport.bus import Bus
from simcore.world.opendrive import OpenDrive
from simcore.world.state import WorldFrame


def load_system_under_test(sut: SystemUnderTest, bus: Bus, base_dir: Path | None) -> Any:
    """Import `sut.module` (`package.module:Class`) and construct `Class(bus, **sut.parameters)`."""
    field = "spec.systemUnderTest.module"
    assert sut.module is not None
    module_name, _, class_name = sut.module.partition(":")
    for entry in reversed(sut.python_path):
        folder = str(((base_dir or Path.cwd()) / entry).resolve())
        if folder not in sys.path:
            sys.path.insert(0, folder)
    cwd = str(Path.cwd())
    if cwd not in sys.path:
        sys.path.append(cwd)
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BadInput(
            f"cannot import {module_name!r}: {exc}; put its folder in systemUnderTest.pythonPath "
            "(relative to the manifest) or run from the folder that contains it",
            field=field,
        ) from None
    node_class = getattr(module, class_name, None)
    if node_class is None or not callable(node_class):
        raise BadInput(f"{module_name!r} has no class {class_name!r}", field=field)
    try:
        inspect.signature(node_class).bind(bus, **sut.parameters)
    except TypeError as exc:
        raise BadInput(
            f"{sut.module} does not take these parameters: {exc}", field="spec.systemUnderTest.parameters"
        ) from None
    except ValueError:
        pass  # no signature to check (a builtin): let the call decide
    try:
        return node_class(bus, **sut.parameters)
    except (TypeError, ValueError) as exc:
        raise BadInput(
            f"{sut.module} refused its parameters: {exc}", field="spec.systemUnderTest.parameters"
        ) from None


class PerceptionLoop:
    def __init__(
        self,
        spec: SimulationRunSpec,
        bus: Bus,
        *,
        road: OpenDrive | None,
        road_file: Path | None,
        seed: int,
        base_dir: Path | None = None,
    ) -> None:
        self.rig = None
        self.evaluator = None
        self.node: Any = None
        self._time = 0.0
        if spec.sensors:
            from simcore.sensors.rig import SensorRig

            self.rig = SensorRig(spec.sensors, road, bus, seed, road_file=road_file)
        if spec.evaluation.detection is not None:
            from simcore.evaluation.detection import DetectionEvaluator, ranges_of

            criteria = [*spec.evaluation.criteria, *(c for s in spec.scenarios for c in s.criteria)]
            self.evaluator = DetectionEvaluator(
                spec.evaluation.detection, ranges_of(c.metric for c in criteria)
            )
            self.evaluator.attach(bus)
        sut = spec.system_under_test
        if sut is not None and sut.module is not None:
            self.node = load_system_under_test(sut, bus, base_dir)

    def step(self, frame: WorldFrame) -> None:
        self._time = frame.time
        if self.rig is not None:
            self.rig.step(frame)

    def close(self) -> None:
        """Close the node, and publish the scores of the sweeps not scored yet (the bus is still open)."""
        if self.evaluator is not None:
            self.evaluator.flush(self._time)
        node, self.node = self.node, None
        close = getattr(node, "close", None)
        if callable(close):
            close()

    def metrics(self) -> dict[str, float]:
        return self.evaluator.result() if self.evaluator is not None else {}
