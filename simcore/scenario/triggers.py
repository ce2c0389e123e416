"""Triggers: OR over condition groups, AND within a group, with each condition's edge and delay (the
condition values themselves come from `simcore.scenario.conditions`)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from simcore.scenario.conditions import holds

if TYPE_CHECKING:
    from simcore.scenario import model as m
    from simcore.scenario.world import ScenarioWorld


@dataclass
class ConditionState:
    """Edge and delay bookkeeping of one condition instance."""

    condition: m.Condition
    previous: bool | None = None
    history: deque[tuple[float, bool]] = field(default_factory=deque)


class Triggers:
    """Evaluates the triggers of one run, remembering each condition's last value and delayed values."""

    def __init__(self, world: ScenarioWorld) -> None:
        self.world = world
        self.states: dict[int, ConditionState] = {}

    def _condition(self, cond: m.Condition, triggering: list[str]) -> bool:
        edge, delay = cond.edge, cond.delay
        if edge == "none" and delay <= 0:
            return holds(cond, self.world, triggering)  # no edge, no delay: nothing to remember
        state = self.states.get(id(cond))
        if state is None:
            state = self.states[id(cond)] = ConditionState(cond)
        value = holds(cond, self.world, triggering)
        # an edge needs a change: the first evaluation only records the value (as esmini does)
        previous = state.previous
        if previous is None:
            previous = value
        state.previous = value
        if edge == "rising":
            fired = value and not previous
        elif edge == "falling":
            fired = previous and not value
        elif edge == "risingOrFalling":
            fired = value != previous
        else:
            fired = value
        if delay <= 0:
            return fired
        now = self.world.time
        history = state.history
        history.append((now, fired))
        result = False
        due = now - delay + 1e-9
        while history and history[0][0] <= due:
            result = history.popleft()[1] or result
        return result

    def fire(self, trigger: m.Trigger | None, triggering: list[str] | None = None) -> bool:
        """OR over groups, AND within a group (as esmini: every group is evaluated; within a group, once a
        condition does not hold only the conditions with a delay are evaluated, their timers run on). When
        the trigger fires, its edge conditions start over (the next evaluation only records the value)."""
        if trigger is None:
            return False
        fired = False
        for group in trigger.groups:
            group_entities: list[str] = []
            ok = True
            for c in group:
                if ok or c.delay > 0:
                    ok = self._condition(c, group_entities) and ok
            if ok:
                fired = True
                if triggering is not None:
                    triggering.extend(group_entities)
        if fired:
            for group in trigger.groups:
                for c in group:
                    state = self.states.get(id(c))
                    if state is not None:
                        state.previous = None
        return fired
