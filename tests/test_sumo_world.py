"""SumoWorld's per-process shortcuts (simcore/world/sumo.py) leave every run as it is without them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: one process's runs of a SUMO-driven car ("ego") behind a scripted one that changes into its lane: `run(seed,
#: reuse, fail)` gives the SUMO-driven car's speed factor (SUMO's random draw at its insertion; the road's speed
#: limit is above what the car wants here), then its pose after each of 200 steps (`fail`: the run raises
#: half-way); `starts` counts libsumo's starts
_DRIVE = """
import json, sys
from pathlib import Path
import libsumo
import simcore.world.sumo as sumo
from simcore.world.opendrive import OpenDrive

network, road_file = Path(sys.argv[1]), Path(sys.argv[2])
road = OpenDrive.from_file(road_file)
starts = []
plain_start = libsumo.start
libsumo.start = lambda args, **kw: starts.append(1) or plain_start(args, **kw)

def run(seed, reuse, fail):
    trajectory = []
    try:
        with sumo.SumoWorld(network, 0.05, seed=seed, reuse=reuse) as world:
            start = road.road_to_world("1", 100.0, road.lane_center_t("1", -1, 100.0))
            cut = road.road_to_world("1", 130.0, road.lane_center_t("1", -2, 130.0))
            box = {"length": 4.5, "width": 1.8, "height": 1.5, "front_offset": 3.65, "max_speed": 50.0,
                   "max_accel": 4.0, "max_decel": 9.0}
            world.add_vehicle("ego", **box, x=start.x, y=start.y, heading=start.heading, speed=20.0,
                              scripted=False)
            trajectory.append(world._sumo.vehicle.getSpeedFactor("ego"))
            world.add_vehicle("cut", **box, x=cut.x, y=cut.y, heading=cut.heading, speed=15.0, scripted=True)
            s = 130.0
            for step in range(200):
                if fail and step == 100:
                    raise RuntimeError("half-way")
                s += 15.0 * 0.05
                share = min(max((step - 40) / 60, 0.0), 1.0)
                t = (1 - share) * road.lane_center_t("1", -2, s) + share * road.lane_center_t("1", -1, s)
                pose = road.road_to_world("1", s, t)
                world.place("cut", pose.x, pose.y, pose.heading, 15.0)
                world.step()
                trajectory.append(tuple(world.read("ego") or ()))
    except RuntimeError:
        pass
    return trajectory
"""

#: first without the Xerces hold, then twice with it (a warm worker's runs, each starting SUMO: not kept between
#: them); prints the three runs and whether the hold took
_RUNS = (
    _DRIVE
    + """
hold = sumo.keep_xml_parser_initialized
sumo.keep_xml_parser_initialized = lambda library: False
plain = run(3, False, False)
sumo.keep_xml_parser_initialized = hold
held = [run(3, False, False), run(3, False, False)]
from libsumo import _libsumo
print(json.dumps({"held": hold(_libsumo.__file__), "runs": [plain, *held], "starts": len(starts)}))
"""
)


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
    assert result["starts"] == 3  # each run started SUMO (none kept): the hold is what starts and closes use


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


#: the runs `plan` lists (seed, reuse, fail) in one process; prints them and libsumo's starts
_PARKED_RUNS = (
    _DRIVE
    + """
runs = [run(*entry) for entry in json.loads(sys.argv[3])]
print(json.dumps({"runs": runs, "starts": len(starts)}))
"""
)


def test_a_parked_simulation_runs_as_a_fresh_start(tmp_path: Path) -> None:
    """A warm worker's runs on one network, step and seed share one libsumo simulation, parked between them
    (simcore/world/sumo_warm.py): each run's trajectory is the fresh start's, bit for bit, also after a run that
    failed half-way and after a run with another seed; another seed starts SUMO anew."""
    pytest.importorskip("libsumo")
    from simcore.world.sumo import netconvert_available, prepare_network

    if not netconvert_available():
        pytest.skip("netconvert is not installed")
    road_file = ROOT / "examples" / "maps" / "highway.xodr"
    network = prepare_network(road_file, cache_dir=tmp_path)
    plan = [
        (3, False, False),  # fresh, closed
        (3, True, False),  # fresh, parked
        (3, True, False),  # parked
        (3, True, True),  # parked, fails half-way
        (3, True, False),  # parked
        (4, True, False),  # another seed: fresh, parked
        (3, True, False),  # fresh again
        (3, True, False),  # parked
    ]
    out = subprocess.run(
        [sys.executable, "-c", _PARKED_RUNS, str(network), str(road_file), json.dumps(plan)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    result = json.loads(out.stdout.splitlines()[-1])
    fresh, *later = result["runs"]
    assert len(fresh) == 201 and all(fresh)
    assert fresh[-1] != fresh[1]  # it drove
    assert later[:2] == [fresh, fresh]
    assert later[2] == fresh[:101]
    assert later[3] == fresh
    assert later[4][0] != fresh[0] and len(later[4]) == 201  # another seed: another speed factor
    assert later[5:] == [fresh, fresh]
    assert result["starts"] == 4  # the unparked run, the first parked one, seed 4, seed 3 again


def test_the_generator_state_written_for_sumo_is_a_seeded_mt19937() -> None:
    """The state written for SUMO's default generator is `std::mt19937`'s after seeding: continued by Python's
    Mersenne Twister (the same generator), its 10,000th number from the default seed 5489 is the one the C++
    standard requires ([rand.predef]); a saved state's count-only generator is replaced by it, a full one kept;
    what loading a state does nothing with is left out."""
    import random

    from simcore.world.sumo_warm import (
        FULL_STATE_COUNT,
        mt19937_seeded,
        with_default_generator_seeded,
        without_inert_parts,
    )

    *words, position = (int(word) for word in mt19937_seeded(5489).split())
    assert len(words) == 624 and position == 624
    generator = random.Random()
    generator.setstate((3, (*words, position), None))
    numbers = [generator.getrandbits(32) for _ in range(10_000)]
    assert numbers[-1] == 4123659995
    assert mt19937_seeded(-1) == mt19937_seeded(2**32 - 1)  # an int seed as the unsigned 32 bits it is

    saved = '<snapshot><rngState default="16" routeHandler="0">\n<rngLane index="0" state="3"/></rngState>'
    written = with_default_generator_seeded(saved, 7)
    assert written == saved.replace('default="16"', f'default="{FULL_STATE_COUNT + 16} {mt19937_seeded(7)}"')
    assert with_default_generator_seeded(written, 8) == written  # already in full: SUMO's own
    assert with_default_generator_seeded("<snapshot/>", 7) is None
    saved = '<?xml version="1.0"?>\n<!-- options\n  <seed value="7"/>\n-->\n<snapshot>\n  <rngState default="1">\n'
    saved += (
        '    <rngLane index="0" state="0"/>\n    <rngLane index="1" state="5"/>\n  </rngState>\n</snapshot>'
    )
    assert without_inert_parts(saved) == (
        '<?xml version="1.0"?>\n<snapshot>\n  <rngState default="1">\n    <rngLane index="1" state="5"/>\n'
        "  </rngState>\n</snapshot>"
    )


def test_a_state_failing_its_check_is_never_parked(tmp_path: Path) -> None:
    """When the state written for SUMO does not give the speed factors of a fresh start (here: the generator
    seeded with another seed), nothing is parked: every run starts SUMO afresh, and drives as a fresh start."""
    pytest.importorskip("libsumo")
    from simcore.world.sumo import netconvert_available, prepare_network

    if not netconvert_available():
        pytest.skip("netconvert is not installed")
    road_file = ROOT / "examples" / "maps" / "highway.xodr"
    network = prepare_network(road_file, cache_dir=tmp_path)
    wrong_seed = "import simcore.world.sumo_warm as warm\nseeded = warm.mt19937_seeded\n"
    wrong_seed += "warm.mt19937_seeded = lambda seed: seeded(seed + 1)\n"
    plan = [(3, False, False), (3, True, False), (3, True, False), (3, True, False)]
    out = subprocess.run(
        [sys.executable, "-c", wrong_seed + _PARKED_RUNS, str(network), str(road_file), json.dumps(plan)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    result = json.loads(out.stdout.splitlines()[-1])
    fresh, *later = result["runs"]
    assert later == [fresh, fresh, fresh]
    assert result["starts"] == 5  # the first keyed run starts twice (after its failed check), the rest once
