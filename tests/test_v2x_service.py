"""V2XService on hand-made frames: RSU ground truth from a fixed pose, per-receiver topics, link records,
line-of-sight blocking, seeded determinism; and `carlos run` of the cooperative-perception example."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from simcore.errors import BadInput
from simcore.spec import SimulationRunSpec
from simcore.transport.bus import InProcessBus, Message
from simcore.v2x.service import V2XService
from simcore.world.state import BoundingBox, EntityState, WorldFrame

CAR = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
TRUCK = BoundingBox(5.0, 0.0, 1.9, 12.0, 2.55, 3.8)
PERSON = BoundingBox(0.0, 0.0, 0.9, 0.6, 0.6, 1.8)
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _entity(
    name: str, x: float, y: float = 0.0, *, box: BoundingBox = CAR, speed: float = 0.0, **kw: Any
) -> EntityState:
    kind = "pedestrian" if box is PERSON else "vehicle"
    category = {id(CAR): "car", id(TRUCK): "truck", id(PERSON): "pedestrian"}[id(box)]
    return EntityState(
        name, kind, category, x, y, 0.0, 0.0, 0.0, 0.0, speed, kw.get("acceleration", 0.0), 0.0, box
    )


def _spec(**v2x: Any) -> dict[str, Any]:
    return {
        "scenarios": [{"name": "s", "openscenario": "x.xosc"}],
        "simulation": {"stepSeconds": 0.1},
        "v2x": v2x,
    }


def _service(spec: dict[str, Any], seed: int = 0) -> tuple[V2XService, list[Message]]:
    bus = InProcessBus()
    got: list[Message] = []
    bus.subscribe("*", got.append)
    service = V2XService(
        SimulationRunSpec.model_validate(spec),
        bus,
        road=None,
        road_file=None,
        parameters={"MastS": 100.0},
        seed=seed,
    )
    return service, got


def _perceived(cpm: Any) -> list[Any]:
    """The perceived objects of an etsi_its_cpm_ts_msgs CPM."""
    for container in cpm.payload.cpm_containers.value.array:
        if container.container_id.value == 5:
            return list(container.container_data_perceived_object_container.perceived_objects.array)
    return []


def _frame(step: int, *entities: EntityState, ego: str | None = "Ego") -> WorldFrame:
    return WorldFrame(step=step, time=round(step * 0.1, 6), entities=tuple(entities), ego=ego)


def test_rsu_perceives_ground_truth_from_its_fixed_pose_in_line_of_sight():
    # a lossless channel, so the ego receives everything the mast sends
    spec = _spec(
        stations=[{"entity": "Ego", "cam": False}], channel={"shadowingSigmaDb": 0, "lineOfSight": False}
    )
    spec["infrastructure"] = [
        {
            "name": "mast",
            "position": {"x": "$MastS", "y": 0.0},
            "height": 1.0,
            "v2x": {"cam": False, "perceptionRange": 80},
        }
    ]
    service, got = _service(spec)
    frame = _frame(
        0,
        _entity("Ego", 30.0),  # hidden by the truck too
        _entity("Truck", 85.0, box=TRUCK),  # box from x = 84 to 96, 3.8 m high: hides Hidden from a 1 m mast
        _entity("Hidden", 75.0),
        _entity("Walker", 100.0, 20.0, box=PERSON),
        _entity("Far", 300.0),
    )
    service.step(frame)
    cpms = [m for m in got if m.topic == "/carlos/Ego/v2x/cpm"]
    assert len(cpms) == 1
    objects = _perceived(cpms[0].obj())
    truck_x = 85.0 + 5.0
    by_x = sorted((o.position.x_coordinate.value.value, o.position.y_coordinate.value.value) for o in objects)
    # the origin's map frame is east/north: x east, y north from the mast
    assert by_x == sorted([(round((truck_x - 100.0) * 100), 0), (0, 2000)])
    assert cpms[0].obj().header.station_id.value == 1001
    assert cpms[0].obj().payload.cpm_containers.value.array[0].container_id.value == 2  # originating RSU
    dims = {
        o.classification.array[0].object_class.choice: (
            o.object_dimension_x.value.value,
            o.object_dimension_y.value.value,
            o.object_dimension_z.value.value,
        )
        for o in objects
    }
    assert dims[0] == (120, 26, 38)  # the truck: a vehicle class


def test_receivers_get_other_stations_messages_and_every_link_is_recorded():
    service, got = _service(_spec(channel={"shadowingSigmaDb": 0, "lineOfSight": False}))
    a = _entity("Ego", 0.0, speed=10.0)
    b = _entity("Near", 50.0, speed=10.0)
    c = _entity("Far", 5000.0, speed=10.0)
    service.step(_frame(0, a, b, c))
    topics = sorted({m.topic for m in got})
    assert topics == ["/carlos/Ego/v2x/cam", "/carlos/Near/v2x/cam", "/carlos/v2x/transmissions"]
    cams = [m.obj() for m in got if m.topic == "/carlos/Ego/v2x/cam"]
    assert [c.header.station_id.value for c in cams] == [2]  # Near's; Far (5 km) is out of range
    assert all(m.time_s == pytest.approx(0.0 + 0.002, abs=0.0011) for m in got if m.topic.endswith("/cam"))
    sent = next(m for m in got if m.topic == "/carlos/v2x/transmissions").obj().transmissions
    links = [(t.sender, r, int(o)) for t in sent for r, o in zip(t.receivers, t.outcomes, strict=True)]
    assert len(links) == 6  # 3 CAMs × 2 other stations
    far = [link for link in links if "Far" in link[:2]]
    assert all(outcome == 1 for *_, outcome in far) and len(far) == 4
    metrics = service.metrics()
    assert metrics["v2x.messages.cam"] == 3
    assert metrics["v2x.packetDeliveryRatio"] == pytest.approx(2 / 6)
    assert metrics["v2x.packetDeliveryRatio.0-100m"] == 1.0


def test_a_truck_between_two_cars_costs_the_nlos_loss():
    channel = {"shadowingSigmaDb": 0, "nlosLossDb": 40, "jitterSeconds": 0}
    for line_of_sight, delivered in ((False, True), (True, False)):
        service, got = _service(_spec(channel={**channel, "lineOfSight": line_of_sight}))
        service.step(
            _frame(0, _entity("Ego", 0.0), _entity("Truck", 20.0, box=TRUCK), _entity("Other", 60.0))
        )
        sent = next(m for m in got if m.topic == "/carlos/v2x/transmissions").obj().transmissions
        other = next(t for t in sent if t.sender == "Other")
        assert bool(other.outcomes[list(other.receivers).index("Ego")] == 0) == delivered


def test_hazard_denm_reaches_the_ego_and_the_warning_time_is_measured():
    service, got = _service(_spec(channel={"shadowingSigmaDb": 0}))
    for step in range(6):
        braking = step >= 2
        lead = _entity("Lead", 80.0, speed=10.0, acceleration=-6.0 if braking else 0.0)
        service.step(_frame(step, _entity("Ego", 0.0, speed=10.0), lead))
    denms = [m.obj() for m in got if m.topic == "/carlos/Ego/v2x/denm"]
    assert denms and denms[0].denm.situation.event_type.cause_code.value == 99
    assert denms[0].denm.management.action_id.sequence_number.value == 1
    metrics = service.metrics()
    assert metrics["v2x.hazards"] == 1 and metrics["v2x.hazardsMissed"] == 0
    assert metrics["v2x.hazardToFirstDenm"] == pytest.approx(0.002, abs=0.0011)  # latency + jitter


def test_same_seed_same_outcomes():
    def run(seed: int) -> list[tuple[str, str, int]]:
        service, got = _service(_spec(channel={"shadowingSigmaDb": 8, "fadingM": 1.0}), seed=seed)
        for step in range(20):
            service.step(
                _frame(step, *(_entity(f"V{i}", 60.0 * i + step, speed=10.0) for i in range(6)), ego="V0")
            )
        return [
            (t.sender, r, int(o))
            for m in got
            if m.topic == "/carlos/v2x/transmissions"
            for t in m.obj().transmissions
            for r, o in zip(t.receivers, t.outcomes, strict=True)
        ]

    assert run(5) == run(5)
    assert run(5) != run(6)


def test_parameters_and_stations_are_checked():
    spec = _spec(channel={"txPowerDbm": "$Missing"})
    with pytest.raises(BadInput, match=r"\$Missing names no parameter"):
        _service(spec)
    service, _ = _service(_spec(stations=[{"entity": "Nobody"}]))
    with pytest.raises(BadInput, match="no entity 'Nobody'"):
        service.step(_frame(0, _entity("Ego", 0.0)))
    with pytest.raises(ValueError, match="V2X is off"):
        SimulationRunSpec.model_validate(
            {
                **_spec(),
                "v2x": None,
                "infrastructure": [{"name": "m", "position": {"x": 0, "y": 0}, "v2x": {}}],
            }
        )


def test_carlos_run_records_v2x_topics_and_metrics(tmp_path: Path):
    carlos = Path(sys.executable).parent / "carlos"
    if not carlos.exists():
        pytest.skip(f"the carlos CLI is not installed next to {sys.executable}")
    manifest = yaml.safe_load((EXAMPLES / "runs" / "cooperative-perception.yaml").read_text())
    manifest["spec"]["scenarios"][0]["openscenario"] = str(EXAMPLES / "scenarios" / "hidden-hazard.xosc")
    manifest["spec"]["sweep"]["matrix"] = {"RsuS": [400.0], "PathLossExponent": [2.7]}
    manifest["spec"]["simulation"]["maxSeconds"] = 12
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(manifest))
    result = subprocess.run(
        [str(carlos), "run", "-q", str(path), "--output", f"file://{tmp_path}/out"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    index = tmp_path / "out" / "cooperative-perception" / "0"
    metrics = json.loads((index / "summary.json").read_text())["metrics"]
    assert (
        metrics["v2x.messages.cam"] > 0
        and metrics["v2x.messages.cpm"] > 0
        and metrics["v2x.messages.denm"] > 0
    )
    assert metrics["v2x.packetDeliveryRatio.0-100m"] >= 0.9
    assert 0.0 < metrics["v2x.cpmObjectCoverage"] <= 1.0
    schemas = {}
    with (index / "recording.mcap").open("rb") as f:
        for schema, channel, _, _ in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            schemas[channel.topic] = schema.name
    assert schemas["/carlos/Ego/v2x/cam"] == "etsi_its_cam_msgs/msg/CAM"
    assert schemas["/carlos/Ego/v2x/denm"] == "etsi_its_denm_msgs/msg/DENM"
    assert schemas["/carlos/Ego/v2x/cpm"] == "etsi_its_cpm_ts_msgs/msg/CollectivePerceptionMessage"
    assert schemas["/carlos/infrastructure/rsu/v2x/cam"] == "etsi_its_cam_msgs/msg/CAM"
    assert schemas["/carlos/v2x/transmissions"] == "carlos_v2x_msgs/msg/TransmissionArray"
    assert schemas["/carlos/infrastructure/rsu/lidar/points"] == "sensor_msgs/msg/PointCloud2"
    assert schemas["/carlos/infrastructure/rsu/lidar/objects"] == "vision_msgs/msg/Detection3DArray"


def test_rsu_cpms_describe_what_its_lidar_saw():
    """With `v2x.perceptionSensor`, a unit's CPMs carry the objects with enough points in its lidar's latest
    sweep: a lidar looking north (90° field of view) sees the walker, not the truck west of the mast that
    the line of sight would give; before its first sweep the unit perceives nothing."""
    from simcore.sensors.rig import SensorRig
    from simcore.world.infrastructure import unit_pose

    spec = _spec(
        stations=[{"entity": "Ego", "cam": False}], channel={"shadowingSigmaDb": 0, "lineOfSight": False}
    )
    lidar = {
        "type": "lidar",
        "name": "top",
        "channels": 16,
        "horizontalResolution": 360,
        "horizontalFov": 90,
        "verticalFov": [-20, 5],
        "mount": {"z": 1.0, "yaw": 90},
    }
    spec["infrastructure"] = [
        {
            "name": "mast",
            "position": {"x": 100.0, "y": 0.0},
            "height": 1.0,
            "sensors": [lidar],
            "v2x": {"cam": False, "perceptionSensor": "top", "perceptionMinPoints": 3},
        }
    ]
    service, got = _service(spec)
    rsu = service.spec.infrastructure[0]
    rig = SensorRig([], None, service.bus, seed=0, units=[(unit_pose(rsu, 0, None, {}), rsu.sensors)])
    entities = (
        _entity("Ego", 30.0),
        _entity("Truck", 85.0, box=TRUCK),
        _entity("Walker", 100.0, 20.0, box=PERSON),
    )
    service.step(_frame(0, *entities))  # the lidar has not swept yet
    rig.step(_frame(1, *entities))
    service.step(_frame(1, *entities))
    cpms = [m.obj() for m in got if m.topic == "/carlos/Ego/v2x/cpm"]
    assert [len(_perceived(c)) for c in cpms] == [0, 1]
    walker = _perceived(cpms[1])[0].classification.array[0].object_class
    assert walker.choice == 1 and walker.vru_sub_class.choice == 0  # a pedestrian
    with pytest.raises(ValueError, match="perceptionSensor 'side' names no lidar"):
        SimulationRunSpec.model_validate(
            {**spec, "infrastructure": [{**spec["infrastructure"][0], "v2x": {"perceptionSensor": "side"}}]}
        )


def test_copies_of_a_message_share_one_serialisation(tmp_path: Path):
    """Every received copy of one message carries the CDR bytes the first copy's subscriber made (the
    recorder writes them as they are): a message delivered to N receivers is serialised once, and the
    recording decodes to the message."""
    from simcore.recorder import McapRecorder

    spec = _spec(channel={"shadowingSigmaDb": 0, "lineOfSight": False})
    service, got = _service(spec)
    with McapRecorder(tmp_path / "v2x.mcap", metadata={}) as recorder:
        service.bus.subscribe("/carlos/*/v2x/*", recorder.write_message)
        service.step(_frame(0, _entity("Ego", 0.0), _entity("A", 20.0), _entity("B", 40.0)))
    copies: dict[int, set[int]] = {}
    for message in got:
        if "/v2x/cam" in message.topic:
            assert message.data is not None
            copies.setdefault(id(message.msg), set()).add(id(message.data))
    assert len(copies) == 3 and all(len(data) == 1 for data in copies.values())  # 3 CAMs, 2 copies each
    with (tmp_path / "v2x.mcap").open("rb") as f:
        decoded = [
            (channel.topic, value)
            for _, channel, _, value in make_reader(
                f, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages()
        ]
    cams = [value for topic, value in decoded if topic.endswith("/v2x/cam")]
    assert len(cams) == 6 and {c.header.station_id.value for c in cams} == {1, 2, 3}
