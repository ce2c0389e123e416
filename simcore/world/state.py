"""The world state every step: what every part downstream of the simulator (recorder, metrics, sensors) reads.

The four types are immutable value classes: fields set once by the constructor (positional or by keyword),
equality and hash over the fields in order, `Name(field=value, …)` as repr, `replace(**changes)` for a copy
with some fields changed. They are built for every entity at every step and read by the metrics, so they are
compiled classes in an installed wheel (setup.py `COMPILED`): a compiled module builds one at the cost of a
C struct and reads a field without a look-up. Their attributes are `Final`, which the compiler makes
read-only; run interpreted, `simcore.world.frozen.freeze` makes them so.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Final, Self, final

from simcore.world.frozen import freeze

Corners = tuple[tuple[float, float], tuple[float, float], tuple[float, float], tuple[float, float]]


#: a box's ground-plane corners, counter-clockwise from front-left, as flat coordinates (x0, y0, …, x3, y3),
#: then the cosine and sine of its heading
CornerCoordinates = tuple[float, float, float, float, float, float, float, float, float, float]


def corner_coordinates(
    x: float, y: float, heading: float, center_x: float, center_y: float, length: float, width: float
) -> CornerCoordinates:
    """The ground-plane corners of a box centred (`center_x`, `center_y`) in the frame of a reference point
    (x, y) with `heading`, counter-clockwise from front-left, as plain floats, then cos and sin of `heading`:
    the one arithmetic of states' corners (`box_corners`), the metrics' footprint and the conditions', so
    their footprints are the same floats (compiled, plain floats come back unboxed)."""
    c, s = math.cos(heading), math.sin(heading)
    cx = x + c * center_x - s * center_y
    cy = y + s * center_x + c * center_y
    hl, hw = length / 2, width / 2
    lc, ls, wc, ws = hl * c, hl * s, hw * c, hw * s
    return (
        cx + lc - ws,
        cy + ls + wc,
        cx - lc - ws,
        cy - ls + wc,
        cx - lc + ws,
        cy - ls - wc,
        cx + lc + ws,
        cy + ls - wc,
        c,
        s,
    )


def box_corners(
    x: float, y: float, heading: float, center_x: float, center_y: float, length: float, width: float
) -> Corners:
    """`corner_coordinates`' corners as points."""
    x0, y0, x1, y1, x2, y2, x3, y3, _, _ = corner_coordinates(
        x, y, heading, center_x, center_y, length, width
    )
    return (x0, y0), (x1, y1), (x2, y2), (x3, y3)


class Value:
    """Base of the immutable value classes built on every step (the frame's types, the metrics' footprint):
    equality and hash over `values()` (instances of the same class only), `Name(field=value, …)` as repr,
    pickling, and `replace(**changes)` for a copy with some fields changed. A subclass names its fields in
    order in `FIELDS` (its `__slots__` too), stores each in its `__init__` and gives them in `values()`."""

    __slots__ = ()
    FIELDS: ClassVar[tuple[str, ...]] = ()

    def values(self) -> tuple[Any, ...]:
        """The fields, in order."""
        raise NotImplementedError

    def replace(self, **changes: Any) -> Self:
        """A copy with `changes` (field=value) made."""
        return type(self)(**{**dict(zip(self.FIELDS, self.values(), strict=True)), **changes})

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__ or not isinstance(other, Value):
            return NotImplemented
        return self.values() == other.values()

    def __hash__(self) -> int:
        return hash(self.values())

    def __repr__(self) -> str:
        shown = ", ".join(f"{n}={v!r}" for n, v in zip(self.FIELDS, self.values(), strict=True))
        return f"{type(self).__name__}({shown})"

    def __reduce__(self) -> tuple[Any, ...]:
        return type(self), self.values()


#: the fields of `BoundingBox`, in order
BOUNDING_BOX_FIELDS: Final = ("center_x", "center_y", "center_z", "length", "width", "height")


@final
class BoundingBox(Value):
    """An entity's box in its own frame (OpenSCENARIO BoundingBox): centre relative to the entity's
    reference point (for vehicles the rear axle, on the ground), x forward, y left, z up; dimensions in m."""

    __slots__ = BOUNDING_BOX_FIELDS
    FIELDS: ClassVar[tuple[str, ...]] = BOUNDING_BOX_FIELDS
    center_x: Final[float]
    center_y: Final[float]
    center_z: Final[float]
    length: Final[float]
    width: Final[float]
    height: Final[float]

    def __init__(
        self, center_x: float, center_y: float, center_z: float, length: float, width: float, height: float
    ) -> None:
        self.center_x = center_x
        self.center_y = center_y
        self.center_z = center_z
        self.length = length
        self.width = width
        self.height = height

    def values(self) -> tuple[float, float, float, float, float, float]:
        """The fields, in order."""
        return (self.center_x, self.center_y, self.center_z, self.length, self.width, self.height)


#: the fields of `LaneCoordinates`, in order
LANE_COORDINATES_FIELDS: Final = ("road_id", "lane_id", "s", "t", "offset")


@final
class LaneCoordinates(Value):
    """Where an entity is on the OpenDRIVE road network (`road_id`, `lane_id`, `s` along the reference
    line, `t` lateral from it, `offset` from the lane centre)."""

    __slots__ = LANE_COORDINATES_FIELDS
    FIELDS: ClassVar[tuple[str, ...]] = LANE_COORDINATES_FIELDS
    road_id: Final[str]
    lane_id: Final[int]
    s: Final[float]
    t: Final[float]
    offset: Final[float]

    def __init__(self, road_id: str, lane_id: int, s: float, t: float, offset: float) -> None:
        self.road_id = road_id
        self.lane_id = lane_id
        self.s = s
        self.t = t
        self.offset = offset

    def values(self) -> tuple[str, int, float, float, float]:
        """The fields, in order."""
        return (self.road_id, self.lane_id, self.s, self.t, self.offset)


#: the fields of `EntityState`, in order
ENTITY_STATE_FIELDS: Final = (
    "name",
    "object_type",
    "category",
    "x",
    "y",
    "z",
    "heading",
    "pitch",
    "roll",
    "speed",
    "acceleration",
    "yaw_rate",
    "bbox",
    "lane",
    "controlled_by",
)


@final
class EntityState(Value):
    """One entity at one instant. Pose is of the entity's reference point in the `map` frame (ENU, REP-103):
    x east, y north, z up; heading counter-clockwise from x, in rad. Speeds in m/s, accelerations in m/s².
    `object_type` is "vehicle", "pedestrian" or "miscObject"; `category` the OpenSCENARIO category (car,
    truck, bus, bicycle, pedestrian, obstacle, …); `speed` signed, along the heading; `acceleration`
    longitudinal; `controlled_by` "scenario", "sumo" or "external"."""

    __slots__ = ENTITY_STATE_FIELDS
    FIELDS: ClassVar[tuple[str, ...]] = ENTITY_STATE_FIELDS
    name: Final[str]
    object_type: Final[str]
    category: Final[str]
    x: Final[float]
    y: Final[float]
    z: Final[float]
    heading: Final[float]
    pitch: Final[float]
    roll: Final[float]
    speed: Final[float]
    acceleration: Final[float]
    yaw_rate: Final[float]
    bbox: Final[BoundingBox]
    lane: Final[LaneCoordinates | None]
    controlled_by: Final[str]

    def __init__(
        self,
        name: str,
        object_type: str,
        category: str,
        x: float,
        y: float,
        z: float,
        heading: float,
        pitch: float,
        roll: float,
        speed: float,
        acceleration: float,
        yaw_rate: float,
        bbox: BoundingBox,
        lane: LaneCoordinates | None = None,
        controlled_by: str = "scenario",
    ) -> None:
        self.name = name
        self.object_type = object_type
        self.category = category
        self.x = x
        self.y = y
        self.z = z
        self.heading = heading
        self.pitch = pitch
        self.roll = roll
        self.speed = speed
        self.acceleration = acceleration
        self.yaw_rate = yaw_rate
        self.bbox = bbox
        self.lane = lane
        self.controlled_by = controlled_by

    def values(self) -> tuple[Any, ...]:
        """The fields, in order."""
        return (
            self.name,
            self.object_type,
            self.category,
            self.x,
            self.y,
            self.z,
            self.heading,
            self.pitch,
            self.roll,
            self.speed,
            self.acceleration,
            self.yaw_rate,
            self.bbox,
            self.lane,
            self.controlled_by,
        )

    @property
    def velocity(self) -> tuple[float, float]:
        return self.speed * math.cos(self.heading), self.speed * math.sin(self.heading)

    def box_center(self) -> tuple[float, float, float]:
        """Centre of the bounding box in the map frame."""
        c, s = math.cos(self.heading), math.sin(self.heading)
        bx, by = self.bbox.center_x, self.bbox.center_y
        return self.x + c * bx - s * by, self.y + s * bx + c * by, self.z + self.bbox.center_z

    def corners(self) -> list[tuple[float, float]]:
        """The box's four ground-plane corners in the map frame, counter-clockwise from front-left."""
        b = self.bbox
        return list(box_corners(self.x, self.y, self.heading, b.center_x, b.center_y, b.length, b.width))


#: the fields of `WorldFrame`, in order
WORLD_FRAME_FIELDS: Final = ("step", "time", "entities", "ego", "events", "ghosts")


@final
class WorldFrame(Value):
    """Every entity at simulated time `time` (s); `step` counts from 0. `events`: the storyboard's
    transitions this step, for logs. `ghosts`: a FollowGhost controller's ghost (`<entity>_ghost`,
    esmini's), published (odometry, tf) but no object of the world: sensors, metrics, V2X and ground truth
    see only `entities`."""

    __slots__ = WORLD_FRAME_FIELDS
    FIELDS: ClassVar[tuple[str, ...]] = WORLD_FRAME_FIELDS
    step: Final[int]
    time: Final[float]
    entities: Final[tuple[EntityState, ...]]
    ego: Final[str | None]
    events: Final[tuple[str, ...]]
    ghosts: Final[tuple[EntityState, ...]]

    def __init__(
        self,
        step: int,
        time: float,
        entities: tuple[EntityState, ...],
        ego: str | None = None,
        events: tuple[str, ...] = (),
        ghosts: tuple[EntityState, ...] = (),
    ) -> None:
        self.step = step
        self.time = time
        self.entities = entities
        self.ego = ego
        self.events = events
        self.ghosts = ghosts

    def values(self) -> tuple[Any, ...]:
        """The fields, in order."""
        return (self.step, self.time, self.entities, self.ego, self.events, self.ghosts)

    def entity(self, name: str) -> EntityState:
        for entity in self.entities:
            if entity.name == name:
                return entity
        raise KeyError(name)


for _cls in (BoundingBox, LaneCoordinates, EntityState, WorldFrame):
    freeze(_cls)
