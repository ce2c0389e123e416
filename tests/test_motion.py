"""Road-following motion (simcore.scenario.motion) on hand-written roads."""

from __future__ import annotations

from simcore.scenario import model as m
from simcore.scenario.motion import Body, _plain_side, advance_on_road
from simcore.world.opendrive import OpenDrive


def _lane(lane_id: int, width: str, link: str = "") -> str:
    return f"<lane id='{lane_id}' type='driving'><link>{link}</link><width sOffset='0' {width}/></lane>"


CONST = "a='3.5' b='0' c='0' d='0'"


def _network(sections: str) -> OpenDrive:
    return OpenDrive.from_string(
        "<?xml version='1.0'?><OpenDRIVE><header revMajor='1' revMinor='6'/>"
        "<road id='1' length='200' junction='-1'><link/><planView>"
        "<geometry s='0' x='0' y='0' hdg='0' length='200'><line/></geometry></planView>"
        f"<lanes>{sections}</lanes></road></OpenDRIVE>",
        "motion.xodr",
    )


def _section(s: float, right: str, left: str = "") -> str:
    return (
        f"<laneSection s='{s}'><left>{left}</left><center><lane id='0' type='none'/></center>"
        f"<right>{right}</right></laneSection>"
    )


def _body(road_id: str, lane_id: int, s: float, speed: float) -> Body:
    body = Body(m.Entity("Car", "vehicle", "car", m.Box(1.4, 0.0, 0.75, 4.5, 1.8, 1.5), m.Performance()))
    body.road_id, body.lane_id, body.s, body.speed = road_id, lane_id, s, speed
    return body


def test_a_lane_renumbered_at_a_section_change_is_followed_by_its_link() -> None:
    """Lane -1 of the first section continues as lane -2 of the second (a lane is added inside it)."""
    od = _network(
        _section(0, _lane(-1, CONST, "<successor id='-2'/>"), _lane(1, CONST))
        + _section(100, _lane(-1, CONST) + _lane(-2, CONST, "<predecessor id='-1'/>"), _lane(1, CONST))
    )
    road = od.roads["1"]
    assert not _plain_side(road, -1) and not _plain_side(road, 1)  # two sections on each side
    car = _body("1", -1, 95.0, 10.0)
    advance_on_road(od, car, 10.0, 1.0)
    assert (car.lane_id, car.s) == (-2, 105.0) and car.y == -5.25
    left = _body("1", 1, 95.0, 10.0)
    advance_on_road(od, left, 10.0, 1.0)
    assert (left.lane_id, left.s) == (1, 105.0) and left.y == 1.75


def test_a_side_with_a_lane_narrowing_to_nothing_is_not_plain() -> None:
    narrowing = "a='3.5' b='-0.05' c='0' d='0'/><width sOffset='70' a='0' b='0' c='0' d='0'"
    od = _network(_section(0, _lane(-1, CONST) + _lane(-2, narrowing), _lane(1, CONST)))
    road = od.roads["1"]
    assert not _plain_side(road, -1) and _plain_side(road, 1)
    car = _body("1", -2, 60.0, 10.0)
    advance_on_road(od, car, 20.0, 1.0)
    assert (car.lane_id, car.offset, car.y) == (-1, 0.0, -1.75)  # left for the next inner lane


def test_moving_along_a_road_gives_what_the_per_s_lane_borders_give() -> None:
    """`advance_on_road` and `update_pose_from_road` take the lane centre from the road's lane tables: to
    the bit the poses that the borders summed at each s give (the tables switched off), on a curved road,
    across a lane section change, in a lane change and at the road's end."""
    xodr = (
        "<?xml version='1.0'?><OpenDRIVE><header revMajor='1' revMinor='6'/>"
        "<road id='1' length='200' junction='-1'><link/><planView>"
        "<geometry s='0' x='0' y='0' hdg='0.1' length='80'><line/></geometry>"
        "<geometry s='80' x='79.6' y='7.98' hdg='0.1' length='120'><arc curvature='0.004'/></geometry>"
        "</planView><lanes>"
        + _section(0, _lane(-1, CONST, "<successor id='-1'/>") + _lane(-2, CONST), _lane(1, CONST))
        + _section(100, _lane(-1, CONST, "<predecessor id='-1'/>") + _lane(-2, CONST), _lane(1, CONST))
        + "</lanes></road></OpenDRIVE>"
    )

    def drive(tables: bool) -> list[str]:
        od = OpenDrive.from_string(xodr, "curve.xodr")
        if not tables:
            od.roads["1"]._crosses = [None] * (len(od.roads["1"]._cross_starts) + 1)
        car = _body("1", -1, 3.0, 30.0)
        car.offset, car.lateral_velocity = -0.3, -0.7
        out = []
        for step in range(90):
            advance_on_road(od, car, 30.0 * 0.05 * (1 + step % 3), step * 0.05)
            car.offset -= 0.01
            out.append(repr((car.road_id, car.lane_id, car.s, car.x, car.y, car.z, car.heading, car.speed)))
        return out

    assert drive(True) == drive(False)
