"""Traffic signals: the state each signal shows, and the phase cycles of the signal controllers
(RoadNetwork/TrafficSignals) that set them."""

from __future__ import annotations

from simcore.errors import BadInput
from simcore.scenario import model as m


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
