"""Detection evaluation: IoU geometry, Hungarian matching, don't-care objects, metrics by band and class."""

from __future__ import annotations

import math

import pytest

from simcore.evaluation.detection import Box3D, DetectionEvaluator, bev_iou, iou_3d, match_frame
from simcore.spec import DetectionEvaluation

CONFIG = DetectionEvaluation(
    sensor="Ego/lidar", topic="/carlos/sut/detections", iou_threshold=0.3, min_points=5
)


def box(
    x: float,
    y: float,
    length: float = 4.0,
    width: float = 2.0,
    yaw: float = 0.0,
    label: str = "car",
    name: str = "",
) -> Box3D:
    return Box3D(x, y, 0.0, length, width, 1.5, yaw, label, name)


def test_bev_iou() -> None:
    a = box(10, 0)
    assert bev_iou(a, a) == pytest.approx(1.0)
    assert bev_iou(a, box(20, 0)) == 0.0
    # shifted by half its length: overlap 2×2 = 4, union 8 + 8 - 4 = 12
    assert bev_iou(a, box(12, 0)) == pytest.approx(4 / 12)
    # a square turned by 90° is the same square; by 45° the overlap is the regular octagon
    sq = box(0, 0, 2, 2)
    assert bev_iou(sq, box(0, 0, 2, 2, yaw=math.pi / 2)) == pytest.approx(1.0)
    octagon = 8 * (math.sqrt(2) - 1)
    assert bev_iou(sq, box(0, 0, 2, 2, yaw=math.pi / 4)) == pytest.approx(octagon / (8 - octagon))
    # yaw and yaw + π are the same footprint
    assert bev_iou(box(5, 5, yaw=0.3), box(5, 5, yaw=0.3 + math.pi)) == pytest.approx(1.0)


def test_iou_3d() -> None:
    a = box(10, 0)
    b = Box3D(10, 0, 0.75, 4.0, 2.0, 1.5, 0.0)  # same footprint, half the height overlaps
    assert iou_3d(a, a) == pytest.approx(1.0)
    assert iou_3d(a, b) == pytest.approx(0.5 / 1.5)
    assert bev_iou(a, b) == pytest.approx(1.0)


def test_hungarian_matching_beats_greedy() -> None:
    # greedy (best IoU first) would give detection 0 to object 1 and leave object 0 unmatched
    objects = [box(0, 0, name="a"), box(2.6, 0, name="b")]
    detections = [box(1.3, 0), box(3.9, 0)]
    m = match_frame(objects, [True, True], detections, CONFIG)
    assert sorted((o, d) for o, d, _, _ in m.matches) == [(0, 0), (1, 1)]
    assert m.false_positives == [] and m.false_negatives == []


def test_threshold_dont_care_and_errors() -> None:
    objects = [box(10, 0, name="seen"), box(30, 0, name="hidden"), box(50, 0, name="missed")]
    detections = [box(10.5, 0.2), box(30, 0), box(70, 5)]
    m = match_frame(objects, [True, False, True], detections, CONFIG)
    assert [(o, d) for o, d, _, _ in m.matches] == [(0, 0)]
    assert m.matches[0][3] == pytest.approx(math.hypot(0.5, 0.2))
    assert m.ignored == [1], "a detection of a don't-care object is neither true nor false positive"
    assert m.false_positives == [2] and m.false_negatives == [2]
    loose = match_frame([box(0, 0)], [True], [box(2.5, 0)], CONFIG)  # IoU 1.5·2/(16-3) = 0.23 < 0.3
    assert loose.matches == [] and loose.false_positives == [0] and loose.false_negatives == [0]


def test_metrics_by_band_and_class() -> None:
    ev = DetectionEvaluator(CONFIG.model_copy(update={"bands": [0.0, 30.0], "max_range": 80.0}))
    points = {"near": 100, "far": 50, "ped": 20, "few": 2}
    # frame 1: near car found, far car missed, a pedestrian found but called a car, a false positive far away
    ev.add_frame(
        0.0,
        [
            box(10, 0, name="near"),
            box(50, 0, name="far"),
            box(20, 5, 0.6, 0.6, label="pedestrian", name="ped"),
        ],
        points,
        [box(10.2, 0), box(20, 5, 0.6, 0.6, label="car"), box(60, -10)],
    )
    # frame 2: both cars found; an object with too few points is not required; one beyond maxRange ignored
    ev.add_frame(
        0.1,
        [box(11, 0, name="near"), box(49, 0, name="far"), box(25, -5, name="few"), box(90, 0, name="out")],
        points,
        [box(11, 0), box(49, 0), box(90, 0)],
    )
    metrics = ev._result_from_frames()
    assert metrics["detection.frames"] == 2
    assert metrics["detection.truePositives"] == 4
    assert metrics["detection.falsePositives"] == 1
    assert metrics["detection.falseNegatives"] == 1
    assert metrics["detection.precision"] == pytest.approx(4 / 5)
    assert metrics["detection.recall"] == pytest.approx(4 / 5)
    assert metrics["detection.f1"] == pytest.approx(0.8)
    assert metrics["detection.recall.0-30m"] == pytest.approx(1.0)
    assert metrics["detection.recall.30-80m"] == pytest.approx(1 / 2)
    assert metrics["detection.precision.30-80m"] == pytest.approx(1 / 2)
    assert metrics["detection.recall.pedestrian"] == pytest.approx(1.0)
    assert metrics["detection.recall.car"] == pytest.approx(3 / 4)
    # the pedestrian detected as a car counts against the car class' precision
    assert metrics["detection.precision.car"] == pytest.approx(3 / 5)
    assert metrics["detection.classAccuracy"] == pytest.approx(3 / 4)
    assert metrics["detection.meanIou"] < 1.0 and metrics["detection.meanCenterError"] > 0.0


def test_undefined_metrics_are_absent() -> None:
    ev = DetectionEvaluator(CONFIG)
    ev.add_frame(0.0, [box(10, 0, name="a")], {"a": 1}, [])
    metrics = ev._result_from_frames()
    assert metrics["detection.frames"] == 1
    assert "detection.recall" not in metrics and "detection.precision" not in metrics


def test_within_ranges_and_per_class_bands() -> None:
    from pydantic import TypeAdapter

    from simcore.evaluation.criteria import ranges_of
    from simcore.spec import Criterion

    criterion = TypeAdapter(Criterion).validate_python("detection.recall >= 0.9 within 50 m")
    assert (
        criterion.metric == "detection.recall.0-50m"
        and criterion.name == "detection.recall >= 0.9 within 50 m"
    )
    assert ranges_of(
        [criterion.metric, "detection.precision.car.0-12.5m", "minDistance", "detection.recall"]
    ) == [12.5, 50.0]
    ev = DetectionEvaluator(CONFIG.model_copy(update={"bands": [0.0, 30.0]}), ranges=[50.0])
    ev.add_frame(
        0.0,
        [
            box(10, 0, name="a"),
            box(40, 0, name="b"),
            box(70, 0, name="c"),
            box(20, 5, 0.6, 0.6, label="pedestrian", name="ped"),
        ],
        {"a": 50, "b": 50, "c": 50, "ped": 50},
        [box(10, 0), box(70, 0), box(45, 10)],
    )
    m = ev._result_from_frames()
    # within 50 m: a found, b and the pedestrian missed; the false positive at 46 m counts
    assert m["detection.recall.0-50m"] == pytest.approx(1 / 3)
    assert m["detection.precision.0-50m"] == pytest.approx(1 / 2)
    assert m["detection.recall.car.0-50m"] == pytest.approx(1 / 2)
    assert m["detection.recall.pedestrian.0-30m"] == 0.0
    assert m["detection.recall"] == pytest.approx(2 / 4)
    with pytest.raises(ValueError, match="detection"):
        TypeAdapter(Criterion).validate_python("minDistance >= 2 within 50 m")


def test_scores_every_sweep_on_the_bus() -> None:
    import numpy as np

    from simcore.sensors import ros
    from simcore.transport.bus import InProcessBus, Message

    bus = InProcessBus()
    scored: list[Message] = []
    bus.subscribe("/carlos/evaluation/detection", scored.append)
    ev = DetectionEvaluator(CONFIG)
    ev.attach(bus)
    objects = bus.advertise("/carlos/Ego/lidar/objects", ros.DETECTIONS)
    info = bus.advertise("/carlos/Ego/lidar/objects/info", ros.DIAGNOSTICS)
    dets = bus.advertise("/carlos/sut/detections", ros.DETECTIONS)
    q = ros.quaternion_of(np.eye(3))

    def array(time: float, centers: list[float], ids: list[str]) -> object:
        hdr = ros.header(time, "Ego/lidar")
        size = np.array([4.0, 2.0, 1.5])
        return ros.detection_array(
            [
                ros.detection(np.array([x, 0.0, 0.0]), q, size, "car", 1.0, i, hdr)
                for x, i in zip(centers, ids, strict=True)
            ],
            hdr,
        )

    for k, time in enumerate((0.0, 0.1, 0.2)):
        dets.publish(
            array(time, [10.2] if k != 1 else [], ["0"] if k != 1 else []), time
        )  # sweep 0.1: nothing
        objects.publish(array(time, [10.0], ["Other"]), time)
        info.publish(
            ros.object_info([{"name": "Other", "points": "40"}], ros.header(time, "Ego/lidar")), time
        )
    # a sweep is scored once the next one's truth arrives; the last one at flush (end of run)
    assert len(scored) == 2
    dets.publish(array(0.0, [10.0], ["late"]), 0.25)  # too late: sweep 0.0 is scored already
    ev.flush(0.3)
    assert len(scored) == 3 and ev.late_detections == 1
    values = [{kv.key: kv.value for kv in m.msg.values} for m in scored]
    assert [v["truePositives"] for v in values] == ["1", "0", "1"]
    assert [v["falseNegatives"] for v in values] == ["0", "1", "0"]
    assert [m.msg.level for m in scored] == [0, 1, 0]
    m = ev.result()
    assert m["detection.frames"] == 3 and m["detection.recall"] == pytest.approx(2 / 3)
    assert m["detection.precision"] == 1.0
