"""Generate the example road networks in `examples/maps/` with scenariogeneration's `xodr` module.

    .venv/bin/python examples/generate.py          # rewrites examples/maps/*.xodr
    .venv/bin/python examples/generate.py --check  # exit 1 if a committed file differs

The output is deterministic: re-running the script reproduces the committed files byte for byte (the
header's `date` attribute, which scenariogeneration sets to the current time, is fixed here).

Roads (right-hand traffic, OpenDRIVE 1.7, lane widths 3.5 m; every driving lane has a `<speed>` record,
because SUMO's netconvert ignores the road type's speed and would otherwise cap every lane at 50 km/h):

* `highway.xodr` — road 1, one-way motorway, 2 km: three driving lanes -1 (left, fast), -2, -3 (right),
  a 2.5 m shoulder (-4) and a 0.5 m border (-5); 130 km/h. Plan view: line 400 m → clothoid 150 m (curvature
  0 → 1/1000) → arc 400 m (R = 1000 m, left) → clothoid 150 m (1/1000 → 0) → line 900 m. The road starts
  at (0, 0) heading along +x.
* `rural.xodr` — road 1, two-way rural road, 1 km: lanes 1 and -1 plus a 0.5 m border on each side; 100 km/h.
  Plan view: line 200 m → clothoid 50 m → arc 150 m (R = 200 m, left) → clothoid 100 m (reversing) →
  arc 150 m (R = 200 m, right) → clothoid 50 m → line 300 m (an S-curve), with a 10 m crest at s = 500 m
  (two cubic elevation pieces, at most 3 % grade).
"""

from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from scenariogeneration import xodr
from scenariogeneration.helpers import prettify

MAPS = Path(__file__).resolve().parent / "maps"
LANE_WIDTH = 3.5
#: Fixed header date so that the output is reproducible.
DATE = "2025-01-01T00:00:00"


def _lane(lane_type: xodr.LaneType, width: float, mark: xodr.RoadMarkType | None) -> xodr.Lane:
    lane = xodr.Lane(lane_type=lane_type, a=width)
    if mark is not None:
        lane.add_roadmark(xodr.RoadMark(mark, width=0.15))
    return lane


def _center(mark: xodr.RoadMarkType) -> xodr.Lane:
    center = xodr.Lane()
    center.add_roadmark(xodr.RoadMark(mark, width=0.15))
    return center


def highway() -> xodr.OpenDrive:
    """One-way three-lane motorway with a shoulder and a R = 1000 m curve between clothoids."""
    plan = xodr.PlanView(0.0, 0.0, 0.0)
    plan.add_geometry(xodr.Line(400.0))
    plan.add_geometry(xodr.Spiral(0.0, 1.0 / 1000.0, length=150.0))
    plan.add_geometry(xodr.Arc(1.0 / 1000.0, length=400.0))
    plan.add_geometry(xodr.Spiral(1.0 / 1000.0, 0.0, length=150.0))
    plan.add_geometry(xodr.Line(900.0))

    # The left edge of the carriageway (center lane) is a solid line; lanes -1/-2 end in broken lines,
    # lane -3 in the solid edge line; the shoulder and border have no marking.
    section = xodr.LaneSection(0.0, _center(xodr.RoadMarkType.solid))
    section.add_right_lane(_lane(xodr.LaneType.driving, LANE_WIDTH, xodr.RoadMarkType.broken))
    section.add_right_lane(_lane(xodr.LaneType.driving, LANE_WIDTH, xodr.RoadMarkType.broken))
    section.add_right_lane(_lane(xodr.LaneType.driving, LANE_WIDTH, xodr.RoadMarkType.solid))
    section.add_right_lane(_lane(xodr.LaneType.shoulder, 2.5, None))
    section.add_right_lane(_lane(xodr.LaneType.border, 0.5, None))
    lanes = xodr.Lanes()
    lanes.add_lanesection(section)

    road = xodr.Road(1, plan, lanes, name="highway")
    road.add_type(xodr.RoadType.motorway, s=0.0, country="DE", speed=130, speed_unit="km/h")
    road.add_elevation(0.0, 0.0, 0.0, 0.0, 0.0)

    odr = xodr.OpenDrive("highway", revMajor="1", revMinor="7")
    odr.add_road(road)
    odr.adjust_roads_and_lanes()
    return odr


def rural() -> xodr.OpenDrive:
    """Two-way rural road, one lane each way, with an S-curve (R = 200 m) and a crest."""
    plan = xodr.PlanView(0.0, 0.0, 0.0)
    plan.add_geometry(xodr.Line(200.0))
    plan.add_geometry(xodr.Spiral(0.0, 1.0 / 200.0, length=50.0))
    plan.add_geometry(xodr.Arc(1.0 / 200.0, length=150.0))
    plan.add_geometry(xodr.Spiral(1.0 / 200.0, -1.0 / 200.0, length=100.0))
    plan.add_geometry(xodr.Arc(-1.0 / 200.0, length=150.0))
    plan.add_geometry(xodr.Spiral(-1.0 / 200.0, 0.0, length=50.0))
    plan.add_geometry(xodr.Line(300.0))

    # A broken center line (overtaking allowed), solid edge lines, a border on each side.
    section = xodr.LaneSection(0.0, _center(xodr.RoadMarkType.broken))
    section.add_left_lane(_lane(xodr.LaneType.driving, LANE_WIDTH, xodr.RoadMarkType.solid))
    section.add_left_lane(_lane(xodr.LaneType.border, 0.5, None))
    section.add_right_lane(_lane(xodr.LaneType.driving, LANE_WIDTH, xodr.RoadMarkType.solid))
    section.add_right_lane(_lane(xodr.LaneType.border, 0.5, None))
    lanes = xodr.Lanes()
    lanes.add_lanesection(section)

    road = xodr.Road(1, plan, lanes, name="rural")
    road.add_type(xodr.RoadType.rural, s=0.0, country="DE", speed=100, speed_unit="km/h")
    # Smooth crest: z rises 0 → 10 m over s = 0…500 and falls back to 0 at s = 1000 (cubic pieces with
    # zero slope at both ends; the steepest grade is 3 % at s = 250 and s = 750).
    road.add_elevation(0.0, 0.0, 0.0, 1.2e-4, -1.6e-7)
    road.add_elevation(500.0, 10.0, 0.0, -1.2e-4, 1.6e-7)

    odr = xodr.OpenDrive("rural", revMajor="1", revMinor="7")
    odr.add_road(road)
    odr.adjust_roads_and_lanes()
    return odr


def _add_lane_speeds(element: ET.Element, kmh: float) -> None:
    """Give every driving lane a `<speed>` record.

    scenariogeneration has no API for lane speeds, and SUMO's netconvert ignores the road type's speed:
    without a lane speed every lane would be limited to netconvert's default of 50 km/h.
    """
    for lane in element.iterfind("road/lanes/laneSection/*/lane"):
        if lane.get("type") == "driving":
            # Schema order: link, width, roadMark, material, speed, access, height, rule.
            assert lane.find("height") is None and lane.find("access") is None
            ET.SubElement(lane, "speed", {"sOffset": "0", "max": f"{kmh:g}", "unit": "km/h"})


def render(odr: xodr.OpenDrive, kmh: float) -> bytes:
    """The OpenDRIVE document as bytes, with lane speed limits and a fixed header date."""
    element = odr.get_element()
    _add_lane_speeds(element, kmh)
    header = element.find("header")
    assert header is not None
    header.set("date", DATE)
    element.insert(0, ET.Comment(f" Generated by examples/generate.py ({odr.name}); do not edit by hand. "))
    text: bytes = prettify(element, encoding="utf-8")
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--check", action="store_true", help="compare with the committed files, write nothing"
    )
    args = parser.parse_args(argv)
    stale = []
    for name, build, kmh in (("highway", highway, 130.0), ("rural", rural, 100.0)):
        path = MAPS / f"{name}.xodr"
        data = render(build(), kmh)
        ET.fromstring(data)  # well-formed
        if args.check:
            if not path.exists() or path.read_bytes() != data:
                stale.append(path)
        else:
            MAPS.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            print(f"wrote {path}")
    for path in stale:
        print(f"{path} is out of date: run examples/generate.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
