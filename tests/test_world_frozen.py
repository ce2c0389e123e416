"""The fast constructor of the frozen dataclasses built on every step (`simcore.world.frozen`)."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from simcore.world.frozen import builder
from simcore.world.road_model import RoadCoordinates
from simcore.world.state import (
    BoundingBox,
    EntityState,
    LaneCoordinates,
    WorldFrame,
    entity_state,
    world_frame,
)


def test_built_objects_are_the_ones_the_constructor_gives() -> None:
    box = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
    lane = LaneCoordinates("1", -2, 12.5, -5.25, 0.0)
    values = ("Ego", "vehicle", "car", 1.0, 2.0, 0.0, 0.1, 0.0, 0.0, 20.0, -1.5, 0.01, box, lane, "sumo")
    built, made = entity_state(*values), EntityState(*values)
    assert type(built) is EntityState and built == made and hash(built) == hash(made)
    assert pickle.loads(pickle.dumps(built)) == made
    with pytest.raises(dataclasses.FrozenInstanceError):
        built.x = 3.0  # type: ignore[misc]
    frame = world_frame(7, 0.35, (built,), "Ego", (), ())
    assert (
        frame == WorldFrame(step=7, time=0.35, entities=(made,), ego="Ego") and frame.entity("Ego") is built
    )
    # a frozen dataclass without slots
    road = builder(RoadCoordinates)("1", -1, 3.0, -1.75, 0.0, 0.2)
    assert type(road) is RoadCoordinates and road == RoadCoordinates("1", -1, 3.0, -1.75, 0.0, 0.2)
    with pytest.raises(dataclasses.FrozenInstanceError):
        road.s = 4.0  # type: ignore[misc]


def test_a_class_it_cannot_build_is_its_own_constructor() -> None:
    class Plain:
        def __init__(self, a: int) -> None:
            self.a = a

    assert builder(Plain) is Plain


def test_the_constructor_takes_every_field_positionally() -> None:
    build = builder(LaneCoordinates)
    assert build is not LaneCoordinates
    with pytest.raises(TypeError):
        build("1", -2, 12.5, -5.25)  # every field, none defaulted
    built = build("1", -2, 12.5, -5.25, -0.0)
    assert type(built) is LaneCoordinates and repr(built) == repr(LaneCoordinates("1", -2, 12.5, -5.25, -0.0))


def test_a_dataclass_whose_field_names_it_cannot_spell_is_its_own_constructor() -> None:
    @dataclasses.dataclass(frozen=True)
    class Hidden:
        _cls: int  # would shadow the generated constructor's own name

    assert builder(Hidden) is Hidden
