"""The world state every step: what every part downstream of the simulator (recorder, metrics, sensors) reads."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from simcore.world.frozen import builder

Corners = tuple[tuple[float, float], tuple[float, float], tuple[float, float], tuple[float, float]]


def box_corners(
    x: float, y: float, heading: float, center_x: float, center_y: float, length: float, width: float
) -> Corners:
    """The ground-plane corners of a box centred (`center_x`, `center_y`) in the frame of a reference point
    (x, y) with `heading`, counter-clockwise from front-left (one arithmetic for states, metrics and
    conditions, so their footprints are the same floats)."""
    c, s = math.cos(heading), math.sin(heading)
    cx = x + c * center_x - s * center_y
    cy = y + s * center_x + c * center_y
    hl, hw = length / 2, width / 2
    lc, ls, wc, ws = hl * c, hl * s, hw * c, hw * s
    return (
        (cx + lc - ws, cy + ls + wc),
        (cx - lc - ws, cy - ls + wc),
        (cx - lc + ws, cy - ls - wc),
        (cx + lc + ws, cy + ls - wc),
    )


@dataclass(frozen=True, slots=True)
class BoundingBox:
    """An entity's box in its own frame (OpenSCENARIO BoundingBox): centre relative to the entity's
    reference point (for vehicles the rear axle, on the ground), x forward, y left, z up; dimensions in m."""

    center_x: float
    center_y: float
    center_z: float
    length: float
    width: float
    height: float


@dataclass(frozen=True, slots=True)
class LaneCoordinates:
    """Where an entity is on the OpenDRIVE road network (`road_id`, `lane_id`, `s` along the reference
    line, `t` lateral from it, `offset` from the lane centre)."""

    road_id: str
    lane_id: int
    s: float
    t: float
    offset: float


@dataclass(frozen=True, slots=True)
class EntityState:
    """One entity at one instant. Pose is of the entity's reference point in the `map` frame (ENU, REP-103):
    x east, y north, z up; heading counter-clockwise from x, in rad. Speeds in m/s, accelerations in m/s²."""

    name: str
    object_type: str  # "vehicle" | "pedestrian" | "miscObject"
    category: str  # OpenSCENARIO category: car, truck, bus, bicycle, pedestrian, obstacle, …
    x: float
    y: float
    z: float
    heading: float
    pitch: float
    roll: float
    speed: float  # signed, along the heading
    acceleration: float  # longitudinal
    yaw_rate: float
    bbox: BoundingBox
    lane: LaneCoordinates | None = None
    controlled_by: str = "scenario"  # "scenario" | "sumo" | "external"

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


@dataclass(frozen=True, slots=True)
class WorldFrame:
    """Every entity at simulated time `time` (s); `step` counts from 0."""

    step: int
    time: float
    entities: tuple[EntityState, ...]
    ego: str | None = None
    events: tuple[str, ...] = field(default_factory=tuple)  # storyboard transitions this step, for logs
    # a FollowGhost controller's ghost (`<entity>_ghost`, esmini's): published (odometry, tf) but no object of
    # the world: sensors, metrics, V2X and ground truth see only `entities`
    ghosts: tuple[EntityState, ...] = field(default_factory=tuple)

    def entity(self, name: str) -> EntityState:
        for entity in self.entities:
            if entity.name == name:
                return entity
        raise KeyError(name)


#: `EntityState`, `LaneCoordinates` and `WorldFrame` from every field, positionally (the engine's per-step
#: frames); equal to the objects their constructors give
entity_state = builder(EntityState)
lane_coordinates = builder(LaneCoordinates)
world_frame = builder(WorldFrame)
