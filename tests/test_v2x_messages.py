"""ETSI messages: field values in the standard's units, CDR round trip through the recorder, the MCAP
ROS 2 decoder (schemas embedded in the file) and rosbags' AnyReader."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from simcore.recorder import McapRecorder
from simcore.transport import messages
from simcore.v2x import etsi

K = etsi.Kinematics(
    latitude=50.7833,
    longitude=6.0466,
    altitude=173.2,
    heading=271.5,
    speed=13.89,
    acceleration=-4.2,
    yaw_rate=0.1,
    length=4.6,
    width=1.86,
)


def _messages() -> list[tuple[str, str, object]]:
    obj = etsi.PerceivedObject(3, 12.5, -4.0, 0.8, 1.2, 0.0, 90.0, 0.6, 0.6, 1.8, 0.5, 1)
    return [
        ("/carlos/ego/v2x/cam", etsi.CAM_TYPE, etsi.cam(7, 5, 1.25, K, low_frequency=True)),
        ("/carlos/ego/v2x/denm", etsi.DENM_TYPE, etsi.denm(7, 5, 3, 1.3, 1.2, K, 99, 1)),
        ("/carlos/ego/v2x/cpm", etsi.CPM_TYPE, etsi.cpm(1001, 15, 1.3, K, [obj])),
    ]


def test_cam_fields_in_etsi_units():
    msg = etsi.cam(7, 5, 1.25, K, low_frequency=True)
    assert msg.header.message_id == 2 and msg.header.station_id.value == 7
    assert msg.cam.generation_delta_time.value == (etsi.SIM_EPOCH_ITS_MS + 1250) % 65536
    basic = msg.cam.cam_parameters.basic_container
    assert basic.reference_position.latitude.value == 507833000
    assert basic.reference_position.longitude.value == 60466000
    assert basic.reference_position.altitude.altitude_value.value == 17320
    hf = msg.cam.cam_parameters.high_frequency_container.basic_vehicle_container_high_frequency
    assert hf.heading.heading_value.value == 2715
    assert hf.speed.speed_value.value == 1389
    assert hf.longitudinal_acceleration.longitudinal_acceleration_value.value == -42
    assert hf.yaw_rate.yaw_rate_value.value == -573  # 0.1 rad/s to the left = 5.73 °/s anticlockwise
    assert hf.vehicle_length.vehicle_length_value.value == 46 and hf.vehicle_width.value == 19
    assert msg.cam.cam_parameters.low_frequency_container_is_present
    assert not etsi.cam(
        7, 5, 1.35, K, low_frequency=False
    ).cam.cam_parameters.low_frequency_container_is_present
    rsu = etsi.cam(1001, 15, 0.0, K, low_frequency=False, rsu=True)
    assert rsu.cam.cam_parameters.high_frequency_container.choice == 1


def test_cpm_fields_in_ts_103_324_units():
    """The CPM of an RSU and of a vehicle: header (protocol 2, message id 14), management container
    (reference time in ms, reference position in 0.1 µdeg), originating station container (vehicle: its
    heading in 0.1° from north), perceived objects (east/north offsets in cm, velocity in cm/s, yaw in 0.1°
    from east, dimensions in dm rounded up, age in ms up to 1.5 s, class, quality)."""
    walker = etsi.PerceivedObject(3, 12.5, -4.0, 0.8, 1.2, -0.5, 450.0, 0.6, 0.6, 1.8, 2.5, 1)
    truck = etsi.PerceivedObject(9, -2000.0, 0.0, 1.9, 0.0, 0.0, 0.0, 12.0, 2.55, 3.8, 0.25, 8)
    rock = etsi.PerceivedObject(11, 5.0, 5.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, -1)
    msg = etsi.cpm(1001, 15, 1.3, K, [walker, truck, rock], rsu=True)
    assert msg.header.protocol_version.value == 2 and msg.header.message_id.value == 14
    assert msg.header.station_id.value == 1001
    management = msg.payload.management_container
    assert management.reference_time.value == etsi.SIM_EPOCH_ITS_MS + 1300
    assert management.reference_position.latitude.value == 507833000
    station, objects = msg.payload.cpm_containers.value.array
    assert station.container_id.value == 2 and objects.container_id.value == 5
    container = objects.container_data_perceived_object_container
    assert container.number_of_perceived_objects.value == 3
    w, t, r = container.perceived_objects.array
    assert w.object_id.value == 3 and w.object_id_is_present
    assert (w.position.x_coordinate.value.value, w.position.y_coordinate.value.value) == (1250, -400)
    assert w.position.z_coordinate.value.value == 80 and w.position.z_coordinate_is_present
    v = w.velocity.cartesian_velocity
    assert w.velocity.choice == 1 and (v.x_velocity.value.value, v.y_velocity.value.value) == (120, -50)
    assert w.angles.z_angle.value.value == 900  # 450° = 90°
    dims = (
        w.object_dimension_x.value.value,
        w.object_dimension_y.value.value,
        w.object_dimension_z.value.value,
    )
    assert dims == (6, 6, 18)
    assert w.object_age.value == 1500  # observed for more than 1.5 s
    assert w.object_perception_quality.value == 15
    walker_class = w.classification.array[0]
    assert walker_class.object_class.choice == 1 and walker_class.object_class.vru_sub_class.choice == 0
    assert walker_class.confidence.value == 100
    assert t.position.x_coordinate.value.value == -131072  # −2 km: the largest negative value
    truck_class = t.classification.array[0].object_class
    assert truck_class.choice == 0 and truck_class.vehicle_sub_class.value == 8
    assert (t.object_dimension_x.value.value, t.object_dimension_y.value.value) == (120, 26)
    assert r.classification.array[0].object_class.choice == 3
    vehicle = etsi.cpm(7, 5, 1.3, K, [])
    station, objects = vehicle.payload.cpm_containers.value.array
    assert station.container_id.value == 1
    assert station.container_data_originating_vehicle_container.orientation_angle.value.value == 2715
    assert objects.container_data_perceived_object_container.number_of_perceived_objects.value == 0


def test_saturation_at_the_largest_valid_value():
    fast = etsi.Kinematics(0.0, 0.0, 0.0, 0.0, speed=500.0, acceleration=-100.0, length=120.0, width=9.0)
    hf = etsi.cam(1, 5, 0.0, fast, low_frequency=False).cam.cam_parameters.high_frequency_container
    vehicle = hf.basic_vehicle_container_high_frequency
    assert vehicle.speed.speed_value.value == 16382
    assert vehicle.longitudinal_acceleration.longitudinal_acceleration_value.value == -160
    assert vehicle.vehicle_length.vehicle_length_value.value == 1022 and vehicle.vehicle_width.value == 61


def test_etsi_heading_is_clockwise_from_north():
    assert etsi.etsi_heading(1.5707963267948966, 0.0) == pytest.approx(90.0)  # map +x = east
    assert etsi.etsi_heading(1.5707963267948966, 1.5707963267948966) == pytest.approx(0.0)
    assert etsi.etsi_heading(1.5707963267948966, 3.141592653589793) == pytest.approx(270.0)


@pytest.mark.parametrize("topic,typename,msg", _messages(), ids=["cam", "denm", "cpm"])
def test_cdr_round_trip(topic, typename, msg):
    data = messages.serialize(msg)
    assert messages.serialize(messages.deserialize(data, typename)) == data


def test_recorded_messages_decode_with_the_embedded_schemas(tmp_path: Path):
    path = tmp_path / "v2x.mcap"
    with McapRecorder(path, metadata={}) as rec:
        for topic, typename, msg in _messages():
            rec.write(topic, typename, msg, 1.3)
    decoded = {}
    with path.open("rb") as f:
        for schema, channel, _, value in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            decoded[channel.topic] = (schema.name, value)
    name, cam = decoded["/carlos/ego/v2x/cam"]
    assert name == "etsi_its_cam_msgs/msg/CAM"
    assert cam.cam.cam_parameters.basic_container.reference_position.latitude.value == 507833000
    name, denm = decoded["/carlos/ego/v2x/denm"]
    assert name == "etsi_its_denm_msgs/msg/DENM"
    assert denm.denm.situation.event_type.cause_code.value == 99
    assert denm.denm.management.action_id.sequence_number.value == 3
    name, cpm = decoded["/carlos/ego/v2x/cpm"]
    assert name == "etsi_its_cpm_ts_msgs/msg/CollectivePerceptionMessage"
    perceived = cpm.payload.cpm_containers.value.array[1].container_data_perceived_object_container
    assert perceived.perceived_objects.array[0].position.x_coordinate.value.value == 1250
    with AnyReader([path], default_typestore=messages.TYPESTORE) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types["/carlos/ego/v2x/denm"] == etsi.DENM_TYPE
        for conn, _, raw in reader.messages():
            embedded = reader.deserialize(raw, conn.msgtype)
            assert messages.serialize(embedded) == messages.serialize(messages.deserialize(raw, conn.msgtype))


def test_vectorised_clipping_equals_the_scalar_rule():
    """`clip_rows` (the CAM and CPM builders' one numpy pass) gives `_clip`'s integers: round half to even,
    saturation at the row's limits, non-finite values at the largest."""
    import math

    import numpy as np

    rng = np.random.default_rng(3)
    values = np.concatenate(
        [rng.normal(0, 300, 200), [0.5, 1.5, -2.5, 1e12, -1e12, math.nan, math.inf, -math.inf]]
    )
    limits = np.array([[-100, 100], [0, 3600]], dtype=np.float64)
    rows = etsi.clip_rows(np.stack([values, values * 10]), limits)
    assert rows[0] == [etsi._clip(v, -100, 100) for v in values]
    assert rows[1] == [etsi._clip(v * 10, 0, 3600) for v in values]
