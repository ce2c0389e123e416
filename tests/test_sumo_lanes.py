"""Scripted vehicles in SUMO: the lane walk (simcore/world/sumo_lanes.py) and SumoWorld putting a vehicle that
stays on its edge in place with `moveTo` must put it where SUMO's own `moveToXY` search does."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from simcore.world.sumo_lanes import LaneShape, locate_on, nearest_lane

ROOT = Path(__file__).resolve().parents[1]


def _arc(lane_id: str, radius: float, points: int = 200, length: float | None = None) -> LaneShape:
    """A quarter circle around the origin, counter-clockwise from (radius, 0)."""
    pts = tuple(
        (
            radius * math.cos(0.5 * math.pi * i / (points - 1)),
            radius * math.sin(0.5 * math.pi * i / (points - 1)),
        )
        for i in range(points)
    )
    shape = LaneShape.of(lane_id, pts, 1.0)
    return LaneShape.of(lane_id, pts, length if length is not None else shape.along[-1])


def _brute(shape: LaneShape, x: float, y: float) -> tuple[float, float]:
    """(distance, lane position) of the nearest point of the polyline, by trying every segment."""
    best = (math.inf, 0.0)
    for i in range(len(shape.xs) - 1):
        x0, y0, x1, y1 = shape.xs[i], shape.ys[i], shape.xs[i + 1], shape.ys[i + 1]
        dx, dy = x1 - x0, y1 - y0
        u = min(max(((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy), 0.0), 1.0)
        d = math.hypot(x0 + u * dx - x, y0 + u * dy - y)
        if d < best[0]:
            best = (d, (shape.along[i] + u * math.hypot(dx, dy)) * shape.scale)
    return best


def test_walk_from_a_hint_finds_the_nearest_point_of_the_polyline() -> None:
    shape = _arc(
        "e_0", 100.0, length=170.0
    )  # SUMO's lane length differs from the polyline's: positions scale
    rng = random.Random(4)
    hint: int | None = None
    for step in range(300):
        angle = 0.5 * math.pi * (0.02 + 0.96 * step / 299)
        r = 100.0 + rng.uniform(-2.0, 2.0)
        x, y = r * math.cos(angle), r * math.sin(angle)
        on = locate_on(shape, x, y, hint)
        assert on is not None
        distance, pos = _brute(shape, x, y)
        assert on.distance == pytest.approx(distance, abs=1e-9)
        assert on.pos == pytest.approx(pos, abs=1e-9)
        hint = on.segment
    # a jump far along the lane from a stale hint still lands on the nearest point (or gives up: None)
    x, y = 101.0 * math.cos(1.4), 101.0 * math.sin(1.4)
    far = locate_on(shape, x, y, 0)
    assert far is None or far.pos == pytest.approx(_brute(shape, x, y)[1], abs=1e-9)
    whole = locate_on(shape, x, y, None)
    assert whole is not None and whole.pos == pytest.approx(_brute(shape, x, y)[1], abs=1e-9)


def test_points_before_the_start_or_past_the_end_are_not_on_the_lane() -> None:
    shape = LaneShape.of("e_0", ((0.0, 0.0), (10.0, 0.0), (20.0, 0.0)), 20.0)
    assert locate_on(shape, -1.0, 0.5, 0) is None
    assert locate_on(shape, 21.0, 0.5, 1) is None
    on = locate_on(shape, 15.0, -1.5, 0)
    assert on is not None and on.pos == pytest.approx(15.0) and on.distance == pytest.approx(1.5)


def test_nearest_lane_is_the_lane_whose_centre_line_is_closest() -> None:
    lanes = [
        LaneShape.of(f"e_{i}", ((0.0, -3.5 * i), (50.0, -3.5 * i), (100.0, -3.5 * i)), 100.0)
        for i in range(3)
    ]
    hints: dict[str, int] = {}
    for y, expected in (
        (0.4, "e_0"),
        (-1.7, "e_0"),
        (-1.8, "e_1"),
        (-4.5, "e_1"),
        (-5.3, "e_2"),
        (-8.0, "e_2"),
    ):
        found = nearest_lane(lanes, 60.0, y, hints)
        assert found is not None and found[0].lane_id == expected
    assert set(hints) == {"e_0", "e_1", "e_2"}  # every lane keeps where the walk ended


def test_a_scripted_vehicle_on_its_edge_is_where_sumo_search_puts_it(tmp_path: Path) -> None:
    """A scripted vehicle driven along a curved motorway lane and across into the next lane (a cut-in), next to
    a twin placed by SUMO's own moveToXY search at the same spot each step: same lane, same position."""
    pytest.importorskip("libsumo")
    from simcore.world.sumo import SumoWorld, netconvert_available, prepare_network

    if not netconvert_available():
        pytest.skip("netconvert is not installed")
    from simcore.world.opendrive import OpenDrive

    road_file = ROOT / "examples" / "maps" / "highway.xodr"
    road = OpenDrive.from_file(road_file)
    network = prepare_network(road_file, cache_dir=tmp_path)
    dt = 0.05
    with SumoWorld(network, dt, seed=1) as world:
        start = road.road_to_world("1", 300.0, road.lane_center_t("1", -1, 300.0))
        kwargs = {
            "length": 4.5, "width": 1.8, "height": 1.5, "front_offset": 3.65, "max_speed": 50.0,
            "max_accel": 4.0, "max_decel": 9.0, "x": start.x, "y": start.y, "heading": start.heading, "speed": 25.0,
        }  # fmt: skip
        world.add_vehicle("fast", scripted=True, **kwargs)
        world.add_vehicle("twin", scripted=False, **kwargs)  # placed with moveToXY at every place()
        sumo = world._sumo
        sumo.vehicle.setSpeedMode("twin", 0)
        s, lanes_seen, moved_to = 300.0, set(), 0
        for step in range(400):
            s += 25.0 * dt
            # from lane -1 towards lane -2 between 5 s and 8 s: the front crosses the lane border
            share = min(max((step * dt - 5.0) / 3.0, 0.0), 1.0)
            t = (1 - share) * road.lane_center_t("1", -1, s) + share * road.lane_center_t("1", -2, s)
            pose = road.road_to_world("1", s, t)
            for name in ("fast", "twin"):
                world.place(name, pose.x, pose.y, pose.heading, 25.0)
                sumo.vehicle.setSpeed("twin", 25.0)
            on_edge = world._spot_on_edge("fast", *world._targets["fast"][:2], 25.0) is not None
            world.step()
            moved_to += on_edge
            if step < 2:
                continue
            lane = sumo.vehicle.getLaneID("fast")
            lanes_seen.add(lane)
            assert lane == sumo.vehicle.getLaneID("twin"), f"step {step}"
            assert sumo.vehicle.getLanePosition("fast") == pytest.approx(
                sumo.vehicle.getLanePosition("twin"), abs=1e-6
            ), f"step {step}"
        assert len(lanes_seen) == 2  # it did change lanes
        assert moved_to > 350  # and almost every step took the walk, not SUMO's search


def _edge(rng: random.Random, lanes: int, width: float, sharp: bool) -> list[LaneShape]:
    """Parallel lanes around a wandering centre line (points 0-8 m apart, some repeated; `sharp`: bends tight
    enough for the inner lanes' polylines to fold over), offset along each point's normal as SUMO does."""
    x, y, heading = 0.0, 0.0, rng.uniform(-math.pi, math.pi)
    centre = [(x, y, heading)]
    for _ in range(rng.randint(2, 120)):
        step = 0.0 if rng.random() < 0.03 else rng.uniform(0.5, 8.0)
        heading += rng.uniform(-1.2, 1.2) if sharp else rng.gauss(0.0, 0.03)
        x, y = x + step * math.cos(heading), y + step * math.sin(heading)
        centre.append((x, y, heading))
    shapes = []
    for index in range(lanes):
        offset = (index - (lanes - 1) / 2) * width
        points = tuple((px - offset * math.sin(h), py + offset * math.cos(h)) for px, py, h in centre)
        shape = LaneShape.of(f"e_{index}", points, 1.0)
        shapes.append(LaneShape.of(f"e_{index}", points, shape.along[-1] * rng.uniform(0.98, 1.02)))
    return shapes


def test_walking_the_last_lane_first_finds_what_walking_every_lane_finds(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """nearest_lane with the lane of the last step (`near`) skips lanes shown to be farther: every answer and
    every hint left for the next step must equal those of walking every lane, on straight, curved and folded
    edges, while drifting across lanes, jumping, and with a wrong `near`."""
    from simcore.world import sumo_lanes

    walks = {"every": 0, "near": 0}
    counting = "every"
    plain_locate = sumo_lanes.locate_on

    def counted(*args: object, **kwargs: object) -> object:
        walks[counting] += 1
        return plain_locate(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(sumo_lanes, "locate_on", counted)
    rng = random.Random(7)
    steps = 0
    for case in range(60):
        shapes = _edge(rng, rng.randint(1, 5), rng.uniform(2.5, 4.0), sharp=case % 6 == 5)
        lead = shapes[rng.randrange(len(shapes))]
        every_hints: dict[str, int] = {}
        near_hints: dict[str, int] = {}
        gaps: sumo_lanes.SegmentGaps = {}
        near: LaneShape | None = None
        s, lateral, target = rng.uniform(0.0, 5.0), 0.0, 0.0
        for _ in range(200):
            s += rng.uniform(-0.5, 2.0) if rng.random() > 0.02 else rng.uniform(-80.0, 80.0)
            if rng.random() < 0.03:  # a lane change (or a drift off the edge)
                target = rng.uniform(-8.0, 8.0)
            lateral += 0.2 * (target - lateral) + rng.gauss(0.0, 0.1)
            i = min(max(int(s / max(lead.along[-1], 1e-9) * (len(lead.xs) - 1)), 0), len(lead.xs) - 2)
            along, length = rng.uniform(0.0, 1.0), max(lead.seglens[i], 1e-9)
            x = lead.xs[i] + along * lead.dxs[i] - lateral * lead.dys[i] / length
            y = lead.ys[i] + along * lead.dys[i] + lateral * lead.dxs[i] / length
            counting = "every"
            expected = nearest_lane(shapes, x, y, every_hints)
            counting = "near"
            if rng.random() < 0.05:
                near = rng.choice([None, shapes[rng.randrange(len(shapes))]])  # not the lane it was on
            found = nearest_lane(shapes, x, y, near_hints, near, gaps)
            assert (found is None) == (expected is None)
            if found is not None and expected is not None:
                assert found[0].lane_id == expected[0].lane_id
                assert tuple(found[1]) == tuple(expected[1])  # bit for bit
            assert near_hints == every_hints
            near = found[0] if found is not None else near
            steps += 1
    assert walks["near"] < 0.75 * walks["every"]  # and it did skip lanes


def test_lane_geometry_is_shared_only_between_identical_edges() -> None:
    """A warm worker builds an edge's lanes once; an edge whose points or length differ in any way (another
    network, or the same file changed) gets its own lanes and its own gap cache."""
    from simcore.world.sumo_lanes import edge_lanes

    raw = (
        ("e_0", ((0.0, 0.0), (100.0, 0.0)), 100.0),
        ("e_1", ((0.0, 3.5), (100.0, 3.5)), 100.0),
    )
    first = edge_lanes(raw)
    first.gaps[("e_0", 0, "e_1", 0)] = 3.5
    again = edge_lanes(tuple((lane_id, tuple(points), length) for lane_id, points, length in raw))
    assert again is first
    moved = edge_lanes((raw[0], ("e_1", ((0.0, 3.5), (100.0, 3.6)), 100.0)))
    longer = edge_lanes((raw[0], ("e_1", ((0.0, 3.5), (100.0, 3.5)), 100.5)))
    assert moved is not first and longer is not first and moved is not longer
    assert moved.gaps == {} and longer.gaps == {}
    assert moved.by_id["e_1"].ys == (3.5, 3.6)
