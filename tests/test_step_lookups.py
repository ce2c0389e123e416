"""The road look-ups of the step loop that reuse what an earlier look-up found give the same floats as the
look-ups they stand for: a record's frame with its curvature, the reference line kept at a body's pose, and
`world_to_road` answering from the hinted road alone."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from simcore.scenario import model as m
from simcore.scenario.motion import Body, advance_on_road, reference_heading, update_pose_from_road
from simcore.world.opendrive import OpenDrive

ROADS = Path(__file__).resolve().parent / "differential_corpus" / "roads"
NETWORKS = [
    "SampleDatabase.xodr",
    "curves.xodr",
    "e6mini.xodr",
    "fabriksgatan.xodr",
    "multi_intersections.xodr",
]


def _network(name: str) -> OpenDrive:
    return OpenDrive.from_file(ROADS / name)


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """Equal floats, bit for bit (NaN equal to NaN)."""
    return len(a) == len(b) and all(x == y or (x != x and y != y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("name", NETWORKS)
def test_frame_k_is_frame_and_curvature(name: str) -> None:
    """Every planView record's frame_k is its frame and curvature; a road's world_xyzk is its world_xyz and
    curvature at s (whichever was asked first: a paramPoly3 keeps its last parameter)."""
    od = _network(name)
    rng = random.Random(name)
    kinds = set()
    for road in od.roads.values():
        for g in road.geometries:
            kinds.add(g.kind)
            for ds in (0.0, g.length, *(rng.uniform(0.0, g.length) for _ in range(5))):
                k = g.frame_k(ds)
                assert _same(k, (*g.frame(ds), g.curvature(ds))), (name, road.id, g.kind, ds)
                assert _same(k[:3], g.local(ds)), (name, road.id, g.kind, ds)
        for s in (0.0, road.length, *(rng.uniform(0.0, road.length) for _ in range(8))):
            t = rng.uniform(-6.0, 6.0)
            assert _same(road.world_xyzk(s, t), (*road.world_xyz(s, t), road.curvature(s))), (
                name,
                road.id,
                s,
            )
            assert _same(road.world_xyzk(s, t)[:4], road.world_xyz(s, t)), (name, road.id, s)
    assert kinds  # (the networks together have every record type, elevations and superelevations)


@pytest.mark.parametrize("name", ["fabriksgatan.xodr", "e6mini.xodr", "curves.xodr"])
def test_pose_keeps_the_reference_line_where_it_is(name: str) -> None:
    """A body moved along its lane keeps the curvature and heading of the reference line at its pose, the
    floats the road gives there; elsewhere `reference_heading` asks the road."""
    od = _network(name)
    entity = m.Entity("Car", "vehicle", "car", m.Box(1.4, 0.0, 0.75, 4.5, 1.8, 1.5), m.Performance())
    for road_id, road in od.roads.items():
        lanes = [lane for lane in od.lane_ids(road_id, 0.0) if lane < 0]
        if not lanes or road.length < 5.0:
            continue
        body = Body(entity=entity, road_id=road_id, lane_id=lanes[0], s=0.0, speed=10.0)
        update_pose_from_road(od, body)
        for _ in range(40):
            advance_on_road(od, body, 0.7, 0.0)
            if body.road_id is None or body.ref_road is not od.roads[body.road_id]:
                break  # off this road's table (past its end): the next road is another test's
            r = od.roads[body.road_id]
            assert body.ref_s == body.s
            assert body.ref_kappa == r.curvature(body.s)
            assert body.ref_heading == r.reference_xyh(body.s)[2]
            assert reference_heading(r, body, body.s) == r.reference_xyh(body.s)[2]
            other = min(body.s + 0.3, r.length)
            assert reference_heading(r, body, other) == r.reference_xyh(other)[2]


@pytest.mark.parametrize("name", ["SampleDatabase.xodr", "multi_intersections.xodr", "fabriksgatan.xodr"])
def test_world_to_road_prefers_the_hinted_road_it_is_on(name: str) -> None:
    """A point inside a lane of the hinted road is on that road, also where junction roads overlap it; with
    another hint or none it is on a road whose lane holds it there."""
    od = _network(name)
    rng = random.Random(name)
    overlapping = 0
    for road_id, road in od.roads.items():
        for _ in range(4):
            s = rng.uniform(0.05, road.length - 0.05) if road.length > 0.1 else road.length / 2
            ids = [lane for lane in od.lane_ids(road_id, s) if lane != 0]
            if not ids:
                continue
            lane_id = rng.choice(ids)
            width = od.lane_width(road_id, lane_id, s)
            if width < 0.5:
                continue
            p = od.lane_to_world(road_id, lane_id, s, rng.uniform(-0.3, 0.3) * width)
            hinted = od.world_to_road(p.x, p.y, None, road_hint=road_id)
            assert hinted is not None and hinted.road_id == road_id, (name, road_id, lane_id, s, hinted)
            assert hinted.lane_id == lane_id and hinted.s == pytest.approx(s, abs=1e-6)
            free = od.world_to_road(p.x, p.y, None)
            assert free is not None
            q = od.road_to_world(free.road_id, free.s, free.t)
            assert math.hypot(q.x - p.x, q.y - p.y) < 1e-3
            overlapping += free.road_id != road_id
    if name != "fabriksgatan.xodr":
        assert overlapping > 0  # junctions: some points lie on more than one road


@pytest.mark.parametrize("name", NETWORKS)
def test_a_lane_cross_gives_its_centres_from_its_table_as_from_its_dict(name: str) -> None:
    """`LaneCross.centre_of` (a table from the lowest lane id) answers as the `centres` dict does, for every
    stretch of every road and every lane id near and far."""
    od = _network(name)
    crosses = 0
    for road in od.roads.values():
        for s in (0.0, road.length / 3, road.length / 2, road.length):
            cross = road.cross_at(s)
            if cross is None:
                continue
            crosses += 1
            for lane_id in range(-80, 81):
                centre = cross.centres.get(lane_id)
                assert cross.centre_of(lane_id) == ((False, 0.0) if centre is None else (True, centre))
    assert crosses


def test_a_lane_cross_with_lane_ids_far_apart_answers_from_its_dict() -> None:
    from simcore.world.road_model import MAX_CENTRE_TABLE, Lane, LaneCross

    far = MAX_CENTRE_TABLE + 5
    cross = LaneCross([(Lane(-1, "driving"), 0.0, -3.5)], [(Lane(far, "driving"), 0.0, 3.0)])
    assert cross.centres == {-1: -1.75, far: 1.5}
    assert cross.centre_of(-1) == (True, -1.75)
    assert cross.centre_of(far) == (True, 1.5)
    assert cross.centre_of(1) == (False, 0.0)
