"""The immutable value objects built on every step: the world frame's types (`simcore.world.state`),
frozen when interpreted (`simcore.world.frozen.freeze`), and the fast constructor of frozen dataclasses
(`simcore.world.frozen.builder`)."""

from __future__ import annotations

import copy
import dataclasses
import pickle
from typing import Any

import pytest

from simcore.world.frozen import builder, freeze
from simcore.world.road_model import RoadCoordinates
from simcore.world.state import (
    BOUNDING_BOX_FIELDS,
    ENTITY_STATE_FIELDS,
    LANE_COORDINATES_FIELDS,
    WORLD_FRAME_FIELDS,
    BoundingBox,
    EntityState,
    LaneCoordinates,
    WorldFrame,
)

FIELDS = {
    BoundingBox: BOUNDING_BOX_FIELDS,
    LaneCoordinates: LANE_COORDINATES_FIELDS,
    EntityState: ENTITY_STATE_FIELDS,
    WorldFrame: WORLD_FRAME_FIELDS,
}


def test_the_world_frame_types_behave_as_frozen_dataclasses_of_their_fields() -> None:
    box = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
    lane = LaneCoordinates("1", -2, 12.5, -5.25, -0.0)
    state = EntityState(
        "Ego", "vehicle", "car", 1.0, 2.0, 0.0, 0.1, 0.0, 0.0, 20.0, -1.5, 0.01, box, lane, "sumo"
    )
    frame = WorldFrame(7, 0.35, (state,), "Ego", ("started",), ())
    made: Any
    for made in (box, lane, state, frame):
        cls = type(made)
        values = made.values()
        assert values == tuple(getattr(made, n) for n in FIELDS[cls])
        reference = dataclasses.make_dataclass(cls.__name__, FIELDS[cls], frozen=True)(*values)
        assert repr(made) == repr(reference) and hash(made) == hash(reference)
        assert made == cls(*values) and made != reference and made is not cls(*values)
        assert pickle.loads(pickle.dumps(made)) == made and copy.copy(made) == made
        name = FIELDS[cls][0]
        with pytest.raises(AttributeError):
            setattr(made, name, values[1])
        with pytest.raises(AttributeError):
            delattr(made, name)
        with pytest.raises(AttributeError):
            made.other = 1
        assert made.values() == values
    # the defaults, keywords, replace
    bare = EntityState("Ego", "vehicle", "car", 1.0, 2.0, 0.0, 0.1, 0.0, 0.0, 20.0, -1.5, 0.01, bbox=box)
    assert (bare.lane, bare.controlled_by) == (None, "scenario")
    assert state.replace(lane=None, controlled_by="scenario") == bare and state.lane is lane
    assert WorldFrame(step=7, time=0.35, entities=(state,)) == frame.replace(ego=None, events=())
    assert frame.entity("Ego") is state
    with pytest.raises(KeyError):
        frame.entity("Nobody")
    with pytest.raises(TypeError):
        state.replace(colour="red")
    with pytest.raises(TypeError):
        LaneCoordinates("1", -2, 12.5, -5.25)  # type: ignore[call-arg]


def test_freeze_takes_only_a_class_whose_constructor_stores_its_slots() -> None:
    class Loose:
        def __init__(self, a: int) -> None:
            self.a = a

    class Reordered:
        __slots__ = ("a", "b")

        def __init__(self, b: int, a: int) -> None:
            self.a, self.b = a, b

    for cls in (Loose, Reordered):
        with pytest.raises(TypeError, match="freeze needs __slots__"):
            freeze(cls)

    class Point:
        __slots__ = ("x", "y")

        def __init__(self, x: float, y: float = 0.0) -> None:
            self.x = x
            self.y = y

    freeze(Point)
    point = Point(1.0)
    assert (point.x, point.y) == (1.0, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'x'"):
        point.x = 2.0
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot delete field 'y'"):
        del point.y


def test_a_frozen_dataclass_is_built_as_its_constructor_builds_it() -> None:
    @dataclasses.dataclass(frozen=True, slots=True)
    class Lane:
        road_id: str
        lane_id: int
        s: float

    build = builder(Lane)
    assert build is not Lane
    built = build("1", -2, 12.5)
    assert type(built) is Lane and built == Lane("1", -2, 12.5) and hash(built) == hash(Lane("1", -2, 12.5))
    with pytest.raises(dataclasses.FrozenInstanceError):
        built.s = 3.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        build("1", -2)  # every field, none defaulted
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


def test_a_dataclass_whose_field_names_it_cannot_spell_is_its_own_constructor() -> None:
    @dataclasses.dataclass(frozen=True)
    class Hidden:
        _cls: int  # would shadow the generated constructor's own name

    assert builder(Hidden) is Hidden
