"""esmini's lane-independent path planner (the FollowRouteController's) and the lane-by-lane route planning
of AssignRouteAction, on roads of the differential corpus (their trajectories against esmini's are checked by
tests/test_differential_corpus.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from simcore.scenario import paths
from simcore.scenario.controllers.follow_route import connected_lane
from simcore.scenario.controllers.lane_router import RoadPoint, calculate_path, waypoints
from simcore.world.opendrive import OpenDrive

ROADS = Path(__file__).resolve().parent / "differential_corpus" / "roads"


@pytest.fixture(scope="module")
def crossings() -> OpenDrive:
    return OpenDrive.from_file(ROADS / "multi_intersections.xodr")


@pytest.fixture(scope="module")
def motorway() -> OpenDrive:
    return OpenDrive.from_file(ROADS / "SampleDatabase.xodr")


def test_the_path_turns_from_the_lane_that_leads_there(crossings: OpenDrive) -> None:
    # road 202 toward s=0: the left turn to road 196 is from lane 1 (a turn lane), so the waypoint on 202 is
    # in lane 1, at the entity (its s is within the lane's stretch)
    start, target = RoadPoint("202", 2, 100.0, -1), RoadPoint("196", -1, 60.0)
    path = calculate_path(crossings, start, target)
    assert path[0].road == "202" and path[-1].road == "196" and path[-1].lane == -1
    points = waypoints(crossings, path, start, target)
    assert points[0] == RoadPoint("202", 1, 100.0, -1)
    assert points[-1] == target


def test_a_target_lane_reached_only_by_a_lane_change_on_its_road_sends_the_path_round(
    crossings: OpenDrive,
) -> None:
    # road 209's lane -1 far end: from 202 the right turn lands in lane -2; esmini's planner goes on round the
    # network to come back in lane -1
    path = calculate_path(crossings, RoadPoint("202", 2, 100.0, -1), RoadPoint("209", -1, 100.0))
    roads = [n.road for n in path]
    assert roads.count("209") == 2 and len(roads) > 6


def test_no_path_to_a_lane_coming_from_a_dead_end(crossings: OpenDrive) -> None:
    assert calculate_path(crossings, RoadPoint("202", 2, 100.0, -1), RoadPoint("242", 1, 50.0)) == []


def test_ties_go_to_the_smallest_lane_difference(motorway: OpenDrive) -> None:
    # to the exit ramp (road 145) from the motorway's road 174: every lane enters road 142 at the same cost;
    # esmini's tie-break keeps the lane nearest the start's, so the motorway waypoint is lane 2
    start = RoadPoint("174", 3, 300.0, -1)
    path = calculate_path(motorway, start, RoadPoint("145", -1, 100.0))
    assert [n.road for n in path] == ["174", "142", "144", "145"]
    assert waypoints(motorway, path, start, RoadPoint("145", -1, 100.0))[0].lane_id == 2


def test_routes_are_planned_in_the_lane_of_their_start(motorway: OpenDrive) -> None:
    # the split of junction 4: road 157's lane -1 leads to road 155, lanes -2/-3 to road 156
    assert paths.plan_in_lane(motorway, ("157", 1), -1, "155", 130.0) is not None
    assert paths.plan_in_lane(motorway, ("157", 1), -2, "155", 130.0) is None
    assert paths.plan_in_lane(motorway, ("157", 1), -2, "156", 130.0) is not None


def test_a_lane_is_followed_through_lane_sections(motorway: OpenDrive) -> None:
    assert connected_lane(motorway, "157", -1, 10.0, 190.0) != 0
