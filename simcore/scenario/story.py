"""The storyboard at run time (OpenSCENARIO 1.x, clause 8.4): which acts, maneuver groups, events and actions
start, end and stop, and the actions that run now. Triggers come from `simcore.scenario.triggers`, action
runtimes from `simcore.scenario.action_registry`; the world only through `StoryWorld`."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Protocol

from simcore.scenario import global_actions
from simcore.scenario import model as m
from simcore.scenario.action_registry import make_runtime
from simcore.scenario.action_world import ActionWorld
from simcore.scenario.storyboard import Node, Registry, State, Transition

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.runtime import Runtime
    from simcore.scenario.triggers import Triggers


# the states and transitions as module globals: a member read from its Enum class (`State.RUNNING`) goes
# through a descriptor written in Python on Python 3.11, some 20 times slower, and the storyboard's states
# are read at every step
STANDBY, RUNNING, COMPLETE = State.STANDBY, State.RUNNING, State.COMPLETE
START, END, STOP, SKIP = Transition.START, Transition.END, Transition.STOP, Transition.SKIP


class StoryWorld(ActionWorld, Protocol):
    owner: Body | None  # the actor whose action runs now ("$owner")
    init_runtimes: list[Runtime]  # the Init actions still running


class StoryRun:
    """The storyboard's elements and their states in one run, and the action nodes running now."""

    def __init__(self, scenario: m.Scenario, world: StoryWorld, triggers: Triggers) -> None:
        self.scenario = scenario
        self.world = world
        self.triggers = triggers
        self.action_order: dict[int, int] = {}  # id of an action node → its place in the storyboard
        self.root = self.build()
        self.registry = Registry(self.root)
        self.running: dict[tuple[str, str], Node] = {}  # (actor, domain) → running action node
        # the running action nodes in the storyboard's order (None: `running` changed since they were listed)
        self._stepped: list[Node] | None = []
        self._transitions = 0  # state transitions so far, and how many there were at the last completion pass
        self._completed_at = -1

    def begin(self) -> None:
        """The storyboard and its stories start running (after Init)."""
        self.root.transition(START, RUNNING, self.world.log, 0.0)
        for story in self.root.children:
            story.transition(START, RUNNING, self.world.log, 0.0)

    def step_actions(self, dt: float) -> None:
        """Step the running actions in the storyboard's order (as esmini, not in the order they started);
        the ones done end, and completion moves up the tree."""
        nodes = self._stepped
        if nodes is None:
            nodes = list({id(n): n for n in self.running.values()}.values())
            if len(nodes) > 1:
                nodes.sort(key=lambda n: self.action_order.get(id(n), 0))
            self._stepped = nodes
        world = self.world
        for node in nodes:
            runtimes: list[Runtime] | None = node.runtime
            if not runtimes:
                continue
            for runtime in runtimes:
                world.owner = runtime.actor
                runtime.step(dt)
            for runtime in runtimes:
                if not runtime.done:
                    break
            else:  # all done
                self.release(node)
                self.set(node, END, COMPLETE)
        self.complete_elements()

    def end_finished_actions(self) -> None:
        """The actions whose runtimes are all done end now (one finished while moving its entity)."""
        for node in list({id(n): n for n in self.running.values()}.values()):
            runtimes = node.runtime or []
            if runtimes and all(r.done for r in runtimes):
                self.release(node)
                self.set(node, END, COMPLETE)
        self.complete_elements()

    def stop_action_of(self, actor: str, domain: str) -> None:
        """Stop the action running on `actor` in `domain` (a controller took it over)."""
        running = self.running.get((actor, domain))
        if running is not None:
            self.release(running)
            self.set(running, STOP, COMPLETE)

    def build(self) -> Node:
        root = Node("storyboard", "storyboard", None)
        for story in self.scenario.stories:
            s = Node("story", story.name, story, root)
            root.children.append(s)
            for act in story.acts:
                a = Node("act", act.name, act, s)
                s.children.append(a)
                for group in act.groups:
                    g = Node("maneuverGroup", group.name, group, a, actors=group.actors)
                    a.children.append(g)
                    for maneuver in group.maneuvers:
                        mv = Node("maneuver", maneuver.name, maneuver, g)
                        g.children.append(mv)
                        for event in maneuver.events:
                            e = Node("event", event.name, event, mv)
                            mv.children.append(e)
                            for action in event.actions:
                                node = Node("action", action.name, action, e)
                                e.children.append(node)
                                self.action_order[id(node)] = len(self.action_order)
        return root

    def set(self, node: Node, transition: Transition, state: State) -> None:
        node.transition(transition, state, self.world.log, self.world.time)
        self._transitions += 1

    def stop(self, node: Node) -> None:
        for child in node.children:
            if child.state != COMPLETE:
                self.stop(child)
        if node.kind == "action":
            self.release(node)
        if node.state != COMPLETE:
            self.set(node, STOP, COMPLETE)

    def release(self, node: Node) -> None:
        for key, running in list(self.running.items()):
            if running is node:
                del self.running[key]
                self._stepped = None
        for runtime in node.runtime or ():
            if not runtime.done:
                runtime.stop()  # stopped before it was done (overridden, or its event stopped)
        node.runtime = None

    def start_group(self, group: Node) -> None:
        self.set(group, START, RUNNING)
        for maneuver in group.children:
            maneuver.state = STANDBY
            maneuver.executions = 0
            self.set(maneuver, START, RUNNING)
            for event in maneuver.children:
                event.state = STANDBY
                event.executions = 0
                for action in event.children:
                    action.state = STANDBY

    def start_event(self, event: Node, actors: tuple[str, ...]) -> None:
        definition: m.Event = event.definition
        maneuver = event.parent
        assert maneuver is not None
        others = [e for e in maneuver.children if e is not event and e.state == RUNNING]
        if definition.priority == "skip" and others:
            self.set(event, SKIP, STANDBY)
            return
        if definition.priority in ("override", "overwrite"):
            for other in others:
                self.stop(other)
                other.executions += 1
        self.set(event, START, RUNNING)
        for action in event.children:
            self.set(action, START, RUNNING)
            self.start_action(action, actors)

    def start_action(self, node: Node, actors: tuple[str, ...]) -> None:
        action: m.Action = node.definition
        if action.private is None:
            if action.global_action is not None:
                global_actions.run(self.world, action.global_action)
            self.set(node, END, COMPLETE)
            return
        runtimes = []
        for actor_name in actors:
            body = self.world.body(actor_name)
            runtime = make_runtime(self.world, body, action.private)
            self.world.owner = body
            key = (actor_name, runtime.domain)
            previous = self.running.get(key)
            if previous is not None and previous is not node:
                # a new action of the same domain on the same actor overrides the running one
                self.release(previous)
                self.set(previous, STOP, COMPLETE)
            self.running[key] = node
            self._stepped = None
            # an Init action still running in this domain (a distance kept from the start) is overridden too
            self.world.init_runtimes = [
                r for r in self.world.init_runtimes if not (r.actor is body and r.domain == runtime.domain)
            ]
            runtime.start()
            runtimes.append(runtime)
        node.runtime = runtimes
        if all(r.done for r in runtimes):
            self.release(node)
            self.set(node, END, COMPLETE)

    def check_stop(self) -> bool:
        """The storyboard's StopTrigger: when it fires, every element stops."""
        if self.triggers.fire(self.scenario.stop_trigger):
            self.stop(self.root)
            return True
        return False

    def evaluate(self) -> None:
        """Start the acts, maneuver groups and events whose triggers fire; stop acts whose stop trigger fires."""
        for story in self.root.children:
            for act in story.children:
                definition: m.Act = act.definition
                if act.state == STANDBY:
                    if definition.start_trigger is None or self.triggers.fire(definition.start_trigger):
                        self.set(act, START, RUNNING)
                        for group in act.children:
                            self.start_group(group)
                elif (
                    act.state == RUNNING
                    and definition.stop_trigger is not None
                    and self.triggers.fire(definition.stop_trigger)
                ):
                    self.stop(act)
                    continue
                if act.state != RUNNING:
                    continue
                # (each element's state is read when it is reached: starting an event may stop others)
                for group in act.children:
                    if group.state != RUNNING:
                        continue
                    for maneuver in group.children:
                        if maneuver.state != RUNNING:
                            continue
                        for event in maneuver.children:
                            if event.state != STANDBY:
                                continue
                            ev: m.Event = event.definition
                            gdef: m.ManeuverGroup = group.definition
                            # the entities that trigger it, where they are the actors
                            triggering: list[str] | None = [] if gdef.select_triggering_entities else None
                            if ev.start_trigger is None or self.triggers.fire(ev.start_trigger, triggering):
                                actors = gdef.actors
                                if triggering:
                                    actors = tuple(dict.fromkeys(triggering))
                                self.start_event(event, actors)

    def complete_elements(self) -> None:
        # completion follows from the states of the children: nothing to do while no element changed state
        if self._transitions == self._completed_at:
            return
        self._completed_at = self._transitions
        for story in self.root.children:
            for act in _running(story.children):
                for group in _running(act.children):
                    for maneuver in _running(group.children):
                        for event in maneuver.children:
                            if event.state == RUNNING and all(a.state == COMPLETE for a in event.children):
                                event.executions += 1
                                if event.executions < event.definition.maximum_execution_count:
                                    self.set(event, END, STANDBY)
                                    for action in event.children:
                                        action.state = STANDBY
                                else:
                                    self.set(event, END, COMPLETE)
                        if all(
                            e.state == COMPLETE or e.executions >= e.definition.maximum_execution_count
                            for e in maneuver.children
                        ):
                            self.set(maneuver, END, COMPLETE)
                    if all(mv.state == COMPLETE for mv in group.children):
                        group.executions += 1
                        if group.executions < group.definition.maximum_execution_count:
                            self.start_group(group)
                        else:
                            self.set(group, END, COMPLETE)
                if all(g.state == COMPLETE for g in act.children):
                    self.set(act, END, COMPLETE)
            if story.state == RUNNING and all(a.state == COMPLETE for a in story.children):
                self.set(story, END, COMPLETE)


def _running(nodes: list[Node]) -> Iterator[Node]:
    """The nodes that are running when reached (their states may change while the caller goes through them)."""
    return (node for node in nodes if node.state == RUNNING)
