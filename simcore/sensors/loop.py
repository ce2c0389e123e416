"""Sensors, the system under test and the detection evaluation of one run, around the simulation loop.

The runner creates a `PerceptionLoop` after its recorder subscribed to the bus, calls `step(frame)` after
publishing each frame and `close()` at the end; `metrics()` gives the `detection.*` metrics.

Order on the bus (synchronous in-process delivery): the evaluator subscribes before the system under
test is constructed, so it sees every detection; a sensor's messages go out in the frame they are due, and
an in-process node reacting to them publishes within the same frame.

The node gets a guarded view of the bus: when one of its callbacks raises, the node is stopped (it receives
nothing more), the run goes on, the error is published once on `/carlos/<sut name>/status`
(diagnostic_msgs/DiagnosticStatus, level ERROR, recorded) and logged, and the metric
`systemUnderTest.failed` is 1 (0 while it ran without an error): a crash of the software under test is a
test result (its detection criteria fail, or a criterion `systemUnderTest.failed == 0`), not an
infrastructure error of the simulator.
"""

from __future__ import annotations

import importlib
import inspect
import logging
import os
import sys
import traceback
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from simcore.errors import BadInput
from simcore.spec import SimulationRunSpec, SystemUnderTest
from simcore.transport.bus import Bus, Callback, Message, Publisher
from simcore.world.infrastructure import unit_pose
from simcore.world.opendrive import OpenDrive
from simcore.world.state import WorldFrame

log = logging.getLogger("carlos.sut")


class GuardedBus:
    """The bus as the system under test sees it: its callbacks stop at its first exception."""

    def __init__(self, bus: Bus, name: str) -> None:
        self.bus = bus
        self.name = name
        self.error: str | None = None
        self.error_time = 0.0

    def advertise(self, topic: str, typename: str) -> Publisher:
        return self.bus.advertise(topic, typename)

    def subscribe(self, pattern: str, callback: Callback) -> None:
        def guarded(message: Message) -> None:
            if self.error is not None:
                return
            try:
                callback(message)
            except Exception as exc:  # the software under test failed: a test result, reported below
                self.error = (
                    f"{type(exc).__name__}: {exc} (handling {message.topic} at t={message.time_s:g} s)"
                )
                self.error_time = message.time_s
                log.warning(
                    "system under test %s stopped: %s\n%s", self.name, self.error, traceback.format_exc()
                )

        self.bus.subscribe(pattern, guarded)

    def close(self) -> None:
        """The node does not close the run's bus."""


def node_environment(sut: SystemUnderTest, environ: Mapping[str, str]) -> dict[str, str]:
    """The variables `sut.env` sets for an in-process node: the values, and each `secretKeyRef` taken from
    the variable of the same name in `environ` (a local run has no Secrets to read)."""
    out: dict[str, str] = {}
    for position, var in enumerate(sut.env):
        if var.value is not None:
            out[var.name] = var.value
        elif var.name in environ:
            out[var.name] = environ[var.name]
        else:
            ref = var.secret_key_ref
            assert ref is not None
            raise BadInput(
                f"{var.name} comes from Secret {ref.name!r} (key {ref.key!r}) on a cluster; a local run takes "
                f"it from its own environment: export {var.name}=… before `carlos run`",
                field=f"spec.systemUnderTest.env[{position}].secretKeyRef",
            )
    return out


def system_under_test_class(sut: SystemUnderTest, base_dir: Path | None) -> Any:
    """Import `sut.module` (`package.module:Class`) and check that `Class(bus, **sut.parameters)` fits its
    signature, names and (annotated as bool, int, float or str) types: bad input before any run."""
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
        signature = inspect.signature(node_class, eval_str=True)
        signature.bind(None, **sut.parameters)
    except TypeError as exc:
        raise BadInput(
            f"{sut.module} does not take these parameters: {exc}", field="spec.systemUnderTest.parameters"
        ) from None
    except (ValueError, NameError):
        return node_class  # no signature to check (a builtin, an unresolvable annotation): the call decides
    for name, value in sut.parameters.items():
        parameter = signature.parameters.get(name)
        if parameter is not None and not _fits(value, parameter.annotation):
            raise BadInput(
                f"{sut.module} takes {name} as {_type_name(parameter.annotation)}, not {value!r}",
                field=f"spec.systemUnderTest.parameters.{name}",
            )
    return node_class


_SIMPLE_TYPES: dict[Any, Callable[[Any], bool]] = {
    bool: lambda v: isinstance(v, bool),
    int: lambda v: isinstance(v, int) and not isinstance(v, bool),
    float: lambda v: isinstance(v, int | float) and not isinstance(v, bool),
    str: lambda v: isinstance(v, str),
    type(None): lambda v: v is None,
}


def _fits(value: Any, annotation: Any) -> bool:
    """Whether a YAML value fits a simple annotation (bool, int, float, str, None or a union of them); any
    other annotation is left to the class."""
    options = (
        typing.get_args(annotation)
        if isinstance(annotation, types.UnionType) or (typing.get_origin(annotation) is typing.Union)
        else (annotation,)
    )
    if not all(option in _SIMPLE_TYPES for option in options):
        return True
    return any(_SIMPLE_TYPES[option](value) for option in options)


def _type_name(annotation: Any) -> str:
    return getattr(annotation, "__name__", None) or str(annotation)


def load_system_under_test(sut: SystemUnderTest, bus: Bus, base_dir: Path | None) -> Any:
    """Import `sut.module` (`package.module:Class`) and construct `Class(bus, **sut.parameters)`."""
    node_class = system_under_test_class(sut, base_dir)
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
        parameters: Mapping[str, Any] | None = None,
    ) -> None:
        self.rig = None
        self.evaluator = None
        self.node: Any = None
        self.guard: GuardedBus | None = None
        self._bus = bus
        self._time = 0.0
        units = [
            (unit_pose(rsu, index, road, parameters or {}), rsu.sensors)
            for index, rsu in enumerate(spec.infrastructure)
            if rsu.sensors
        ]
        if spec.sensors or units:
            from simcore.sensors.rig import SensorRig

            self.rig = SensorRig(spec.sensors, road, bus, seed, road_file=road_file, units=units)
        if spec.evaluation.detection is not None:
            from simcore.evaluation.criteria import ranges_of
            from simcore.evaluation.detection import DetectionEvaluator

            criteria = [*spec.evaluation.criteria, *(c for s in spec.scenarios for c in s.criteria)]
            self.evaluator = DetectionEvaluator(
                spec.evaluation.detection, ranges_of(c.metric for c in criteria)
            )
            self.evaluator.attach(bus)
        self._saved_env: dict[str, str | None] = {}
        sut = spec.system_under_test
        if sut is not None and sut.module is not None:
            self.guard = GuardedBus(bus, sut.name)
            env = node_environment(sut, os.environ)
            self._saved_env = {name: os.environ.get(name) for name in env}
            os.environ.update(env)  # the run's process is the node's: restored in close()
            try:
                self.node = load_system_under_test(sut, self.guard, base_dir)
            except BaseException:
                self._restore_env()
                raise

    def step(self, frame: WorldFrame) -> None:
        self._time = frame.time
        if self.rig is not None:
            self.rig.step(frame)
        if self.guard is not None and self.guard.error is not None and not self._reported:
            self._reported = True
            self._report_failure()

    _reported = False

    def _report_failure(self) -> None:
        from simcore.transport.messages import TYPESTORE, ros_name

        assert self.guard is not None
        status = TYPESTORE.types["diagnostic_msgs/msg/DiagnosticStatus"]
        kv = TYPESTORE.types["diagnostic_msgs/msg/KeyValue"]
        msg = status(
            level=2,  # ERROR
            name=self.guard.name,
            message=self.guard.error or "",
            hardware_id="",
            values=[kv(key="state", value="failed"), kv(key="time", value=repr(self.guard.error_time))],
        )
        topic = f"/carlos/{ros_name(self.guard.name)}/status"
        self._bus.advertise(topic, "diagnostic_msgs/msg/DiagnosticStatus").publish(msg, self._time)

    def close(self) -> None:
        """Close the node, and publish the scores of the sweeps not scored yet (the bus is still open)."""
        if self.guard is not None and self.guard.error is not None and not self._reported:
            self._reported = True
            self._report_failure()
        if self.evaluator is not None:
            self.evaluator.flush(self._time)
        node, self.node = self.node, None
        close = getattr(node, "close", None)
        try:
            if callable(close):
                close()
        finally:
            self._restore_env()

    def _restore_env(self) -> None:
        saved, self._saved_env = self._saved_env, {}
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value

    def metrics(self) -> dict[str, float]:
        out = self.evaluator.result() if self.evaluator is not None else {}
        if self.guard is not None:
            out["systemUnderTest.failed"] = 1.0 if self.guard.error is not None else 0.0
        return out

    @property
    def failure(self) -> str | None:
        """The system under test's error, if it failed."""
        return self.guard.error if self.guard is not None else None
