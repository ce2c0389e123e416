"""simcore.evaluation: metrics from hand-built frames, box geometry properties, criteria, summaries, JUnit."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter

from simcore.evaluation.criteria import CriterionResult, evaluate, verdict
from simcore.evaluation.metrics import (
    TOUCH_TOLERANCE,
    Box,
    MetricsAccumulator,
    box_distance,
    boxes_overlap,
    footprint,
    separation,
)
from simcore.evaluation.report import index_summary, junit_xml, run_summary
from simcore.evaluation.report import testcase_name as case_name
from simcore.spec import Criterion, CriterionModel
from simcore.world.state import BoundingBox, EntityState, LaneCoordinates, WorldFrame

EPS = 1e-9


def car(
    name: str,
    x: float,
    y: float = 0.0,
    *,
    heading: float = 0.0,
    speed: float = 0.0,
    acceleration: float = 0.0,
    lane: int | None = None,
    road: str = "1",
    length: float = 4.5,
    width: float = 1.8,
    center_x: float = 1.4,
) -> EntityState:
    """A car whose reference point (rear axle) is 1.4 m behind its box centre, by default."""
    return EntityState(
        name=name,
        object_type="vehicle",
        category="car",
        x=x,
        y=y,
        z=0.0,
        heading=heading,
        pitch=0.0,
        roll=0.0,
        speed=speed,
        acceleration=acceleration,
        yaw_rate=0.0,
        bbox=BoundingBox(center_x, 0.0, 0.75, length, width, 1.5),
        lane=None if lane is None else LaneCoordinates(road, lane, x, y, 0.0),
    )


def frame(t: float, *entities: EntityState, ego: str | None = "ego") -> WorldFrame:
    return WorldFrame(step=round(t * 20), time=t, entities=entities, ego=ego)


def square(x: float, y: float, heading: float = 0.0, half: float = 1.0) -> EntityState:
    return car("sq", x, y, heading=heading, length=2 * half, width=2 * half, center_x=0.0)


# ---------------------------------------------------------------------------------------------- metrics


def head_on_frames(lane_other: int | None = None, lane_ego: int | None = None) -> list[WorldFrame]:
    """Ego eastbound and a car westbound in the same lane, both at 10 m/s, 50 m apart at t=0.

    Boxes (x extents): ego at x=e spans [e-0.85, e+3.65]; the other at x=o (heading π) spans
    [o-3.65, o+0.85]. Free gap = (o - e) - 7.3."""
    accelerations = [0.5, -3.0, -1.0]
    return [
        frame(
            float(t),
            car("ego", 10.0 * t, speed=10.0, acceleration=a, lane=lane_ego),
            car("other", 50.0 - 10.0 * t, heading=math.pi, speed=10.0, lane=lane_other),
        )
        for t, a in zip((0, 1, 2), accelerations, strict=True)
    ]


def test_head_on_before_contact() -> None:
    acc = MetricsAccumulator()
    for f in head_on_frames():
        acc.update(f)
    m = acc.result()
    # Closest at t=2: ego front 23.65, other rear 26.35.
    assert m["minDistance"] == pytest.approx(2.7, abs=EPS)
    assert m["minTimeHeadway"] == pytest.approx(0.27, abs=EPS)  # 2.7 m / 10 m/s
    assert m["minTimeToCollision"] == pytest.approx(0.135, abs=EPS)  # 2.7 m / (10 + 10) m/s
    assert m["collision"] == 0.0
    assert "collisionTime" not in m
    assert "minLateralDistance" not in m  # never side by side
    assert m["maxDeceleration"] == 3.0
    assert m["maxAcceleration"] == 0.5
    assert m["maxSpeed"] == 10.0
    assert m["meanSpeed"] == pytest.approx(10.0, abs=EPS)
    assert m["egoDistance"] == pytest.approx(20.0, abs=EPS)
    assert m["simSeconds"] == 2.0
    assert acc.details() == {
        "minDistanceWith": "other",
        "minTimeHeadwayWith": "other",
        "minTimeToCollisionWith": "other",
    }


def test_head_on_collision() -> None:
    acc = MetricsAccumulator()
    for f in head_on_frames():
        acc.update(f)
    # t=2.2: ego box [21.15, 25.65], other box [24.35, 28.85]: 1.3 m overlap.
    acc.update(frame(2.2, car("ego", 22.0, speed=10.0), car("other", 28.0, heading=math.pi, speed=10.0)))
    acc.update(
        frame(2.25, car("ego", 22.5, speed=0.0, acceleration=-8.0), car("other", 27.5, heading=math.pi))
    )
    m = acc.result()
    assert m["collision"] == 1.0
    assert m["collisionTime"] == 2.2
    assert m["minDistance"] == 0.0
    assert m["minTimeHeadway"] == 0.0  # gap clamped at 0 while overlapping
    assert m["minTimeToCollision"] == 0.0
    assert m["minLateralDistance"] == 0.0  # side by side once overlapping
    assert m["maxDeceleration"] == 8.0
    assert m["egoDistance"] == pytest.approx(22.5, abs=EPS)
    # |speed| integral: 10 m/s for 2.2 s, then 10 → 0 over 0.05 s: 22.25 m over 2.25 s.
    assert m["meanSpeed"] == pytest.approx(22.25 / 2.25, abs=EPS)
    assert m["simSeconds"] == 2.25
    details = acc.details()
    assert details["collisionWith"] == "other"
    assert details["collisionEntities"] == ["other"]


def test_lane_coordinates_decide_the_lane() -> None:
    same = MetricsAccumulator()
    for f in head_on_frames(lane_other=-1, lane_ego=-1):
        same.update(f)
    assert same.result()["minTimeHeadway"] == pytest.approx(0.27, abs=EPS)
    other_lane = MetricsAccumulator()
    for f in head_on_frames(lane_other=-2, lane_ego=-1):
        other_lane.update(f)
    m = other_lane.result()
    # Geometrically in the ego's lane, but the lane coordinates say otherwise.
    assert "minTimeHeadway" not in m
    assert "minTimeToCollision" not in m
    assert m["minDistance"] == pytest.approx(2.7, abs=EPS)


def cut_in_frames(cutter_speed: float = 15.0, lanes: tuple[int, int, int] | None = None) -> list[WorldFrame]:
    """Ego at 20 m/s in y=0; the cutter moves from y=3.5 (next lane) to y=1.0 (within ±1.75 m)."""
    positions = [(20.0, 3.5), (35.0, 2.0), (50.0, 1.0)]
    return [
        frame(
            float(t),
            car("ego", 20.0 * t, speed=20.0, lane=None if lanes is None else -1),
            car("cutter", x, y, speed=cutter_speed, lane=None if lanes is None else lanes[t]),
        )
        for t, (x, y) in enumerate(positions)
    ]


def test_cut_in() -> None:
    acc = MetricsAccumulator()
    for f in cut_in_frames():
        acc.update(f)
    m = acc.result()
    # t=0: x gap 19.15-3.65 = 15.5, y gap 2.6-0.9 = 1.7; t=1: x gap 34.15-23.65 = 10.5, y gap 1.1-0.9 = 0.2;
    # t=2: boxes overlap laterally, ego front 40+3.65 = 43.65, cutter rear 50-0.85 = 49.15: 5.5 m.
    assert m["minDistance"] == pytest.approx(5.5, abs=EPS)
    # Only t=2 counts (|lateral| 1.0 <= 1.75); t=0 (3.5) and t=1 (2.0) are in the next lane.
    assert m["minTimeHeadway"] == pytest.approx(5.5 / 20.0, abs=EPS)
    assert m["minTimeToCollision"] == pytest.approx(5.5 / 5.0, abs=EPS)
    assert "minLateralDistance" not in m
    assert m["collision"] == 0.0


def test_cut_in_by_a_faster_car_has_no_time_to_collision() -> None:
    acc = MetricsAccumulator()
    for f in cut_in_frames(cutter_speed=25.0):
        acc.update(f)
    m = acc.result()
    assert m["minTimeHeadway"] == pytest.approx(5.5 / 20.0, abs=EPS)
    assert "minTimeToCollision" not in m


def test_cut_in_with_lane_coordinates() -> None:
    acc = MetricsAccumulator()
    for f in cut_in_frames(lanes=(-2, -2, -2)):  # still in the next lane by the lane coordinates
        acc.update(f)
    assert "minTimeHeadway" not in acc.result()
    acc = MetricsAccumulator()
    for f in cut_in_frames(lanes=(-2, -1, -1)):  # in the ego's lane from t=1 on: 10.5 m ahead at t=1
        acc.update(f)
    assert acc.result()["minTimeHeadway"] == pytest.approx(5.5 / 20.0, abs=EPS)
    assert acc.result()["minTimeToCollision"] == pytest.approx(min(10.5 / 5.0, 5.5 / 5.0), abs=EPS)


def test_side_by_side_lateral_distance() -> None:
    acc = MetricsAccumulator()
    acc.update(frame(0.0, car("ego", 0.0, speed=20.0), car("left", 1.0, 3.0, speed=20.0)))
    m = acc.result()
    assert m["minLateralDistance"] == pytest.approx(3.0 - 1.8, abs=EPS)
    assert m["minDistance"] == pytest.approx(1.2, abs=EPS)
    assert "minTimeHeadway" not in m  # alongside, not ahead in lane (3.0 > 1.75)


def test_headway_needs_ego_speed() -> None:
    acc = MetricsAccumulator()
    acc.update(frame(0.0, car("ego", 0.0, speed=0.05), car("lead", 20.0, speed=0.0)))
    m = acc.result()
    assert "minTimeHeadway" not in m
    # Closing at 0.05 m/s > 0.01 m/s: TTC = 15.5 / 0.05.
    assert m["minTimeToCollision"] == pytest.approx(15.5 / 0.05, rel=1e-12)


def test_behind_is_not_ahead() -> None:
    acc = MetricsAccumulator()
    acc.update(frame(0.0, car("ego", 0.0, speed=20.0), car("follower", -20.0, speed=30.0)))
    m = acc.result()
    assert "minTimeHeadway" not in m and "minTimeToCollision" not in m
    assert m["minDistance"] == pytest.approx(15.5, abs=EPS)


def test_rotated_ego_frame() -> None:
    """The same head-on scene rotated by 1 rad around an arbitrary point gives the same numbers."""
    angle, px, py = 1.0, 3.0, -7.0
    c, s = math.cos(angle), math.sin(angle)

    def rotate(e: EntityState) -> EntityState:
        x, y = e.x - px, e.y - py
        return car(e.name, px + c * x - s * y, py + s * x + c * y, heading=e.heading + angle, speed=e.speed)

    acc = MetricsAccumulator()
    for f in head_on_frames():
        acc.update(frame(f.time, *(rotate(e) for e in f.entities)))
    m = acc.result()
    assert m["minDistance"] == pytest.approx(2.7, abs=1e-9)
    assert m["minTimeHeadway"] == pytest.approx(0.27, abs=1e-9)
    assert m["minTimeToCollision"] == pytest.approx(0.135, abs=1e-9)
    assert m["egoDistance"] == pytest.approx(20.0, abs=1e-9)


def test_ego_defaults_to_first_entity_and_must_exist() -> None:
    acc = MetricsAccumulator()
    acc.update(frame(0.0, car("a", 0.0, speed=3.0), car("b", 20.0), ego=None))
    assert acc.result()["maxSpeed"] == 3.0
    with pytest.raises(ValueError, match="'hero' is not among"):
        acc.update(frame(0.05, car("a", 0.0), ego="hero"))


def test_empty_accumulator_and_lonely_ego() -> None:
    acc = MetricsAccumulator()
    assert acc.result() == {}
    acc.update(frame(0.0))
    assert acc.result() == {"simSeconds": 0.0}
    acc.update(frame(0.05, car("ego", 0.0, speed=2.0)))
    m = acc.result()
    assert m["collision"] == 0.0 and "minDistance" not in m
    assert m["meanSpeed"] == 2.0 and m["simSeconds"] == 0.05


def test_corner_touch_in_accumulator_is_a_collision() -> None:
    acc = MetricsAccumulator()
    acc.update(frame(0.5, square(0, 0), square(1 + math.sqrt(2), 1, math.pi / 4), ego=None))
    assert acc.result()["collision"] == 1.0
    assert acc.result()["collisionTime"] == 0.5


# --------------------------------------------------------------------------------------------- geometry


def test_rotated_squares_touching_at_a_corner() -> None:
    a = Box.of(square(0, 0))
    # A square rotated 45° whose left vertex is exactly at a's corner (1, 1).
    b = Box.of(square(1 + math.sqrt(2), 1, math.pi / 4))
    assert boxes_overlap(a, b)
    assert box_distance(a, b) == 0.0


def test_rotated_squares_one_centimetre_apart() -> None:
    a = Box.of(square(0, 0))
    b = Box.of(square(1.01 + math.sqrt(2), 1, math.pi / 4))
    assert not boxes_overlap(a, b)
    assert separation(a, b) == pytest.approx(0.01, abs=1e-12)
    assert box_distance(a, b) == pytest.approx(0.01, abs=1e-12)


def test_separating_axis_of_the_rotated_box_only() -> None:
    """Diagonally apart: the projections overlap on a's axes; only b's axis separates them."""
    a = Box.of(square(0, 0))
    b = Box.of(square(2, 2, math.pi / 4))
    for ax, ay in a.axes:
        pa = [x * ax + y * ay for x, y in a.corners]
        pb = [x * ax + y * ay for x, y in b.corners]
        assert min(pb) < max(pa)
    assert not boxes_overlap(a, b)
    assert box_distance(a, b) == pytest.approx(math.sqrt(2) - 1, abs=1e-12)


def _segments_intersect(
    p: tuple[float, float], q: tuple[float, float], r: tuple[float, float], s: tuple[float, float]
) -> bool:
    def orient(a: tuple[float, float], b: tuple[float, float], c: tuple[float, float]) -> float:
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    d1, d2, d3, d4 = orient(r, s, p), orient(r, s, q), orient(p, q, r), orient(p, q, s)
    if d1 == d2 == d3 == d4 == 0:  # collinear: intersect iff the extents overlap on both coordinates
        return all(
            max(min(p[k], q[k]), min(r[k], s[k])) <= min(max(p[k], q[k]), max(r[k], s[k])) for k in (0, 1)
        )
    return d1 * d2 <= 0 and d3 * d4 <= 0


def _inside(point: tuple[float, float], corners: tuple[tuple[float, float], ...]) -> bool:
    x, y = point
    signs = [
        (corners[i][0] - corners[i - 1][0]) * (y - corners[i - 1][1])
        - (corners[i][1] - corners[i - 1][1]) * (x - corners[i - 1][0])
        for i in range(4)
    ]
    return all(v >= 0 for v in signs) or all(v <= 0 for v in signs)


def _oracle_distance(a: Box, b: Box) -> float:
    """Polygon distance without the separating-axis theorem: 0 if edges cross or one contains the
    other, else the least vertex-to-edge distance."""
    ca, cb = a.corners, b.corners
    for i in range(4):
        for j in range(4):
            if _segments_intersect(ca[i - 1], ca[i], cb[j - 1], cb[j]):
                return 0.0
    if _inside(ca[0], cb) or _inside(cb[0], ca):
        return 0.0
    best = math.inf
    for p, q in ((ca, cb), (cb, ca)):
        for px, py in p:
            for j in range(4):
                (x0, y0), (x1, y1) = q[j - 1], q[j]
                dx, dy = x1 - x0, y1 - y0
                t = max(0.0, min(1.0, ((px - x0) * dx + (py - y0) * dy) / (dx * dx + dy * dy)))
                best = min(best, math.hypot(px - x0 - t * dx, py - y0 - t * dy))
    return best


coords = st.floats(-10, 10, allow_nan=False)
boxes = st.builds(
    lambda x, y, h, length, width: Box.of(
        car("b", x, y, heading=h, length=length, width=width, center_x=0.3)
    ),
    coords,
    coords,
    st.floats(-math.pi, math.pi),
    st.floats(0.05, 8.0),
    st.floats(0.05, 4.0),
)


@settings(max_examples=400, deadline=None)
@given(boxes, boxes)
def test_box_distance_properties(a: Box, b: Box) -> None:
    d = box_distance(a, b)
    assert d >= 0.0
    assert d == box_distance(b, a)  # symmetric, exactly
    overlap = boxes_overlap(a, b)
    assert overlap == boxes_overlap(b, a)
    assert (d == 0.0) == overlap  # 0 iff the separating-axis test finds no separating axis
    if not overlap:
        # The gap on any axis is a lower bound of the distance; it exceeds the touch tolerance.
        assert d >= separation(a, b) - 1e-12
        assert separation(a, b) > TOUCH_TOLERANCE
    assert d == pytest.approx(_oracle_distance(a, b), abs=1e-6)


@settings(max_examples=300, deadline=None)
@given(
    coords,
    coords,
    st.floats(0.05, 8),
    st.floats(0.05, 8),
    coords,
    coords,
    st.floats(0.05, 8),
    st.floats(0.05, 8),
)
def test_axis_aligned_distance_is_exact(
    x1: float, y1: float, l1: float, w1: float, x2: float, y2: float, l2: float, w2: float
) -> None:
    a = Box.of(car("a", x1, y1, length=l1, width=w1, center_x=0.0))
    b = Box.of(car("b", x2, y2, length=l2, width=w2, center_x=0.0))
    gx = max(abs(x1 - x2) - (l1 + l2) / 2, 0.0)
    gy = max(abs(y1 - y2) - (w1 + w2) / 2, 0.0)
    expected = math.hypot(gx, gy)
    d = box_distance(a, b)
    if expected > 1e-6:
        assert d == pytest.approx(expected, abs=1e-9)
    else:
        assert d < 1e-6


@settings(max_examples=200, deadline=None)
@given(boxes, boxes, st.floats(-math.pi, math.pi), coords, coords)
def test_box_distance_is_invariant_under_rigid_motion(
    a: Box, b: Box, angle: float, tx: float, ty: float
) -> None:
    c, s = math.cos(angle), math.sin(angle)

    def move(box: Box) -> Box:
        corners = tuple((c * x - s * y + tx, s * x + c * y + ty) for x, y in box.corners)
        axes = tuple((c * x - s * y, s * x + c * y) for x, y in box.axes)
        return Box.of_points(corners, axes)

    assert box_distance(move(a), move(b)) == pytest.approx(box_distance(a, b), abs=1e-6)


# --------------------------------------------------------------------------------------------- criteria


def crit(text: str) -> CriterionModel:
    model: CriterionModel = TypeAdapter(Criterion).validate_python(text)
    return model


def test_criteria_operators() -> None:
    metrics = {"minDistance": 2.0, "collision": 0.0, "simSeconds": 0.05 * 200}
    results = evaluate(
        [
            crit("minDistance >= 2"),
            crit("minDistance > 2"),
            crit("minDistance <= 2"),
            crit("minDistance < 2"),
            crit("collision == false"),
            crit("collision != 0"),
            crit("simSeconds == 10"),
        ],
        metrics,
    )
    assert [r.passed for r in results] == [True, False, True, False, True, False, True]
    first = results[0]
    assert (first.name, first.metric, first.expected, first.actual, first.optional) == (
        "minDistance >= 2",
        "minDistance",
        ">= 2",
        2.0,
        False,
    )
    assert results[1].message == "minDistance = 2 m: > 2 m does not hold"
    assert results[4].expected == "== 0"
    assert verdict(results, None) == "failed"


def test_equality_tolerance_is_tight() -> None:
    (result,) = evaluate([crit("simSeconds == 10")], {"simSeconds": 10.001})
    assert not result.passed
    (result,) = evaluate([crit("simSeconds != 10")], {"simSeconds": 10.001})
    assert result.passed


def test_absent_and_unknown_metrics_fail_with_a_message() -> None:
    absent, unknown = evaluate(
        [crit("minTimeToCollision >= 1.5"), crit("minDistanse >= 2")], {"minDistance": 3.0}
    )
    assert not absent.passed and absent.actual is None
    assert "'minTimeToCollision' was not measured in this run" in absent.message
    assert "never closed in" in absent.message
    assert not unknown.passed and unknown.actual is None
    assert "unknown metric 'minDistanse'" in unknown.message
    assert "minDistance" in unknown.message


def test_nan_metric_fails() -> None:
    (result,) = evaluate([crit("minDistance != 2")], {"minDistance": math.nan})
    assert not result.passed and "NaN" in result.message


def test_optional_criterion_and_verdict() -> None:
    optional = CriterionModel(
        metric="minTimeHeadway", operator=">=", value=1.0, optional=True, name="keeps distance"
    )
    results = evaluate([crit("collision == 0"), optional], {"collision": 0.0, "minTimeHeadway": 0.4})
    assert results[1] == CriterionResult(
        name="keeps distance",
        metric="minTimeHeadway",
        expected=">= 1",
        actual=0.4,
        passed=False,
        optional=True,
        message="minTimeHeadway = 0.4 s: >= 1 s does not hold",
    )
    assert verdict(results, None) == "passed"
    assert verdict(results, "simulator crashed") == "error"
    assert verdict([], None) == "passed"
    required_failed = evaluate([crit("collision == 0")], {"collision": 1.0})
    assert verdict(required_failed, None) == "failed"
    assert verdict(required_failed, "boom") == "error"


# --------------------------------------------------------------------------------------------- reports


def summary(
    index: int,
    scenario: str,
    metrics: dict[str, float],
    criteria: list[str],
    *,
    optional: bool = False,
    error: str | None = None,
    parameters: dict[str, Any] | None = None,
) -> dict[str, Any]:
    results = evaluate([crit(c) for c in criteria], metrics)
    return index_summary(
        index=index,
        scenario=scenario,
        parameters=parameters if parameters is not None else {"speed": 30, "gap": 15.0},
        seed=7 + index,
        optional=optional,
        sim_seconds=metrics.get("simSeconds", 0.0),
        wall_seconds=1.25,
        metrics=metrics,
        results=results,
        error=error,
        end_reason="error" if error else "stopTrigger",
    )


def test_index_summary_fields() -> None:
    s = summary(3, "cut-in", {"minDistance": 1.5, "simSeconds": 12.0}, ["minDistance >= 2"])
    assert list(s) == [
        "index",
        "scenario",
        "parameters",
        "seed",
        "status",
        "optional",
        "simSeconds",
        "wallSeconds",
        "metrics",
        "criteria",
        "error",
        "endReason",
        "attempts",
    ]
    assert s["status"] == "failed"
    assert s["criteria"][0] == {
        "name": "minDistance >= 2",
        "metric": "minDistance",
        "expected": ">= 2",
        "actual": 1.5,
        "passed": False,
        "optional": False,
        "message": "minDistance = 1.5 m: >= 2 m does not hold",
    }
    assert json.loads(json.dumps(s)) == s
    with pytest.raises(ValueError, match="needs the error message"):
        index_summary(
            index=0,
            scenario="x",
            parameters={},
            seed=0,
            optional=False,
            sim_seconds=0,
            wall_seconds=0,
            metrics={},
            results=[],
            error=None,
            end_reason="error",
        )
    with pytest.raises(ValueError, match="finite"):
        summary(0, "x", {"minDistance": math.inf}, [])


def mixed_run(required_fails: bool) -> list[dict[str, Any]]:
    return [
        summary(0, "cut-in", {"minDistance": 3.0, "collision": 0.0}, ["collision == 0", "minDistance >= 2"]),
        summary(
            1,
            "cut-in",
            {"minDistance": 1.0 if required_fails else 2.5, "collision": 0.0},
            ["collision == 0", "minDistance >= 2"],
            parameters={"speed": 30, "gap": 5.0},
        ),
        summary(2, "pedestrian", {"collision": 1.0}, ["collision == 0"], optional=True, parameters={}),
        summary(3, "pedestrian", {}, [], optional=True, error="SUMO died <&> \x1b[31m", parameters={}),
    ]


def test_optional_scenario_failing_does_not_fail_the_run() -> None:
    run = run_summary("nightly", mixed_run(required_fails=False), total=4)
    assert run["status"] == "passed"
    assert run["exitCode"] == 0
    assert run["counts"] == {
        "total": 4,
        "passed": 2,
        "failed": 0,
        "errors": 0,
        "optionalFailed": 2,
        "missing": 0,
    }
    assert run["scenarios"]["pedestrian"]["optional"] is True
    assert run["scenarios"]["pedestrian"]["counts"]["optionalFailed"] == 2
    assert run["scenarios"]["cut-in"]["metrics"]["minDistance"] == {
        "min": 2.5,
        "mean": 2.75,
        "max": 3.0,
        "count": 2,
    }
    assert run["scenarios"]["pedestrian"]["metrics"]["collision"]["count"] == 1
    json.dumps(run)

    root = ET.fromstring(junit_xml("nightly", mixed_run(required_fails=False)))
    assert root.tag == "testsuites"
    assert {k: root.get(k) for k in ("tests", "failures", "errors", "skipped")} == {
        "tests": "4",
        "failures": "0",
        "errors": "0",
        "skipped": "2",
    }
    suites = {s.get("name"): s for s in root.findall("testsuite")}
    assert [s.get("name") for s in root.findall("testsuite")] == ["cut-in", "pedestrian"]
    assert (suites["pedestrian"].get("tests"), suites["pedestrian"].get("skipped")) == ("2", "2")
    assert (suites["cut-in"].get("tests"), suites["cut-in"].get("skipped")) == ("2", "0")
    cases = suites["pedestrian"].findall("testcase")
    assert cases[0].get("name") == "pedestrian[2]"
    skipped = cases[0].find("skipped")
    assert skipped is not None
    assert skipped.get("message") == "optional: collision == 0: expected == 0, actual 1"
    skipped = cases[1].find("skipped")
    assert skipped is not None
    assert skipped.get("message") == "optional: SUMO died <&> \ufffd[31m"
    assert cases[1].find("error") is None and cases[1].find("failure") is None


def test_required_failure_gives_exit_code_1() -> None:
    summaries = mixed_run(required_fails=True)
    run = run_summary("nightly", summaries, total=4)
    assert run["status"] == "failed"
    assert run["exitCode"] == 1
    assert run["counts"]["failed"] == 1 and run["counts"]["passed"] == 1

    root = ET.fromstring(junit_xml("nightly", summaries))
    assert {k: root.get(k) for k in ("tests", "failures", "errors", "skipped")} == {
        "tests": "4",
        "failures": "1",
        "errors": "0",
        "skipped": "2",
    }
    suite = root.find("testsuite[@name='cut-in']")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors"), suite.get("skipped")) == (
        "2",
        "1",
        "0",
        "0",
    )
    assert suite.get("time") == "2.500"
    case = suite.findall("testcase")[1]
    assert case.get("name") == "cut-in[1] speed=30,gap=5"
    assert case.get("classname") == "carlos.nightly.cut-in"
    assert case.get("time") == "1.250"
    failure = case.find("failure")
    assert failure is not None
    assert failure.get("message") == "minDistance >= 2: expected >= 2, actual 1"
    properties = {p.get("name"): p.get("value") for p in case.iter("property")}
    assert properties == {
        "param.speed": "30",
        "param.gap": "5",
        "seed": "8",
        "attempts": "1",
        "endReason": "stopTrigger",
    }


def test_a_bad_input_error_gives_exit_code_2_apart_from_infrastructure() -> None:
    passed = summary(0, "cut-in", {"collision": 0.0}, ["collision == 0"])
    bad = {**summary(1, "cut-in", {}, [], error="no lane id=-9"), "badInput": True}
    crashed = summary(2, "cut-in", {}, [], error="libsumo: connection closed")
    assert run_summary("r", [passed, bad], total=2)["exitCode"] == 2
    assert run_summary("r", [passed, bad, crashed], total=3)["exitCode"] == 2  # a retry cannot fix it
    assert run_summary("r", [passed, crashed], total=3)["exitCode"] == 3
    failed = summary(3, "cut-in", {"collision": 1.0}, ["collision == 0"])
    assert run_summary("r", [passed, bad, crashed, failed], total=4)["exitCode"] == 1
    optional_bad = {**summary(1, "o", {}, [], error="no lane", optional=True), "badInput": True}
    assert run_summary("r", [passed, optional_bad], total=2)["exitCode"] == 0


def test_required_error_and_missing_give_exit_code_3() -> None:
    summaries = [
        summary(0, "cut-in", {"collision": 0.0}, ["collision == 0"]),
        summary(1, "cut-in", {}, [], error="libsumo: connection closed"),
    ]
    run = run_summary("r", summaries, total=2)
    assert (run["status"], run["exitCode"], run["counts"]["errors"]) == ("failed", 3, 1)
    root = ET.fromstring(junit_xml("r", summaries))
    assert (root.get("errors"), root.get("failures"), root.get("skipped")) == ("1", "0", "0")
    error = root.find("testsuite/testcase/error")
    assert error is not None and error.get("message") == "libsumo: connection closed"

    missing = run_summary("r", summaries[:1], total=2)
    assert (missing["status"], missing["exitCode"], missing["counts"]["missing"]) == ("failed", 3, 1)

    # A test failure wins over an error: a retry would not fix it.
    failed = summary(2, "cut-in", {"collision": 1.0}, ["collision == 0"])
    assert run_summary("r", [*summaries, failed], total=3)["exitCode"] == 1

    assert run_summary("r", [], total=0) == {
        "run": "r",
        "status": "passed",
        "exitCode": 0,
        "counts": {"total": 0, "passed": 0, "failed": 0, "errors": 0, "optionalFailed": 0, "missing": 0},
        "scenarios": {},
    }


def test_run_summary_rejects_bad_indexes() -> None:
    s = summary(0, "a", {}, [])
    with pytest.raises(ValueError, match="two summaries"):
        run_summary("r", [s, s], total=2)
    with pytest.raises(ValueError, match="outside"):
        run_summary("r", [s], total=0)


def test_testcase_names_and_escaping() -> None:
    s = summary(
        3,
        "cut-in",
        {},
        [],
        parameters={"speed": 30, "gap": 15, "flag": True, "ratio": 0.1 + 0.2, "s": 'a"<b'},
    )
    assert case_name(s) == 'cut-in[3] speed=30,gap=15,flag=true,ratio=0.30000000000000004,s=a"<b'
    xml = junit_xml('run&"x"', [s])
    root = ET.fromstring(xml)
    assert root.get("name") == 'run&"x"'
    case = root.find("testsuite/testcase")
    assert case is not None and case.get("name") == case_name(s)
    assert xml.startswith('<?xml version="1.0" encoding="UTF-8"?>')


poses = st.tuples(coords, coords, st.floats(-math.pi, math.pi))


@settings(max_examples=300, deadline=None)
@given(poses, poses, st.floats(0.2, 40.0), st.floats(-40.0, 40.0))
def test_accumulator_agrees_with_corner_geometry(
    ego_pose: tuple[float, float, float], other_pose: tuple[float, float, float], v_ego: float, v_other: float
) -> None:
    """One frame: the accumulator's distance, collision, headway and TTC against the same quantities
    computed directly from `corners()` in the ego's frame."""
    ego = car("ego", *ego_pose[:2], heading=ego_pose[2], speed=v_ego)
    other = car("other", *other_pose[:2], heading=other_pose[2], speed=v_other, length=3.0, width=2.5)
    acc = MetricsAccumulator()
    acc.update(frame(0.0, ego, other))
    m = acc.result()
    a, b = Box.of(ego), Box.of(other)
    assert m["minDistance"] == box_distance(a, b)
    assert m["collision"] == (1.0 if boxes_overlap(a, b) else 0.0)

    fx, fy = math.cos(ego.heading), math.sin(ego.heading)
    ex, ey, _ = ego.box_center()
    ox, oy, _ = other.box_center()
    lon = (ox - ex) * fx + (oy - ey) * fy
    lat = -(ox - ex) * fy + (oy - ey) * fx
    along = [x * fx + y * fy for x, y in b.corners]
    ego_along = [x * fx + y * fy for x, y in a.corners]
    if lon > 0 and abs(lat) <= 1.75:
        gap = max(min(along) - max(ego_along), 0.0)
        assert m["minTimeHeadway"] == pytest.approx(gap / v_ego, abs=1e-9)
        closing = v_ego - v_other * math.cos(other.heading - ego.heading)
        if closing > 0.02:
            assert m["minTimeToCollision"] == pytest.approx(gap / closing, rel=1e-9, abs=1e-9)
        elif closing < 0.005:
            assert "minTimeToCollision" not in m
    else:
        assert "minTimeHeadway" not in m and "minTimeToCollision" not in m


JUNIT_STREAM = [
    {
        "index": 3,
        "scenario": "b",
        "status": "passed",
        "parameters": {"v": 2.5},
        "seed": 3,
        "wallSeconds": 0.25,
    },
    {
        "index": 0,
        "scenario": "a & <a>",
        "status": "error",
        "error": "boom <x>",
        "seed": 0,
        "attempts": 2,
        "wallSeconds": 1.0,
    },
    {
        "index": 2,
        "scenario": "b",
        "status": "failed",
        "optional": True,
        "criteria": [],
        "seed": 2,
        "wallSeconds": 0.5,
    },
    {"index": 1, "scenario": "b", "status": "passed", "seed": 1, "flaky": True, "wallSeconds": 0.125},
]
JUNIT_EXPECTED = """<?xml version="1.0" encoding="UTF-8"?>
<testsuites name="r" tests="4" failures="0" errors="1" skipped="1" time="1.875">
  <testsuite name="b" tests="3" failures="0" errors="0" skipped="1" time="0.875">
    <testcase name="b[1]" classname="carlos.r.b" time="0.125">
      <properties>
        <property name="seed" value="1" />
        <property name="flaky" value="true" />
      </properties>
    </testcase>
    <testcase name="b[2]" classname="carlos.r.b" time="0.500">
      <properties>
        <property name="seed" value="2" />
      </properties>
      <skipped message="optional: failed">failed without a failed required criterion</skipped>
    </testcase>
    <testcase name="b[3] v=2.5" classname="carlos.r.b" time="0.250">
      <properties>
        <property name="param.v" value="2.5" />
        <property name="seed" value="3" />
      </properties>
    </testcase>
  </testsuite>
  <testsuite name="a &amp; &lt;a&gt;" tests="1" failures="0" errors="1" skipped="0" time="1.000">
    <testcase name="a &amp; &lt;a&gt;[0]" classname="carlos.r.a &amp; &lt;a&gt;" time="1.000">
      <properties>
        <property name="seed" value="0" />
        <property name="attempts" value="2" />
      </properties>
      <error message="boom &lt;x&gt;" type="SimulationError">boom &lt;x&gt;</error>
    </testcase>
  </testsuite>
</testsuites>
"""


def test_junit_is_written_from_a_stream_in_suite_and_index_order_with_the_document_layout() -> None:
    """Summaries arrive one at a time in any order (a generator: never a list); the document is the same
    bytes as a whole tree indented would be: suites by first appearance, cases by index, counts and times."""
    import io

    from simcore.evaluation.report import write_junit_xml

    out = io.BytesIO()
    write_junit_xml("r", (dict(s) for s in JUNIT_STREAM), out)
    assert out.getvalue().decode() == JUNIT_EXPECTED
    assert junit_xml("r", iter(JUNIT_STREAM)) == JUNIT_EXPECTED
    empty = junit_xml("r", iter(()))
    assert empty.endswith(
        '<testsuites name="r" tests="0" failures="0" errors="0" skipped="0" time="0.000" />\n'
    )


@given(
    coords,
    coords,
    st.floats(-10.0, 10.0),
    st.floats(-3.0, 3.0),
    st.floats(-1.0, 1.0),
    st.floats(0.0, 20.0),
    st.floats(0.0, 4.0),
)
def test_a_footprint_has_the_very_corners_of_the_state(
    x: float, y: float, heading: float, center_x: float, center_y: float, length: float, width: float
) -> None:
    """The metrics' footprint and the states' corners are the same floats (one arithmetic,
    `state.corner_coordinates`), so that the metrics, the conditions and the published states agree to the
    bit."""
    from simcore.world.state import box_corners

    box = footprint(x, y, heading, center_x, center_y, length, width)
    assert box.corners == box_corners(x, y, heading, center_x, center_y, length, width)
    assert box.axes == ((math.cos(heading), math.sin(heading)), (-math.sin(heading), math.cos(heading)))


def test_a_footprint_is_the_state_s_corners_and_axes_as_an_immutable_value() -> None:
    import copy
    import pickle

    from simcore.world.state import box_corners

    box = footprint(3.0, -2.0, 0.4, 1.4, 0.2, 4.5, 1.8)
    c, s = math.cos(0.4), math.sin(0.4)
    assert box.corners == box_corners(3.0, -2.0, 0.4, 1.4, 0.2, 4.5, 1.8)
    assert box.axes == ((c, s), (-s, c))
    assert Box.of_points(box.corners, box.axes) == box and hash(Box.of_points(box.corners, box.axes)) == hash(
        box
    )
    assert pickle.loads(pickle.dumps(box)) == box and copy.copy(box) == box
    assert box != footprint(3.0, -2.0, 0.4, 1.4, 0.2, 4.5, 1.9)
    assert repr(box) == f"Box(corners={box.corners!r}, axes={box.axes!r})"
    with pytest.raises(AttributeError):
        box.x0 = 1.0  # type: ignore[misc]
    with pytest.raises(AttributeError):
        del box.fy  # type: ignore[misc]
