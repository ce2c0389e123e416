"""How entities move: road-following kinematics for entities the scenario drives, and the transition shapes
of OpenSCENARIO's TransitionDynamics."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final, final

from simcore.scenario import model as m
from simcore.world.native_calls import atan2, hypot
from simcore.world.state import BoundingBox

if TYPE_CHECKING:
    from simcore.world.opendrive import OpenDrive
    from simcore.world.road_model import Road


def shape_value(shape: str, p: float) -> float:
    """Fraction of a transition completed at progress p ∈ [0, 1] for a dynamics shape."""
    p = min(max(p, 0.0), 1.0)
    if shape == "step":
        return 1.0
    if shape == "linear":
        return p
    if shape == "cubic":
        return p * p * (3.0 - 2.0 * p)
    if shape == "sinusoidal":
        return 0.5 - 0.5 * math.cos(math.pi * p)
    raise ValueError(shape)


def shape_slope(shape: str, p: float) -> float:
    """d shape_value / d p at progress p ∈ [0, 1] (0 outside and for a step)."""
    if not 0.0 <= p <= 1.0 or shape == "step":
        return 0.0
    if shape == "linear":
        return 1.0
    if shape == "cubic":
        return 6.0 * p * (1.0 - p)
    if shape == "sinusoidal":
        return 0.5 * math.pi * math.sin(math.pi * p)
    raise ValueError(shape)


def shape_peak_rate_factor(shape: str) -> float:
    """Peak slope of a shape relative to the linear one (rate dimension means the peak rate)."""
    return {"linear": 1.0, "cubic": 1.5, "sinusoidal": math.pi / 2, "step": 1.0}[shape]


_PI: Final = math.pi
_TWO_PI: Final = 2 * math.pi


def wrap_angle(angle: float) -> float:
    return (angle + math.pi) % _TWO_PI - math.pi


@final
class EntityFacts:
    """A body's entity, its box and external driving, and what its states take from them: name, object type,
    category, published box and who drives it (`ScenarioEngine._facts_of`; kept in `Body.facts`). A class,
    not a tuple: compiled, its fields are read as they are, where a tuple is unpacked and checked whole."""

    __slots__ = ("bbox", "box", "category", "controlled_by", "entity", "external", "name", "object_type")

    def __init__(
        self,
        entity: m.Entity,
        box: m.Box,
        external: bool,
        name: str,
        object_type: str,
        category: str,
        bbox: BoundingBox,
        controlled_by: str,
    ) -> None:
        self.entity = entity
        self.box = box
        self.external = external
        self.name = name
        self.object_type = object_type
        self.category = category
        self.bbox = bbox
        self.controlled_by = controlled_by


#: the road state a pose is computed from (`_road_state`): road, lane, s, offset, direction, heading offset,
#: lateral velocity, speed (a typed tuple: compiled, kept in the body as plain values, not an object)
RoadState = tuple[str | None, int, float, float, int, float, float, float]
#: a body not posed on a road: equal to no road state (its s is NaN)
UNPOSED: RoadState = (None, 0, math.nan, 0.0, 0, 0.0, 0.0, 0.0)


@dataclass
class Body:
    """The mutable state of one entity during a run."""

    entity: m.Entity
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    heading: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    speed: float = 0.0
    acceleration: float = 0.0
    yaw_rate: float = 0.0
    vx: float = 0.0  # world velocity over the last step (its displacement / dt), m/s
    vy: float = 0.0
    previous_velocity: tuple[float, float] = (0.0, 0.0)  # (vx, vy) of the step before the last
    at_step_start: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # speed, heading, x, y (advance)
    # road following (None when the entity is off every road)
    road_id: str | None = None
    lane_id: int = 0
    s: float = 0.0
    offset: float = 0.0  # from the centre of lane_id, + to the left of the reference line (+t)
    direction: int = 1  # +1 travels toward increasing s
    heading_offset: float = 0.0  # heading relative to the lane's travel direction, kept along the lane
    posed: RoadState = UNPOSED  # the road state the pose was last computed from
    # the reference line at the s of the pose on its road (`update_pose_from_road`): its curvature, where the
    # next step's move along the lane starts, and its heading, which conditions measure in (`reference_heading`)
    ref_road: Road | None = None
    ref_s: float = math.nan
    ref_kappa: float = 0.0
    ref_heading: float = 0.0
    odometer: float = 0.0
    standstill_since: float | None = 0.0
    end_of_road_since: float | None = None
    end_of_road_steps: int = 0  # steps begun at the end of the road since it got there
    lateral_velocity: float = 0.0  # d(offset)/dt during a lane change, in t units
    placed: bool = False
    gone: bool = False  # left the SUMO network
    extra: dict[str, float] = field(default_factory=dict)
    mover: Any = None  # a runtime that moves the entity itself (a trajectory) instead of lane following
    facts: EntityFacts | None = None  # what its published states take from its entity (ScenarioEngine)
    route: list[tuple[str, int]] = field(default_factory=list)  # roads ahead (id, direction) of a route
    # the assigned route's waypoints as road points (lane_router.RoadPoint) and their route strategies
    route_points: list[Any] = field(default_factory=list)
    route_strategies: list[str] = field(default_factory=list)
    external: bool = False  # an external controller is active on it: moved by its control input only

    name: str = field(init=False)  # the entity's (a plain attribute: read on every step)

    def __post_init__(self) -> None:
        self.name = self.entity.name


def lane_shift(road: OpenDrive, road_id: str, s: float, lane_id: int, steps: int, direction: int) -> int:
    """The lane `steps` lanes to the left (negative: right) of `lane_id`, seen in the travel direction."""
    lanes = sorted(road.lane_ids(road_id, s))
    if lane_id not in lanes:
        raise ValueError(f"lane {lane_id} does not exist on road {road_id} at s={s:.1f}")
    # +t is left when travelling toward +s
    along_t = steps if direction > 0 else -steps
    position = lanes.index(lane_id) + along_t
    if not 0 <= position < len(lanes):
        raise ValueError(f"no lane {steps:+d} from lane {lane_id} on road {road_id}")
    return lanes[position]


def lane_at_t(road: OpenDrive, road_id: str, s: float, t: float) -> tuple[int, float]:
    """The lane containing lateral position t (else the one with the closest centre) and the offset from
    its centre. One pass over the lane borders at s."""
    r = road.roads.get(road_id) or road.road(road_id)
    s = 0.0 if s < 0.0 else s  # min(max(s, 0.0), r.length)
    s = r.length if r.length < s else s
    cross = r.cross_at(s)
    if cross is not None:  # the same borders over a stretch of road: its table of them, made once
        return cross.lane_at(t)
    best_lane, best_offset, best = 0, t, math.inf
    for lane, inner, outer in r.all_borders(s):
        if lane.id == 0 or inner == outer:
            continue
        centre = 0.5 * (inner + outer)
        lo, hi = (inner, outer) if inner < outer else (outer, inner)
        if lo - 1e-9 <= t <= hi + 1e-9:
            return lane.id, t - centre
        if abs(t - centre) < best:
            best, best_lane, best_offset = abs(t - centre), lane.id, t - centre
    return best_lane, best_offset


def lane_point(
    road: OpenDrive, road_id: str, lane_id: int, s: float, offset: float, on: Road | None = None
) -> tuple[float, int, float]:
    """Where a body in lane `lane_id`, `offset` from its centre at `s`, is across the road: ``(t, lane, offset
    from that lane's centre)`` with ``t = lane_center_t(road_id, lane_id, s) + offset`` and the lane
    `lane_at_t` finds at ``t`` (the lane changes mid lane change). The same floats as those two calls, with
    one look-up of the lane borders at `s` where they are the same over a stretch of road. `on`: the road
    `road_id` names, when the caller has it at hand."""
    r = on if on is not None else road.roads.get(road_id)
    if r is not None and lane_id != 0 and 0.0 <= s <= r.length:  # as lane_center_t and lane_at_t take s
        cross = r.cross_at(s)
        if cross is not None:
            known, centre = cross.centre_of(lane_id)
            if known:
                t = centre + offset
                found, off = cross.lane_at(t)
                return t, found, off
    t = road.lane_center_t(road_id, lane_id, s) + offset
    found, off = lane_at_t(road, road_id, s, t)
    return t, found, off


def advance_on_road(road: OpenDrive, body: Body, distance: float, now: float) -> None:
    """Move a road-following body `distance` metres along its lane, across road links; pose updated."""
    assert body.road_id is not None
    if distance == 0.0 and body.posed == _road_state(body):
        return  # standing still where the pose was computed: nothing changes
    remaining = distance
    roads = road.roads
    for _ in range(16):  # at most this many road changes in one step
        road_id, lane_id, s = body.road_id, body.lane_id, body.s
        r = roads.get(road_id) or road.road(road_id)
        centre = r.centre_t(lane_id, s)  # road.lane_center_t(road_id, lane_id, s) where the table has it
        t = (road.lane_center_t(road_id, lane_id, s) if centre is None else centre) + body.offset
        # metres along the lane per unit of s (curvature makes lanes longer or shorter than the reference line)
        length = r.length
        # a curve parallel to the reference line at distance t has length (1 - κ t) per unit of s
        on = 0.0 if s < 0.0 else s  # min(max(s, 0.0), length), without the calls
        on = length if length < on else on
        # the curvature there: known from the pose when the body is still where it was posed
        kappa = body.ref_kappa if on == body.ref_s and r is body.ref_road else r.curvature(on)
        scale = abs(1.0 - kappa * t)
        ds = remaining / (1e-6 if scale < 1e-6 else scale)  # max(scale, 1e-6)
        target = s + body.direction * ds
        # reaching a road's end exactly counts as reaching it (the end-of-road timer starts on this step,
        # as esmini's); standing still there stays
        if 0.0 < target < length or (ds == 0.0 and 0.0 <= target <= length):
            if lane_id == 0 or _plain_side(r, 1 if lane_id > 0 else -1):
                body.s = target  # no lane link or vanishing lane to follow on this side of the road
            else:
                _follow_lane_links(r, body, target)
                body.s = target
                if body.lane_id != 0:
                    _leave_vanished_lane(r, body)
            if ds != 0.0:  # standing still at the end of a road, it stays there
                body.end_of_road_since = None
            break
        # past the end of this road: continue on the successor
        overshoot = (target - length) if target >= length else -target
        edge_s = length if target >= length else 0.0
        nxt = next_road(road, body)
        if nxt is None:
            body.s = edge_s
            if body.end_of_road_since is None:
                body.end_of_road_since = now
                body.end_of_road_steps = 0
            else:
                body.end_of_road_steps += 1
                if body.end_of_road_steps >= 2:
                    # stuck at the end of a road with nowhere to go: it stops (as esmini's default
                    # controller does, two steps after it got there)
                    body.speed = 0.0
            break
        road_id, lane_id, direction = nxt
        # the offset is kept to the same side of the travel direction (t flips with the s direction)
        body.offset *= body.direction * direction
        body.lateral_velocity *= body.direction * direction
        body.road_id, body.lane_id, body.direction = road_id, lane_id, direction
        body.s = 0.0 if direction > 0 else road.road_length(road_id)
        remaining = overshoot * scale
    update_pose_from_road(road, body)


def _follow_lane_links(r: object, body: Body, s_new: float) -> None:
    """Across a lane section boundary within a road, the lane continues by its successor/predecessor link
    (lane ids may be renumbered between sections)."""
    side = 1 if body.lane_id > 0 else -1
    old = r.section_at(body.s, side)  # type: ignore[attr-defined]
    new = r.section_at(s_new, side)  # type: ignore[attr-defined]
    if old is new:
        return
    lane = old.lane(body.lane_id)
    link = None if lane is None else (lane.successor if s_new > body.s else lane.predecessor)
    if link is not None and link != 0 and new.lane(link) is not None:
        body.lane_id = link


def _leave_vanished_lane(r: object, body: Body) -> None:
    """A lane whose width has shrunk to nothing (a lane that ends by merging) is left for the next lane
    toward the reference line, at its centre (as esmini does)."""
    side = 1 if body.lane_id > 0 else -1
    section = r.section_at(body.s, side)  # type: ignore[attr-defined]
    lane = section.lane(body.lane_id)
    if lane is None or not _may_vanish(lane, section) or lane.width_at(body.s - section.s) > 1e-6:
        return
    inner = body.lane_id - side
    if inner != 0 and section.lane(inner) is not None:
        body.lane_id = inner
        body.offset = 0.0


def _plain_side(r: Any, side: int) -> bool:
    """Is one lane section all of this side of the road, with no lane narrowing to nothing in it? A body in
    a lane there keeps its lane id along the road (`_follow_lane_links` and `_leave_vanished_lane` change
    nothing). Found once per road and side, kept on the road (its lanes never change after parsing)."""
    plain = r.plain_sides
    found = plain.get(side)
    if found is None:
        sections = r.side_sections(side)
        found = len(sections) == 1 and not any(
            _may_vanish(lane, sections[0]) for lane in (sections[0].left if side > 0 else sections[0].right)
        )
        plain[side] = found
    return found


def _may_vanish(lane: Any, section: Any) -> bool:
    """Does the lane's width reach zero somewhere in its section (found once per lane, kept on the lane)?"""
    found = lane.may_vanish
    if found is None:
        ends = [p.s0 for p in lane.widths] + [max(section.end - section.s, 0.0)]
        probes = [x for a, b in itertools.pairwise(ends) for x in (a, (a + b) / 2, b)]
        found = bool(lane.widths) and any(lane.width_at(x) <= 1e-6 for x in probes)
        lane.may_vanish = found
    return bool(found)


def next_road(road: OpenDrive, body: Body) -> tuple[str, int, int] | None:
    """Where a body goes at the end of its road: along its route when it has one, else straight on."""
    assert body.road_id is not None
    while body.route and body.route[0][0] == body.road_id:
        body.route.pop(0)
    if body.route:
        want_road, want_dir = body.route[0]
        options = road.connections(body.road_id, body.lane_id, body.direction)
        chosen = [o for o in options if o[0] == want_road and o[2] == want_dir]
        if not chosen and not options:
            # the lane ends here: the route's connection from the nearest lane that has one
            others = [o for o in road.connections(body.road_id, None, body.direction) if o[0] == want_road]
            chosen = sorted(others, key=lambda o: abs(o[1] - body.lane_id))
        if chosen:
            body.route.pop(0)
            return chosen[0]
        # the route turns from another lane: the entity goes where its lane leads and leaves the route (esmini
        # "moved away from route")
        body.route.clear()
    return onward(road, body.road_id, body.lane_id, body.direction)


def onward(road: OpenDrive, road_id: str, lane_id: int, direction: int) -> tuple[str, int, int] | None:
    """Where a lane goes on at the end of its road (travelling in `direction`) without a route: the one
    successor, or through a junction the connection that turns least."""
    options = road.connections(road_id, lane_id, direction)
    if len(options) > 1:
        return straightest(road, road_id, direction, options)
    return road.successor(road_id, lane_id, direction)


def straightest(
    road: OpenDrive, road_id: str, direction: int, options: list[tuple[str, int, int]]
) -> tuple[str, int, int]:
    """Without a route, the way through a junction that turns least: the connecting road whose far end
    heads closest to where the body heads at the end of its road (esmini's junction selector angle 0, what
    its default controller takes at the first junction)."""
    edge = road.road_length(road_id) if direction > 0 else 0.0
    here = road.road_to_world(road_id, edge, 0.0).heading + (0.0 if direction > 0 else math.pi)

    def turn(option: tuple[str, int, int]) -> float:
        road_id, _, direction = option
        far = road.road_length(road_id) if direction > 0 else 0.0
        there = road.road_to_world(road_id, far, 0.0).heading + (0.0 if direction > 0 else math.pi)
        return abs(wrap_angle(there - here))

    return min(options, key=turn)


def along_lane(
    road: OpenDrive, road_id: str, lane_id: int, s: float, direction: int, distance: float
) -> tuple[str, int, float, int]:
    """(road, lane, s, direction) `distance` metres of s further along a lane in `direction` (negative:
    back), across road ends by the lane's links (the straightest way through junctions); it stops at a dead
    end. The direction returned is the travel direction on the road reached."""
    moving = direction if distance >= 0 else -direction
    remaining = abs(distance)
    for _ in range(32):
        length = road.road_length(road_id)
        target = s + moving * remaining
        if 0.0 <= target <= length:
            return road_id, lane_id, target, moving if distance >= 0 else -moving
        nxt = onward(road, road_id, lane_id, moving)
        edge = length if target > length else 0.0
        if nxt is None:
            return road_id, lane_id, edge, moving if distance >= 0 else -moving
        remaining -= abs(edge - s)
        road_id, lane_id, moving = nxt
        s = 0.0 if moving > 0 else road.road_length(road_id)
    return road_id, lane_id, s, moving if distance >= 0 else -moving


def update_pose_from_road(road: OpenDrive, body: Body) -> None:
    # (the body's fields read once each: this runs for every road-following entity at every step)
    road_id, lane_id, s, offset = body.road_id, body.lane_id, body.s, body.offset
    assert road_id is not None
    r = road.roads.get(road_id)
    if r is not None and 0.0 <= s <= r.length:  # road.road_xyzh's road and s: ask the road itself
        centre = r.centre_t(lane_id, s)  # road.lane_center_t where the table has it
        t = (road.lane_center_t(road_id, lane_id, s) if centre is None else centre) + offset
        body.x, body.y, body.z, heading, body.ref_kappa = r.world_xyzk(s, t)
        body.ref_road, body.ref_s, body.ref_heading = r, s, heading
    else:
        t = road.lane_center_t(road_id, lane_id, s) + offset
        body.x, body.y, body.z, heading = road.road_xyzh(road_id, s, t)
    direction = body.direction
    road_heading = heading if direction > 0 else heading + _PI
    drift = 0.0
    speed = body.speed
    lateral_velocity = body.lateral_velocity
    if lateral_velocity != 0.0 and abs(speed) > 0.1:
        # (without a lateral motion the drift is atan2(±0, |speed|) = ±0: adding it changes no heading)
        lateral = lateral_velocity * direction  # + is to the left of the travel direction
        drift = atan2(lateral, abs(speed))
    heading_offset = body.heading_offset
    body.heading = (road_heading + drift + heading_offset + _PI) % _TWO_PI - _PI  # wrap_angle
    body.posed = (
        road_id,
        lane_id,
        s,
        offset,
        direction,
        heading_offset,
        lateral_velocity,
        speed,
    )  # _road_state


def reference_heading(r: Road, body: Body, s: float) -> float:
    """The heading of road `r`'s reference line at `s` (``r.reference_xyh(s)[2]``): kept from the body's pose
    when it is posed there."""
    if s == body.ref_s and r is body.ref_road:
        return body.ref_heading
    return r.reference_xyh(s)[2]


def _road_state(body: Body) -> RoadState:
    return (
        body.road_id,
        body.lane_id,
        body.s,
        body.offset,
        body.direction,
        body.heading_offset,
        body.lateral_velocity,
        body.speed,
    )


def hitch_point(tow: Body) -> tuple[float, float]:
    """Where a tow vehicle's trailer is coupled: TrailerHitch dx ahead of its reference point (behind when
    negative)."""
    dx = tow.entity.trailer_hitch or 0.0
    return tow.x + dx * math.cos(tow.heading), tow.y + dx * math.sin(tow.heading)


def align_trailer(tow: Body, trailer: Body) -> None:
    """Put a trailer straight behind its tow vehicle: its coupler on the hitch, same heading."""
    hx, hy = hitch_point(tow)
    coupler = trailer.entity.trailer_coupler or 0.0
    trailer.heading = tow.heading
    trailer.x = hx - coupler * math.cos(tow.heading)
    trailer.y = hy - coupler * math.sin(tow.heading)
    trailer.z = tow.z
    trailer.speed = tow.speed
    trailer.placed = True
    trailer.gone = tow.gone


def pull_trailer(tow: Body, trailer: Body) -> None:
    """Drag a trailer after its tow vehicle moved: its coupler stays on the hitch and it turns toward it (a
    rigid bar from the hitch to the trailer's reference point, as esmini's trailer model); it takes the tow
    vehicle's speed."""
    hx, hy = hitch_point(tow)
    vx, vy = trailer.x - hx, trailer.y - hy
    length = hypot(vx, vy)
    coupler = trailer.entity.trailer_coupler or 0.0
    if length < 1e-9:  # on the hitch: straight behind
        vx, vy, length = -math.cos(tow.heading), -math.sin(tow.heading), 1.0
    trailer.x = hx + vx * coupler / length
    trailer.y = hy + vy * coupler / length
    trailer.heading = wrap_angle(atan2(vy, vx) + math.pi)
    trailer.speed = tow.speed
    trailer.z = tow.z
