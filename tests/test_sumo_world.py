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


def _rewrite_keeping_size_and_times(path: Path, data: bytes) -> None:
    """`data` written over `path` (as long as its content), its modification time kept."""
    import os

    before = path.stat()
    assert len(data) == before.st_size
    path.write_bytes(data)
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))


def test_a_road_file_is_known_by_its_content(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A warm worker checks a `.net.xml` once per content; a changed file, even one of the same size and
    modification time, is checked again, and a changed OpenDRIVE file gets the network its content names."""
    from simcore.errors import BadInput
    from simcore.world import sumo

    calls = {"check": 0}
    plain_check = sumo.check_network_xml

    def counted_check(path: Path) -> None:
        calls["check"] += 1
        plain_check(path)

    monkeypatch.setattr(sumo, "check_network_xml", counted_check)
    cache = tmp_path / "cache"
    cache.mkdir()
    road = tmp_path / "road.xodr"
    text = (ROOT / "examples" / "maps" / "highway.xodr").read_bytes()
    road.write_bytes(text)
    (cache / sumo._network_name(road, text)).write_text("<net/>")  # already converted: no netconvert here
    first = sumo.prepare_network(road, cache)
    assert sumo.prepare_network(road, cache) == first == cache / sumo._network_name(road, text)
    changed = text.replace(b"<header", b"<HEADER", 1)
    _rewrite_keeping_size_and_times(road, changed)
    (cache / sumo._network_name(road, changed)).write_text("<net/>")
    assert sumo.prepare_network(road, cache) == cache / sumo._network_name(road, changed) != first

    net = tmp_path / "road.net.xml"
    net.write_text("<net/>")
    assert sumo.prepare_network(net) == sumo.prepare_network(net) == net
    assert calls["check"] == 1
    _rewrite_keeping_size_and_times(net, b"<nat/>")  # another content, and no network
    with pytest.raises(BadInput, match="expected <net>"):
        sumo.prepare_network(net)
    assert calls["check"] == 2


def test_runs_on_one_network_file_share_its_lanes_and_only_its_lanes(tmp_path: Path) -> None:
    """A run looks up the lanes of an edge once for every later run on the same network file content; a
    network file changed in between starts from nothing."""
    pytest.importorskip("libsumo")
    from simcore.world.sumo import SumoWorld, netconvert_available, prepare_network
    from simcore.world.sumo_lanes import edge_lanes

    if not netconvert_available():
        pytest.skip("netconvert is not installed")
    network = tmp_path / "highway.net.xml"
    network.write_bytes(
        prepare_network(ROOT / "examples" / "maps" / "highway.xodr", cache_dir=tmp_path).read_bytes()
    )
    with SumoWorld(network, 0.05, seed=1) as world:
        lanes = world._sumo.lane.getIDList()
        first = {lane: world._edge_lanes(lane) for lane in lanes if not lane.startswith(":")}
        assert first and all(edge is not None for edge in first.values())
    with SumoWorld(network, 0.05, seed=1) as world:
        for lane, edge in first.items():
            assert world._edge_of_lane[lane] is edge  # shared, not looked up again
            assert edge is not None
            raw = tuple(
                (lid, world._sumo.lane.getShape(lid), world._sumo.lane.getLength(lid)) for lid in edge.by_id
            )
            assert edge_lanes(raw) is edge  # and it is what this run's SUMO gives
    network.write_bytes(network.read_bytes())  # rewritten as it was: the same content
    with SumoWorld(network, 0.05, seed=1) as world:
        assert world._edge_of_lane and all(world._edge_of_lane[lane] is edge for lane, edge in first.items())
    network.write_bytes(network.read_bytes() + b"\n")  # another content
    with SumoWorld(network, 0.05, seed=1) as world:
        assert world._edge_of_lane == {}
