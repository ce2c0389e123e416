"""Traffic signals: the state each signal shows, and the phase cycles of the signal controllers
(RoadNetwork/TrafficSignals) that set them."""

from __future__ import annotations

from typing import TYPE_CHECKING

from simcore.errors import BadInput
from simcore.scenario import model as m

if TYPE_CHECKING:
    from simcore.scenario.storyboard import Node
    from simcore.world.opendrive import OpenDrive


class SignalControllers:
    """The signal states and controller phases of one run."""

    def __init__(self, controllers: tuple[m.SignalController, ...]) -> None:
        self.controllers = {c.name: c for c in controllers}
        # controller → (time its current cycle was anchored, phase index then)
        self.cycles: dict[str, tuple[float, int]] = _signal_starts(controllers)
        self.signals: dict[str, str] = {}  # signal (id or name the scenario uses) → the state it shows
        self.phases: dict[str, str] = {}  # controller → its current phase

    def set_phase(self, controller: str, phase: str, time: float, source: str) -> None:
        """TrafficSignalControllerAction: `controller` restarts its cycle at `phase` now."""
        ctrl = self.controllers.get(controller)
        if ctrl is None:
            raise BadInput(
                f"TrafficSignalControllerAction: no TrafficSignalController {controller!r} in "
                "RoadNetwork/TrafficSignals",
                file=source,
            )
        names = [p.name for p in ctrl.phases]
        if phase not in names:
            raise BadInput(
                f"TrafficSignalControllerAction: controller {ctrl.name!r} has no phase {phase!r} "
                f"(phases: {', '.join(names)})",
                file=source,
            )
        self.cycles[ctrl.name] = (time, names.index(phase))
        self.update(time)

    def update(self, time: float) -> None:
        """Signal controllers: the phase each is in now, and the signal states that phase sets."""
        for name, (anchor, index) in self.cycles.items():
            ctrl = self.controllers[name]
            if not ctrl.phases or time < anchor - 1e-9:
                continue
            total = sum(p.duration for p in ctrl.phases)
            elapsed = (time - anchor) % total if total > 0 else 0.0
            n = len(ctrl.phases)
            i = index
            for _ in range(n):
                duration = ctrl.phases[i].duration
                if elapsed < duration - 1e-9:
                    break
                elapsed -= duration
                i = (i + 1) % n
            phase = ctrl.phases[i]
            if self.phases.get(name) != phase.name:
                self.phases[name] = phase.name
                for signal, state in phase.states:
                    self.signals[signal] = state


def unknown_signals(scenario: m.Scenario, root: Node, road: OpenDrive, source: str) -> list[str]:
    """Warnings about the traffic signals the scenario names (by id or name) that the road network lacks."""
    known = set(road.signals) | {n for n in road.signals.values() if n}
    named: dict[str, str] = {}
    for item in scenario.init:
        if isinstance(item.action, m.TrafficSignalStateAction):
            named.setdefault(item.action.name, "TrafficSignalStateAction")
    for ctrl in scenario.signal_controllers:
        for phase in ctrl.phases:
            for signal, _ in phase.states:
                named.setdefault(signal, f"TrafficSignalController[{ctrl.name}]")
    for node in root.walk():
        definition = node.definition
        if isinstance(definition, m.Action) and isinstance(
            definition.global_action, m.TrafficSignalStateAction
        ):
            named.setdefault(definition.global_action.name, "TrafficSignalStateAction")
        triggers = (getattr(definition, "start_trigger", None), getattr(definition, "stop_trigger", None))
        for trigger in triggers:
            for group in trigger.groups if trigger is not None else ():
                for cond in group:
                    if isinstance(cond.value_condition, m.TrafficSignalCondition):
                        named.setdefault(cond.value_condition.name, "TrafficSignalCondition")
    for trigger_ in (scenario.stop_trigger,):
        for group in trigger_.groups if trigger_ is not None else ():
            for cond in group:
                if isinstance(cond.value_condition, m.TrafficSignalCondition):
                    named.setdefault(cond.value_condition.name, "TrafficSignalCondition")
    ids = ", ".join(sorted(road.signals)) or "none"
    return [
        f"{source}: {where}: traffic signal {name!r} is not a <signal> of the road network {road.name} (ids: {ids})"
        for name, where in named.items()
        if name not in known
    ]


def _signal_starts(controllers: tuple[m.SignalController, ...]) -> dict[str, tuple[float, int]]:
    """When each signal controller starts its first phase: its delay, counted from the start of the
    controller it references (if any)."""
    by_name = {c.name: c for c in controllers}
    out: dict[str, tuple[float, int]] = {}
    for ctrl in controllers:
        start = 0.0
        seen: set[str] = set()
        current: m.SignalController | None = ctrl
        while current is not None and current.name not in seen:
            seen.add(current.name)
            start += current.delay
            current = by_name.get(current.reference) if current.reference else None
        out[ctrl.name] = (start, 0)
    return out
