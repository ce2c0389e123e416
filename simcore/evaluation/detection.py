"""Scoring an object detector against the simulated ground truth (`spec.evaluation.detection`).

Per lidar sweep (matched by header stamp): the ground truth is the sensor's `…/objects` (boxes in the
sensor frame) with `…/objects/info` (lidar points per object); the detections are the system under test's
`vision_msgs/Detection3DArray` with the same stamp (none published = nothing detected).

- Objects and detections farther than `maxRange` (BEV distance of the box centre from the sensor) are
  left out. A ground-truth object with fewer than `minPoints` lidar points is "don't care": a detection
  matched to it is neither a true nor a false positive, and missing it is no false negative.
- Matching: the Hungarian algorithm (scipy `linear_sum_assignment`) on the IoU matrix (BEV IoU of the
  oriented footprints, or 3D IoU = BEV intersection × height overlap / union volume), maximising total
  IoU; a pair with IoU ≥ `iouThreshold` is a match. Classes do not take part in matching.
- Metrics (absent when undefined: precision without detections, recall without required objects):
  `detection.frames`, `.truePositives`, `.falsePositives`, `.falseNegatives`, `.precision` (TP/(TP+FP)),
  `.recall` (TP/(TP+FN)), `.f1`, `.meanIou` and `.meanCenterError` (m, 3D, over true positives),
  `.classAccuracy` (true positives whose detected class is the object's); per distance band
  `detection.<metric>.<lo>-<hi>m` (objects by their distance, false positives by the detection's) and
  per class `detection.recall.<class>` (object class), `detection.precision.<class>` (detected class);
  the class metrics per band too (`detection.recall.car.0-30m`). Ranges from 0 that criteria name
  (`detection.recall >= 0.9 within 50 m`, i.e. `detection.recall.0-50m`) are computed as well
  (`simcore.evaluation.criteria.ranges_of`).
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from simcore.spec import DetectionEvaluation
from simcore.transport.bus import Bus, Message


@dataclass(frozen=True, slots=True)
class Box3D:
    """An oriented box (yaw only) in the sensor frame."""

    x: float
    y: float
    z: float
    length: float
    width: float
    height: float
    yaw: float
    label: str = ""
    name: str = ""

    @property
    def distance(self) -> float:
        return math.hypot(self.x, self.y)

    def footprint(self) -> list[tuple[float, float]]:
        """Ground-plane corners, counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hl, hw = self.length / 2, self.width / 2
        return [
            (self.x + c * dx - s * dy, self.y + s * dx + c * dy)
            for dx, dy in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))
        ]


def _area(poly: Sequence[tuple[float, float]]) -> float:
    n = len(poly)
    if n < 3:
        return 0.0
    return 0.5 * abs(
        sum(poly[i][0] * poly[(i + 1) % n][1] - poly[(i + 1) % n][0] * poly[i][1] for i in range(n))
    )


def _clip(
    subject: list[tuple[float, float]], clipper: Sequence[tuple[float, float]]
) -> list[tuple[float, float]]:
    """Sutherland–Hodgman: `subject` clipped by the convex counter-clockwise polygon `clipper`."""
    out = subject
    n = len(clipper)
    for i in range(n):
        if not out:
            break
        ax, ay = clipper[i]
        bx, by = clipper[(i + 1) % n]

        def inside(
            p: tuple[float, float], ax: float = ax, ay: float = ay, bx: float = bx, by: float = by
        ) -> bool:
            return (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) >= 0.0

        def cut(
            p: tuple[float, float],
            q: tuple[float, float],
            ax: float = ax,
            ay: float = ay,
            bx: float = bx,
            by: float = by,
        ) -> tuple[float, float]:
            ex, ey = bx - ax, by - ay
            dp = ex * (p[1] - ay) - ey * (p[0] - ax)
            dq = ex * (q[1] - ay) - ey * (q[0] - ax)
            t = dp / (dp - dq)
            return p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])

        src, out = out, []
        for j in range(len(src)):
            p, q = src[j - 1], src[j]
            if inside(q):
                if not inside(p):
                    out.append(cut(p, q))
                out.append(q)
            elif inside(p):
                out.append(cut(p, q))
    return out


def bev_intersection(a: Box3D, b: Box3D) -> float:
    """Area of the overlap of the two footprints."""
    if math.hypot(a.x - b.x, a.y - b.y) > (math.hypot(a.length, a.width) + math.hypot(b.length, b.width)) / 2:
        return 0.0
    return _area(_clip(a.footprint(), b.footprint()))


def bev_iou(a: Box3D, b: Box3D) -> float:
    inter = bev_intersection(a, b)
    union = a.length * a.width + b.length * b.width - inter
    return inter / union if union > 0 else 0.0


def iou_3d(a: Box3D, b: Box3D) -> float:
    inter_bev = bev_intersection(a, b)
    dz = min(a.z + a.height / 2, b.z + b.height / 2) - max(a.z - a.height / 2, b.z - b.height / 2)
    inter = inter_bev * max(dz, 0.0)
    union = a.length * a.width * a.height + b.length * b.width * b.height - inter
    return inter / union if union > 0 else 0.0


def boxes_from_detections(msg: Any) -> list[Box3D]:
    """The boxes of a vision_msgs/Detection3DArray (label = the best hypothesis' class_id)."""
    out = []
    for det in msg.detections:
        p = det.bbox.center.position
        q = det.bbox.center.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        label = max(det.results, key=lambda r: r.hypothesis.score).hypothesis.class_id if det.results else ""
        s = det.bbox.size
        out.append(Box3D(p.x, p.y, p.z, s.x, s.y, s.z, yaw, label, det.id))
    return out


@dataclass
class FrameMatch:
    """One sweep's matching: (object index, detection index, IoU, centre error) per true positive."""

    time: float
    matches: list[tuple[int, int, float, float]] = field(default_factory=list)
    false_positives: list[int] = field(default_factory=list)
    false_negatives: list[int] = field(default_factory=list)
    ignored: list[int] = field(default_factory=list)  # detections matched to don't-care objects
    required: int = 0  # objects that had to be detected


def match_frame(
    objects: Sequence[Box3D],
    required: Sequence[bool],
    detections: Sequence[Box3D],
    config: DetectionEvaluation,
    time: float = 0.0,
) -> FrameMatch:
    iou = bev_iou if config.iou == "bev" else iou_3d
    result = FrameMatch(time)
    matched_obj: set[int] = set()
    matched_det: set[int] = set()
    if objects and detections:
        m = np.array([[iou(o, d) for d in detections] for o in objects])
        rows, cols = linear_sum_assignment(m, maximize=True)
        for r, c in zip(rows, cols, strict=True):
            if m[r, c] < config.iou_threshold:
                continue
            matched_obj.add(int(r))
            matched_det.add(int(c))
            if required[r]:
                o, d = objects[r], detections[c]
                err = math.dist((o.x, o.y, o.z), (d.x, d.y, d.z))
                result.matches.append((int(r), int(c), float(m[r, c]), err))
            else:
                result.ignored.append(int(c))
    result.false_positives = [j for j in range(len(detections)) if j not in matched_det]
    result.false_negatives = [i for i in range(len(objects)) if required[i] and i not in matched_obj]
    return result


@dataclass
class _Counts:
    tp: int = 0
    fp: int = 0
    fn: int = 0
    iou: float = 0.0
    center: float = 0.0
    same_class: int = 0

    def metrics(self, prefix: str, suffix: str, *, full: bool = True) -> dict[str, float]:
        out: dict[str, float] = {}
        if full:
            out[f"{prefix}.truePositives{suffix}"] = float(self.tp)
            out[f"{prefix}.falsePositives{suffix}"] = float(self.fp)
            out[f"{prefix}.falseNegatives{suffix}"] = float(self.fn)
        if self.tp + self.fp:
            out[f"{prefix}.precision{suffix}"] = self.tp / (self.tp + self.fp)
        if self.tp + self.fn:
            out[f"{prefix}.recall{suffix}"] = self.tp / (self.tp + self.fn)
        if full and self.tp:
            out[f"{prefix}.meanIou{suffix}"] = self.iou / self.tp
            out[f"{prefix}.meanCenterError{suffix}"] = self.center / self.tp
        return out


#: Per-sweep results, published as sweeps are scored (one sweep after theirs, the rest at the end of the run).
FRAME_TOPIC = "/carlos/evaluation/detection"
FRAME_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"


def _frame_status(frame: FrameMatch, detections: int) -> Any:
    """diagnostic_msgs/DiagnosticStatus of one scored sweep: level WARN when it has a miss or a false
    positive; values stamp (s), required, detections, truePositives, falsePositives, falseNegatives,
    meanIou."""
    from simcore.transport.messages import TYPESTORE

    status = TYPESTORE.types[FRAME_TYPE]
    kv = TYPESTORE.types["diagnostic_msgs/msg/KeyValue"]
    tp, fp, fn = len(frame.matches), len(frame.false_positives), len(frame.false_negatives)
    mean_iou = sum(m[2] for m in frame.matches) / tp if tp else float("nan")
    values = {
        "stamp": repr(frame.time),
        "required": str(frame.required),
        "detections": str(detections),
        "truePositives": str(tp),
        "falsePositives": str(fp),
        "falseNegatives": str(fn),
        "meanIou": repr(mean_iou),
    }
    return status(
        level=1 if fp or fn else 0,
        name="detection",
        message=f"{tp} matched, {fp} false positives, {fn} missed",
        hardware_id="",
        values=[kv(key=k, value=v) for k, v in values.items()],
    )


def _edge(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class DetectionEvaluator:
    """Collects ground truth and detections from the bus and scores them at the end (`result()`)."""

    def __init__(self, config: DetectionEvaluation, ranges: Sequence[float] = ()) -> None:
        """`ranges`: extra distances r for metrics over objects closer than r (`detection.recall.0-50m`),
        e.g. those the criteria name (`detection.recall >= 0.9 within 50 m`)."""
        self.config = config
        self.ranges = sorted(set(ranges))
        from simcore.transport.messages import ros_name

        entity, _, sensor = config.sensor.partition("/")
        base = f"/carlos/{ros_name(entity)}/{sensor}"
        self.objects_topic = f"{base}/objects"
        self.info_topic = f"{base}/objects/info"
        self._objects: dict[int, tuple[float, list[Box3D]]] = {}
        self._points: dict[int, dict[str, int]] = {}
        self._detections: dict[int, list[Box3D]] = {}
        self.frames: list[FrameMatch] = []
        self._frame_data: list[tuple[list[Box3D], list[Box3D]]] = []
        self._scored: set[int] = set()
        self._publisher: Any = None
        self.late_detections = 0

    def attach(self, bus: Bus) -> None:
        """Subscribe to the truth and the detections; per-sweep results go to `FRAME_TOPIC`."""
        bus.subscribe(self.objects_topic, self._on_objects)
        bus.subscribe(self.info_topic, self._on_info)
        bus.subscribe(self.config.topic, self._on_detections)
        self._publisher = bus.advertise(FRAME_TOPIC, FRAME_TYPE)

    def _on_objects(self, message: Message) -> None:
        msg = message.obj()
        self._objects[_stamp_ns(msg)] = (message.time_s, boxes_from_detections(msg))

    def _on_info(self, message: Message) -> None:
        msg = message.obj()
        points: dict[str, int] = {}
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            points[status.name] = int(values.get("points", "0"))
        stamp = _stamp_ns(msg)
        self._points[stamp] = points
        # the sweeps before this one are complete: a detector may answer up to one sweep late
        self._score_pending(before=stamp, time_s=message.time_s)

    def _on_detections(self, message: Message) -> None:
        msg = message.obj()
        stamp = _stamp_ns(msg)
        if stamp in self._scored:
            self.late_detections += 1  # its sweep was scored already: it counts as nothing detected
            return
        self._detections.setdefault(stamp, []).extend(boxes_from_detections(msg))

    def flush(self, time_s: float) -> None:
        """Score every sweep not scored yet (at the end of the run, while the bus is still recorded)."""
        self._score_pending(before=None, time_s=time_s)

    def _score_pending(self, before: int | None, time_s: float, *, publish: bool = True) -> None:
        for stamp in sorted(self._objects):
            if stamp in self._scored or (before is not None and stamp >= before):
                continue
            time, objects = self._objects.pop(stamp)
            frame = self.add_frame(
                time, objects, self._points.pop(stamp, {}), self._detections.pop(stamp, [])
            )
            self._scored.add(stamp)
            if publish and self._publisher is not None:
                self._publisher.publish(_frame_status(frame, len(self._frame_data[-1][1])), time_s)

    def add_frame(
        self, time: float, objects: Sequence[Box3D], points: dict[str, int], detections: Sequence[Box3D]
    ) -> FrameMatch:
        """Score one sweep (objects and detections in the sensor frame; points: lidar points per object name)."""
        cfg = self.config
        objs = [o for o in objects if o.distance <= cfg.max_range]
        dets = [d for d in detections if d.distance <= cfg.max_range]
        required = [points.get(o.name, 0) >= cfg.min_points for o in objs]
        frame = match_frame(objs, required, dets, cfg, time)
        frame.required = sum(required)
        self.frames.append(frame)
        self._frame_data.append((objs, dets))
        return frame

    def result(self) -> dict[str, float]:
        """The `detection.*` metrics over every sweep with ground truth received from the bus."""
        self._score_pending(before=None, time_s=0.0, publish=False)  # after `flush`, nothing is left
        return self._result_from_frames()

    def _result_from_frames(self) -> dict[str, float]:
        """The metrics over the frames added so far (`add_frame`)."""
        cfg = self.config
        edges = [*cfg.bands, cfg.max_range]
        out: dict[str, float] = {"detection.frames": float(len(self.frames))}
        out.update(self._metrics(lambda _: True, ""))
        for lo, hi in itertools.pairwise(edges):
            if lo >= cfg.max_range:
                continue
            last = hi == cfg.max_range

            def in_band(distance: float, lo: float = lo, hi: float = hi, last: bool = last) -> bool:
                return lo <= distance < hi or (last and distance == hi)

            out.update(self._metrics(in_band, f".{_edge(lo)}-{_edge(hi)}m"))
        for reach in self.ranges:

            def within(distance: float, reach: float = reach) -> bool:
                return distance < reach

            out.update(self._metrics(within, f".0-{_edge(reach)}m"))
        return out

    def _metrics(self, keep: Callable[[float], bool], suffix: str) -> dict[str, float]:
        """The metrics over objects (true positives, false negatives: by the object's distance) and false
        positives (by the detection's distance) that `keep` accepts; names end with `suffix`."""
        total = _Counts()
        recall_by_class: dict[str, _Counts] = defaultdict(_Counts)
        precision_by_class: dict[str, _Counts] = defaultdict(_Counts)
        for frame, (objs, dets) in zip(self.frames, self._frame_data, strict=True):
            for oi, di, iou, err in frame.matches:
                o, d = objs[oi], dets[di]
                if not keep(o.distance):
                    continue
                total.tp += 1
                total.iou += iou
                total.center += err
                total.same_class += o.label == d.label
                recall_by_class[o.label].tp += 1
                if o.label == d.label:
                    precision_by_class[d.label].tp += 1
                else:
                    precision_by_class[d.label].fp += 1
            for di in frame.false_positives:
                d = dets[di]
                if keep(d.distance):
                    total.fp += 1
                    precision_by_class[d.label].fp += 1
            for oi in frame.false_negatives:
                o = objs[oi]
                if keep(o.distance):
                    total.fn += 1
                    recall_by_class[o.label].fn += 1
        out = total.metrics("detection", suffix)
        if total.tp:
            p, r = total.tp / (total.tp + total.fp), total.tp / (total.tp + total.fn)
            out[f"detection.f1{suffix}"] = 2 * p * r / (p + r)
            out[f"detection.classAccuracy{suffix}"] = total.same_class / total.tp
        elif total.fp or total.fn:
            out[f"detection.f1{suffix}"] = 0.0
        for label, counts in recall_by_class.items():
            if label and counts.tp + counts.fn:
                out[f"detection.recall.{label}{suffix}"] = counts.tp / (counts.tp + counts.fn)
        for label, counts in precision_by_class.items():
            if label and counts.tp + counts.fp:
                out[f"detection.precision.{label}{suffix}"] = counts.tp / (counts.tp + counts.fp)
        return out
