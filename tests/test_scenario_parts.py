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


def test_a_scenario_file_is_parsed_once_per_version_and_loaded_with_each_load_s_values(
    tmp_path: Path,
) -> None:
    """Loads of one file share its parsed XML (a sweep's points), each with its own parameter values; an
    edit of the file, even one keeping its size, is read at the next load."""
    import os

    from simcore.scenario import xosc
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
    assert sum(1 for key in xosc._PARSED if key[0] == str(path.absolute())) == 1
    stat = path.stat()
    path.write_text(text("20.0"))  # the same size, and the same modification time
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert xosc.load_scenario(path).parameters["S"] == 20.0
