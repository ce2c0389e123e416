"""Triggers: OR over condition groups, AND within a group, with each condition's edge and delay (the
condition values themselves come from `simcore.scenario.conditions`)."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

from simcore.scenario.conditions import Bound, bind

if TYPE_CHECKING:
    from simcore.scenario import model as m
    from simcore.scenario.world import ScenarioWorld


class ConditionState:
    """Edge and delay bookkeeping of one condition instance, and its evaluation: `check` gives whether it
    fires now. The condition is bound to the world (`conditions.bind`) at its first evaluation, which raises
    what evaluating it would; a condition without edge and delay is then checked by its value itself."""

    __slots__ = ("check", "condition", "delay", "edge", "history", "previous", "value", "world")

    def __init__(self, condition: m.Condition, world: ScenarioWorld) -> None:
        self.condition = condition
        self.world = world
        self.edge = condition.edge
        self.delay = condition.delay
        self.previous: bool | None = None
        # the times at which the condition fired, until its delay has passed (a delayed condition fires
        # then; the times it did not fire need no keeping)
        self.history: deque[float] = deque()
        self.value: Bound = self._unbound
        self.check: Bound = self._first

    @staticmethod
    def _unbound(triggering: list[str] | None) -> bool:
        raise AssertionError("a condition's value is read after its first check")

    def _first(self, triggering: list[str] | None) -> bool:
        self.value = bind(self.condition, self.world)
        undelayed = self.delay <= 0
        if undelayed and self.edge == "none":
            self.check = self.value
        elif undelayed and self.edge == "rising":
            self.check = self._rising
        else:
            self.check = self._edged
        return self.check(triggering)

    def _rising(self, triggering: list[str] | None) -> bool:
        """`_edged` for the commonest edged condition: rising, without delay."""
        value = self.value(triggering)
        previous = self.previous
        self.previous = value
        return value and not (value if previous is None else previous)

    def _edged(self, triggering: list[str] | None) -> bool:
        value = self.value(triggering)
        # an edge needs a change: the first evaluation only records the value (as esmini does)
        previous = self.previous
        if previous is None:
            previous = value
        self.previous = value
        edge = self.edge
        if edge == "rising":
            fired = value and not previous
        elif edge == "falling":
            fired = previous and not value
        elif edge == "risingOrFalling":
            fired = value != previous
        else:
            fired = value
        delay = self.delay
        if delay <= 0:
            return fired
        now = self.world.time
        history = self.history
        if fired:
            history.append(now)
        result = False
        due = now - delay + 1e-9
        while history and history[0] <= due:
            history.popleft()
            result = True
        return result


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
            state = self.states[id(cond)] = ConditionState(cond, self.world)
        return state

    def _groups_of(self, trigger: m.Trigger) -> tuple[tuple[ConditionState, ...], ...]:
        """The condition states of a trigger fired for the first time."""
        groups = tuple(tuple(self._state(c) for c in group) for group in trigger.groups)
        self._groups[id(trigger)] = (trigger, groups)
        return groups

    def fire(self, trigger: m.Trigger | None, triggering: list[str] | None = None) -> bool:
        """OR over groups, AND within a group (as esmini: every group is evaluated; within a group, once a
        condition does not hold only the conditions with a delay are evaluated, their timers run on). When
        the trigger fires, its edge conditions start over (the next evaluation only records the value).
        The entities that fulfil the entity conditions of the groups that hold are added to `triggering`."""
        if trigger is None:
            return False
        entry = self._groups.get(id(trigger))
        groups = entry[1] if entry is not None and entry[0] is trigger else self._groups_of(trigger)
        fired = False
        for group in groups:
            # the entities a group adds are taken back when the group does not hold
            mark = 0 if triggering is None else len(triggering)
            ok = True
            for state in group:
                if ok or state.delay > 0:
                    ok = state.check(triggering) and ok
            if ok:
                fired = True
            elif triggering is not None:
                del triggering[mark:]
        if fired:
            for group in groups:
                for state in group:
                    state.previous = None
        return fired
