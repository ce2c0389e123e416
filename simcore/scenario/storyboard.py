"""Storyboard state machines (OpenSCENARIO 1.x, clause 8.4): standby → running → complete, with the start,
end, stop and skip transitions that StoryboardElementStateConditions observe.

Pure bookkeeping: no world access. The engine decides when triggers fire and when actions finish.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Final


class State(Enum):
    STANDBY = "standbyState"
    RUNNING = "runningState"
    COMPLETE = "completeState"


class Transition(Enum):
    START = "startTransition"
    END = "endTransition"
    STOP = "stopTransition"
    SKIP = "skipTransition"


_STATES: Final = {s.value: s for s in State}
_TRANSITIONS: Final = {t.value: t for t in Transition}


@dataclass(eq=False)
class Node:
    """One storyboard element at run time."""

    kind: str  # storyboard, story, act, maneuverGroup, maneuver, event, action
    name: str
    definition: Any
    parent: Node | None = None
    children: list[Node] = field(default_factory=list)
    state: State = State.STANDBY
    executions: int = 0  # completed executions (events and maneuver groups)
    runtime: Any = None  # action runtime while running
    actors: tuple[str, ...] = ()
    # transitions so far, by name (an Enum member hashes in Python: conditions read these at every step)
    counts: dict[str, int] = field(default_factory=dict)

    def transition(self, transition: Transition, state: State, log: list[str], time: float) -> None:
        self.state = state
        name = transition.value
        self.counts[name] = self.counts.get(name, 0) + 1
        log.append(f"{time:8.3f} {self.kind} {self.name}: {name} → {state.value}")

    def walk(self) -> list[Node]:
        nodes = [self]
        for child in self.children:
            nodes.extend(child.walk())
        return nodes


def state_of(state_name: str) -> State | None:
    """The state a StoryboardElementStateCondition names (None: it names a transition, or nothing)."""
    return _STATES.get(state_name)


def transition_of(state_name: str) -> Transition | None:
    """The transition a StoryboardElementStateCondition names (None: it names a state)."""
    return _TRANSITIONS.get(state_name)


class Registry:
    """Storyboard elements by type and name, for StoryboardElementStateConditions."""

    def __init__(self, root: Node) -> None:
        self.by_key: dict[tuple[str, str], list[Node]] = {}
        for node in root.walk():
            self.by_key.setdefault((node.kind, node.name), []).append(node)

    def find(self, kind: str, name: str) -> list[Node]:
        found = self.by_key.get((kind, name), [])
        if found or "::" not in name:
            return found
        # a qualified name (esmini's "Event::Action"): the last part, whose ancestors carry the others
        parts = name.split("::")
        out = []
        for node in self.by_key.get((kind, parts[-1]), []):
            ancestors = []
            parent = node.parent
            while parent is not None:
                ancestors.append(parent.name)
                parent = parent.parent
            if all(p in ancestors for p in parts[:-1]):
                out.append(node)
        return out
