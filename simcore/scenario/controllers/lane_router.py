"""esmini's lane-independent path planner (RoadManager's LaneIndependentRouter), which its
FollowRouteController drives by: a Dijkstra search over (road, lane) nodes from a start position to a target
road *and lane*, leaving each road from any driving lane on the travel side (the lane changes are the
controller's), and the waypoints that path gives (one per road, in the lane that leads on).

As esmini has it:

- a node's weight is the length driven (`shortest`, the default), the time at the road's speed limit
  (`fastest`) or the junctions passed (`leastIntersections`); between equal weights the node whose lane
  differs least from the lane it came from goes first;
- the target is only found when a connection lands in the target lane on the target road: a target lane
  that is reached by a lane change on the target road itself sends the search on through the network, round
  and back onto the target road in that lane (the controller then drives that loop);
- the waypoint on each road of the path is in the lane that connects to the next road, halfway along the
  stretch of road (from its exit end) where that lane exists; on the start road, where the entity already
  is within that stretch, at the entity (the lane change is due at once)."""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from simcore.world.opendrive import OpenDrive
    from simcore.world.road_model import LaneSection, Road

# esmini's Lane::IsDriving: the lane types a vehicle drives in
DRIVING_TYPES: Final = frozenset(
    {"driving", "entry", "exit", "onRamp", "offRamp", "bidirectional", "mwyEntry", "mwyExit"}
)
DEFAULT_SPEED: Final = 19.444  # m/s, esmini's speed of a road without a speed record (a rural road)


@dataclass(frozen=True)
class RoadPoint:
    """A position on a road: its road, lane, s and travel direction along s (+1 toward increasing s)."""

    road_id: str
    lane_id: int
    s: float
    direction: int = 1


@dataclass
class Node:
    """A road of a path: entered in `lane` from `from_lane` of the previous road; `direction` is the travel
    direction along this road, `leaves` whether it has a link at its far end (None for the target)."""

    road: str
    lane: int
    from_lane: int
    weight: float
    direction: int
    leaves: bool
    previous: Node | None

    def key(self) -> tuple[str, int, int, int, bool]:
        return (self.road, self.lane, self.from_lane, self.direction, self.leaves)


def is_driving(section: LaneSection, lane_id: int) -> bool:
    lane = section.lane(lane_id)
    return lane is not None and lane_id != 0 and lane.type in DRIVING_TYPES


def _exit_link(road: Road, direction: int) -> object | None:
    return road.successor if direction > 0 else road.predecessor


def _weight(odr: OpenDrive, strategy: str, previous: Node | None, road_id: str, length: float) -> float:
    if strategy == "fastest":
        limit = odr.speed_limit(road_id, 0.0) or DEFAULT_SPEED
        return length / limit
    if strategy == "leastIntersections":
        road = odr.road(previous.road) if previous is not None else None
        link = _exit_link(road, previous.direction) if road is not None and previous is not None else None
        return 1.0 if getattr(link, "element_type", "") == "junction" else 0.0
    return length


def _entered_at_start(odr: OpenDrive, node: Node) -> bool | None:
    """Whether the link from `node`'s road onward reaches the next road at that road's start (None: a junction
    link, which has no contact point)."""
    link = _exit_link(odr.road(node.road), node.direction)
    contact = getattr(link, "contact_point", None)
    return None if contact is None else contact == "start"


def calculate_path(
    odr: OpenDrive, start: RoadPoint, target: RoadPoint, strategy: str = "shortest"
) -> list[Node]:
    """The nodes from the start road to the target road and lane, both included; [] when there is no path (or
    start and target are in the same lane of the same road)."""
    if not _valid(odr, start) or not _valid(odr, target):
        return []
    if start.road_id == target.road_id and start.lane_id == target.lane_id:
        return []
    road = odr.road(start.road_id)
    if _exit_link(road, start.direction) is None:
        return []
    to_end = road.length - start.s if start.direction > 0 else start.s
    if strategy == "fastest":
        weight = to_end / (odr.speed_limit(start.road_id, 0.0) or DEFAULT_SPEED)
    else:
        weight = to_end if strategy != "leastIntersections" else 0.0
    first = Node(start.road_id, start.lane_id, 0, weight, start.direction, True, None)
    counter = itertools.count()
    heap: list[tuple[float, int, int, Node]] = [(first.weight, 0, next(counter), first)]
    visited: set[tuple[str, int, int, int, bool]] = set()
    for _ in range(20000):
        if not heap:
            return []
        _, _, _, node = heapq.heappop(heap)
        if node.key() in visited:
            continue
        visited.add(node.key())
        if node.road == target.road_id and node.lane == target.lane_id:
            out = []
            walk: Node | None = node
            while walk is not None:
                out.append(walk)
                walk = walk.previous
            return out[::-1]
        if not node.leaves:
            continue
        for nxt in _next_nodes(odr, node, target, strategy):
            assert nxt.previous is not None
            tie = abs(nxt.lane - nxt.previous.lane)
            heapq.heappush(heap, (nxt.weight, tie, next(counter), nxt))
    return []


def _valid(odr: OpenDrive, point: RoadPoint) -> bool:
    road = odr.roads.get(point.road_id)
    if road is None or not 0.0 <= point.s <= road.length + 1e-9:
        return False
    return is_driving(_section_at(road, point.s), point.lane_id)


def _section_at(road: Road, s: float) -> LaneSection:
    found = road.lane_sections[0]
    for section in road.lane_sections:
        if section.s <= s + 1e-9:
            found = section
    return found


def _next_nodes(odr: OpenDrive, node: Node, target: RoadPoint, strategy: str) -> list[Node]:
    road = odr.road(node.road)
    section = road.lane_sections[-1] if node.direction > 0 else road.lane_sections[0]
    sign = 1 if node.lane > 0 else -1
    out: list[Node] = []
    lanes = [ln.id for ln in section.left + section.right]
    # esmini walks the section's lanes in its own order (left, centre, right): the order breaks ties only
    for lane_id in sorted(lanes, reverse=True):
        if lane_id == 0 or (1 if lane_id > 0 else -1) != sign or not is_driving(section, lane_id):
            continue
        for next_road, next_lane, next_dir in odr.connections(node.road, lane_id, node.direction):
            if next_lane == 0 or next_road not in odr.roads:
                continue
            nxt_road = odr.road(next_road)
            if next_road == target.road_id and next_lane == target.lane_id:
                at_start = _entered_at_start(odr, node)
                length = 0.0 if at_start is None else (target.s if at_start else nxt_road.length - target.s)
                weight = node.weight + _weight(odr, strategy, node, next_road, length)
                out.append(Node(next_road, next_lane, lane_id, weight, next_dir, False, node))
                continue
            if _exit_link(nxt_road, next_dir) is None:
                continue  # a dead end
            weight = node.weight + _weight(odr, strategy, node, next_road, nxt_road.length)
            out.append(Node(next_road, next_lane, lane_id, weight, next_dir, True, node))
    return out


def waypoints(odr: OpenDrive, path: list[Node], start: RoadPoint, target: RoadPoint) -> list[RoadPoint]:
    """One waypoint per road of `path` but the last (in the lane that leads to the next road, halfway along
    the stretch where that lane exists, or at the start position on the start road when it is already in
    that stretch), then the target."""
    out: list[RoadPoint] = []
    for index in range(len(path) - 1):
        current, nxt = path[index], path[index + 1]
        road = odr.road(current.road)
        lane = nxt.from_lane
        length = 0.0
        sections = road.lane_sections[::-1] if current.direction > 0 else road.lane_sections
        for section in sections:
            if not is_driving(section, lane):
                break
            length += section.end - section.s
        if current.direction > 0:
            s = road.length - length / 2.0
            if index == 0 and start.s > road.length - length:
                s = start.s
        else:
            s = length / 2.0
            if index == 0 and start.s < length:
                s = start.s
        out.append(RoadPoint(current.road, lane, s, current.direction))
    out.append(target)
    return out
