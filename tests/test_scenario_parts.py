"""The parts of the scenario engine on their own: the registries cover every OpenSCENARIO type of the model,
and conditions and triggers work against any `ScenarioWorld` (here a small stand-in, no engine)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast, get_args

import pytest

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario.action_registry import PRIVATE_ACTIONS
from simcore.scenario.conditions import ENTITY_CONDITIONS, VALUE_CONDITIONS, holds
from simcore.scenario.global_actions import GLOBAL_ACTIONS
from simcore.scenario.motion import Body
from simcore.scenario.triggers import Triggers
from simcore.scenario.world import ScenarioWorld


def test_every_condition_type_has_an_evaluation() -> None:
    assert set(get_args(m.ValueCondition)) <= set(VALUE_CONDITIONS)
    assert set(get_args(m.EntityCondition)) <= set(ENTITY_CONDITIONS)


def test_every_action_type_has_an_implementation() -> None:
    assert set(get_args(m.PrivateAction)) == set(PRIVATE_ACTIONS)
    assert set(get_args(m.GlobalAction)) == set(GLOBAL_ACTIONS)


def _entity(name: str) -> m.Entity:
    return m.Entity(name, "vehicle", "car", m.Box(1.4, 0.0, 0.75, 4.5, 1.8, 1.5), m.Performance())


@dataclass
class StandIn:
    """The members of ScenarioWorld that speed and time conditions read."""

    bodies: dict[str, Body]
    time: float = 0.0
    source: str = "stand-in.xosc"
    memo: dict[Any, Any] = field(default_factory=dict)

    def body(self, name: str) -> Body:
        return self.bodies[name]


def _world(*names: str) -> tuple[StandIn, ScenarioWorld]:
    stand_in = StandIn({n: Body(entity=_entity(n)) for n in names})
    return stand_in, cast(ScenarioWorld, stand_in)


def _faster_than(value: float, *entities: str, edge: m.Edge = "none", rule: str = "any") -> m.Condition:
    return m.Condition(
        "fast",
        0.0,
        edge,
        entity_condition=m.SpeedCondition(value, "greaterThan"),
        triggering_entities=entities,
        triggering_rule=rule,  # type: ignore[arg-type]
    )


def test_an_entity_condition_names_the_entities_that_trigger_it() -> None:
    stand_in, world = _world("A", "B", "C")
    stand_in.bodies["B"].speed = 20.0
    stand_in.bodies["C"].speed = 30.0
    triggering: list[str] = []
    assert holds(_faster_than(10.0, "A", "B", "C"), world, triggering)
    assert triggering == ["B"]  # "any" stops at the first entity that fulfils it
    assert not holds(_faster_than(10.0, "A", "B", "C", rule="all"), world, [])
    stand_in.bodies["A"].gone = True  # entities out of the world are skipped
    triggering = []
    assert holds(_faster_than(10.0, "A", "B", "C", rule="all"), world, triggering)
    assert triggering == ["B", "C"]


def test_a_rising_edge_fires_once_on_the_change_and_not_on_the_first_evaluation() -> None:
    stand_in, world = _world("A")
    stand_in.bodies["A"].speed = 20.0
    triggers = Triggers(world)
    trigger = m.Trigger(((_faster_than(10.0, "A", edge="rising"),),))
    assert not triggers.fire(trigger)  # already true at the first evaluation: no edge
    stand_in.bodies["A"].speed = 5.0
    assert not triggers.fire(trigger)
    stand_in.bodies["A"].speed = 15.0
    assert triggers.fire(trigger)
    assert not triggers.fire(trigger)  # still true, no new edge


def test_a_delayed_condition_fires_its_delay_later() -> None:
    stand_in, world = _world("A")
    condition = m.Condition(
        "late", 1.0, "none", value_condition=m.SimulationTimeCondition(0.5, "greaterThan")
    )
    triggers = Triggers(world)
    trigger = m.Trigger(((condition,),))
    fired = []
    for step in range(40):
        stand_in.time = step * 0.05
        if triggers.fire(trigger):
            fired.append(round(stand_in.time, 2))
    assert fired[0] == pytest.approx(1.55)  # true from t=0.55, fired one second later


def test_an_unknown_condition_type_is_bad_input_naming_it() -> None:
    @dataclass(frozen=True)
    class HoverCondition:
        height: float

    _, world = _world("A")
    condition = m.Condition(
        "hover", 0.0, "none", entity_condition=HoverCondition(1.0), triggering_entities=("A",)
    )  # type: ignore[arg-type]
    with pytest.raises(BadInput, match="HoverCondition is not supported"):
        holds(condition, world, [])


def test_a_group_that_does_not_hold_adds_no_triggering_entity() -> None:
    """The entities of a group are the trigger's only when the whole group holds (AND within it), and those
    of every group that holds are (OR over groups, in their order)."""
    stand_in, world = _world("A", "B", "C")
    stand_in.bodies["A"].speed = 20.0
    stand_in.bodies["C"].speed = 30.0
    held_not = (_faster_than(10.0, "A"), _faster_than(10.0, "B"))  # A holds, B does not
    trigger = m.Trigger((held_not, (_faster_than(10.0, "C"),), (_faster_than(10.0, "A", "B"),)))
    triggering: list[str] = ["earlier"]
    assert Triggers(world).fire(trigger, triggering)
    assert triggering == ["earlier", "C", "A"]
    triggering = []
    assert not Triggers(world).fire(m.Trigger((held_not,)), triggering) and triggering == []


def test_a_rising_edge_without_delay_fires_as_the_edge_and_delay_rules_say() -> None:
    """The shortcut of the commonest edged condition (rising, no delay) against the general rule, on every
    sequence of five values, and after the trigger fired (its edges start over)."""
    import itertools

    from simcore.scenario.triggers import ConditionState

    for values in itertools.product((False, True), repeat=5):
        fired = {}
        for general in (False, True):
            stand_in, world = _world("A")
            state = ConditionState(_faster_than(10.0, "A", edge="rising"), world)
            stand_in.bodies["A"].speed = 0.0
            state.check(None)  # bound now
            assert state.check == state._rising
            if general:
                state.check = state._edged
            state.previous = None
            seen = []
            for i, value in enumerate(values):
                stand_in.bodies["A"].speed = 20.0 if value else 0.0
                if i == 3:
                    state.previous = None  # as after the trigger fired
                seen.append(state.check(None))
            fired[general] = seen
        assert fired[False] == fired[True], values


def test_an_element_state_condition_sees_each_transition_once_however_it_is_evaluated() -> None:
    """A StoryboardElementStateCondition keeps one count of the transitions it has seen per run, shared by
    its triggers and `holds`."""
    from simcore.scenario.storyboard import Node, Registry, State, Transition

    root = Node("storyboard", "storyboard", None)
    event = Node("event", "E", None, root)
    root.children.append(event)
    stand_in, world = _world("A")
    stand_in.registry = Registry(root)  # type: ignore[attr-defined]
    stand_in.step_index = 0  # type: ignore[attr-defined]
    cond = m.Condition(
        "ended",
        0.0,
        "none",
        value_condition=m.StoryboardElementStateCondition("event", "E", "endTransition"),
    )
    triggers = Triggers(world)
    trigger = m.Trigger(((cond,),))
    assert not triggers.fire(trigger)
    event.transition(Transition.END, State.COMPLETE, [], 0.1)
    assert holds(cond, world, None)  # seen here ...
    assert not triggers.fire(trigger)  # ... so not again
    event.transition(Transition.END, State.COMPLETE, [], 0.2)
    assert triggers.fire(trigger)
    assert not holds(cond, world, None)


def test_collision_with_any_entity_is_collision_with_one_of_them() -> None:
    import math

    from simcore.scenario.conditions import bind_collision
    from simcore.scenario.measure import Measure

    for dx, dy, heading in (
        (4.5, 0.0, 0.0),
        (4.5 + 1e-4, 0.0, 0.0),
        (0.0, 1.8, 0.0),
        (4.54, -1.4, math.pi / 2),
    ):
        stand_in, world = _world("Ego", "Other", "Far")
        stand_in.step_index = 0  # type: ignore[attr-defined]
        stand_in.road = None  # type: ignore[attr-defined]
        stand_in.measure = Measure(stand_in)  # type: ignore[attr-defined,arg-type]
        other = stand_in.bodies["Other"]
        other.x, other.y, other.heading = dx, dy, heading
        stand_in.bodies["Far"].x = 100.0
        ego = stand_in.bodies["Ego"]
        expected = bind_collision(m.CollisionCondition("Other"), world)(ego)
        assert bind_collision(m.CollisionCondition(None), world)(ego) == expected
        assert not bind_collision(m.CollisionCondition("Far"), world)(ego)


def test_a_scenario_file_is_parsed_once_per_content_and_loaded_with_each_load_s_values(
    tmp_path: Path,
) -> None:
    """Loads of one file share its parsed XML (a sweep's points), each with its own parameter values; an
    edit of the file, even one keeping its size, is read at the next load."""
    import os

    from simcore.scenario import xosc, xosc_xml
    from tests.xosc_fixtures import openscenario, place, scenario_object, write_scenario

    def text(default: str) -> str:
        return openscenario(
            parameters=f'<ParameterDeclarations><ParameterDeclaration name="S" parameterType="double" value="{default}"/></ParameterDeclarations>',
            entities=scenario_object("Ego"),
            init=place("Ego", 10.0).replace('s="10.0"', 's="$S"'),
        )

    path = write_scenario(tmp_path, text("10.0"))
    first = xosc.load_scenario(path, {"S": 30.0})
    second = xosc.load_scenario(path)
    assert first.parameters["S"] == 30.0 and second.parameters["S"] == 10.0
    assert first.init[0].action.position.s == 30.0  # type: ignore[union-attr]
    assert second.init[0].action.position.s == 10.0  # type: ignore[union-attr]
    assert sum(1 for key in xosc_xml._PARSED if key[0] == str(path.absolute())) == 1
    stat = path.stat()
    path.write_text(text("20.0"))  # the same size, and the same modification time
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert xosc.load_scenario(path).parameters["S"] == 20.0


def test_the_parsed_files_a_worker_keeps_are_bounded(tmp_path: Path) -> None:
    """A worker loading many scenario files (a sweep over many scenarios) keeps at most PARSED_FILES_MAX
    parsed files; one dropped is parsed again when loaded again, with the same result."""
    from simcore.scenario import xosc, xosc_xml
    from tests.xosc_fixtures import openscenario, place, scenario_object

    paths = []
    for i in range(xosc_xml.PARSED_FILES_MAX + 5):
        path = tmp_path / f"s{i}.xosc"
        path.write_text(openscenario(entities=scenario_object("Ego"), init=place("Ego", 10.0 + i)))
        paths.append(path)
        assert xosc.load_scenario(path).init[0].action.position.s == 10.0 + i  # type: ignore[union-attr]
        assert len(xosc_xml._PARSED) <= xosc_xml.PARSED_FILES_MAX
    assert xosc.load_scenario(paths[0]).init[0].action.position.s == 10.0  # type: ignore[union-attr]
