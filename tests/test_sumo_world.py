"""SumoWorld's per-process shortcuts (simcore/world/sumo.py) leave every run as it is without them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: one process: a short run of a SUMO-driven car and a scripted one, first without the Xerces hold, then twice
#: with it (a warm worker's runs); prints the three trajectories and whether the hold took
_RUNS = """
import json, sys
from pathlib import Path
import simcore.world.sumo as sumo

network, road_file = Path(sys.argv[1]), Path(sys.argv[2])
from simcore.world.opendrive import OpenDrive
road = OpenDrive.from_file(road_file)

def run():
    trajectory = []
    with sumo.SumoWorld(network, 0.05, seed=3) as world:
        start = road.road_to_world("1", 100.0, road.lane_center_t("1", -1, 100.0))
        cut = road.road_to_world("1", 130.0, road.lane_center_t("1", -2, 130.0))
        box = {"length": 4.5, "width": 1.8, "height": 1.5, "front_offset": 3.65, "max_speed": 50.0,
               "max_accel": 4.0, "max_decel": 9.0}
        world.add_vehicle("ego", **box, x=start.x, y=start.y, heading=start.heading, speed=20.0, scripted=False)
        world.add_vehicle("cut", **box, x=cut.x, y=cut.y, heading=cut.heading, speed=15.0, scripted=True)
        s = 130.0
        for step in range(200):
            s += 15.0 * 0.05
            share = min(max((step - 40) / 60, 0.0), 1.0)
            t = (1 - share) * road.lane_center_t("1", -2, s) + share * road.lane_center_t("1", -1, s)
            pose = road.road_to_world("1", s, t)
            world.place("cut", pose.x, pose.y, pose.heading, 15.0)
            world.step()
            trajectory.append(tuple(world.read("ego") or ()))
    return trajectory

hold = sumo.keep_xml_parser_initialized
sumo.keep_xml_parser_initialized = lambda library: False
plain = run()
sumo.keep_xml_parser_initialized = hold
held = [run(), run()]
from libsumo import _libsumo
print(json.dumps({"held": hold(_libsumo.__file__), "runs": [plain, *held]}))
"""


def test_runs_with_the_xml_parser_kept_initialised_are_the_runs_without(tmp_path: Path) -> None:
    """libsumo starts and closes Xerces at every run unless CARLOS holds it initialised for the process: the
    SUMO-driven car's trajectory is the same, bit for bit, without the hold and in two runs with it."""
    pytest.importorskip("libsumo")
    from simcore.world.sumo import netconvert_available, prepare_network

    if not netconvert_available():
        pytest.skip("netconvert is not installed")
    road_file = ROOT / "examples" / "maps" / "highway.xodr"
    network = prepare_network(road_file, cache_dir=tmp_path)
    out = subprocess.run(
        [sys.executable, "-c", _RUNS, str(network), str(road_file)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    result = json.loads(out.stdout.splitlines()[-1])
    plain, *held = result["runs"]
    assert result["held"] is True  # the hold was taken (this libsumo has Xerces 3.2)
    assert all(state for state in plain)
    assert held == [plain, plain]
