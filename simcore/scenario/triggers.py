"""Triggers: OR over condition groups, AND within a group, with each condition's edge and delay (the
condition values themselves come from `simcore.scenario.conditions`)."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

from simcore.scenario.conditions import VALUE_CONDITIONS, ValueEvaluator, holds

if TYPE_CHECKING:
    from simcore.scenario import model as m
    from simcore.scenario.world import ScenarioWorld


class ConditionState:
    """Edge and delay bookkeeping of one condition instance, and its evaluation (found once: a value
    condition's evaluator is called directly, an entity condition goes through `holds`)."""

    __slots__ = ("condition", "delay", "edge", "evaluate", "history", "previous", "value_condition")

    def __init__(self, condition: m.Condition) -> None:
        self.condition = condition
        self.edge = condition.edge
        self.delay = condition.delay
        self.previous: bool | None = None
        # the times at which the condition fired, until its delay has passed (a delayed condition fires
        # then; the times it did not fire need no keeping)
        self.history: deque[float] = deque()
        self.value_condition: Any = condition.value_condition
        self.evaluate: ValueEvaluator | None = (
            VALUE_CONDITIONS.get(type(self.value_condition)) if self.value_condition is not None else None
        )


class Triggers:
    """Evaluates the triggers of one run, remembering each condition's last value and delayed values."""

    def __init__(self, world: ScenarioWorld) -> None:
        self.world = world
        self.states: dict[int, ConditionState] = {}  # by id of the condition (kept alive by its state)
        # each trigger's groups of condition states, by id of the trigger (kept alive by the entry)
        self._groups: dict[int, tuple[m.Trigger, tuple[tuple[ConditionState, ...], ...]]] = {}

    def _state(self, cond: m.Condition) -> ConditionState:
        state = self.states.get(id(cond))
        if state is None or state.condition is not cond:
            state = self.states[id(cond)] = ConditionState(cond)
        return state

    def _groups_of(self, trigger: m.Trigger) -> tuple[tuple[ConditionState, ...], ...]:
        entry = self._groups.get(id(trigger))
        if entry is None or entry[0] is not trigger:
            groups = tuple(tuple(self._state(c) for c in group) for group in trigger.groups)
            entry = self._groups[id(trigger)] = (trigger, groups)
        return entry[1]

    def _condition(self, state: ConditionState, triggering: list[str]) -> bool:
        evaluate = state.evaluate
        if evaluate is not None:
            value = evaluate(state.value_condition, self.world)
        else:
            value = holds(state.condition, self.world, triggering)
        edge, delay = state.edge, state.delay
        if edge == "none" and delay <= 0:
            return value  # no edge, no delay: nothing to remember
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
        if fired:
            history.append(now)
        result = False
        due = now - delay + 1e-9
        while history and history[0] <= due:
            history.popleft()
            result = True
        return result

    def fire(self, trigger: m.Trigger | None, triggering: list[str] | None = None) -> bool:
        """OR over groups, AND within a group (as esmini: every group is evaluated; within a group, once a
        condition does not hold only the conditions with a delay are evaluated, their timers run on). When
        the trigger fires, its edge conditions start over (the next evaluation only records the value)."""
        if trigger is None:
            return False
        groups = self._groups_of(trigger)
        fired = False
        for group in groups:
            group_entities: list[str] = []
            ok = True
            for state in group:
                if ok or state.delay > 0:
                    ok = self._condition(state, group_entities) and ok
            if ok:
                fired = True
                if triggering is not None:
                    triggering.extend(group_entities)
        if fired:
            for group in groups:
                for state in group:
                    state.previous = None
        return fired
