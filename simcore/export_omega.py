"""`carlos export --format omega-prime`: one omega-prime file per index (ASAM OSI GroundTruth per step).

An omega-prime file is an MCAP file of `osi3.GroundTruth` messages (protobuf, topic `ground_truth`, one per
simulation step) with the scenario's OpenDRIVE map as one `osi3.MapAsamOpenDrive` message on topic
`ground_truth_map`, written by betterosi (the `net.asam.osi.trace` metadata and channel metadata are its own).
It is read by `omega_prime.Recording.from_file(path, validate=True)`.

What goes in, from the index's `recording.mcap`:
- every scenario entity (the ids of `/carlos/objects`, in their order of first appearance: OSI id 0, 1, …) as
  an OSI MovingObject per step: `type`/`vehicle_classification` from the OpenSCENARIO category, `dimension`
  from the ground-truth box, `position` = the box centre (OSI: the bounding box's centre, not the entity's
  reference point; /tf has the reference point), `orientation` roll/pitch/yaw from /tf, `velocity` = the
  odometry speed along the entity's x axis turned into the map frame, `acceleration` = the change of that
  velocity between steps (central differences, one-sided at the ends: the recording has no acceleration);
- `host_vehicle_id` = the ego (`spec.simulation.ego`, else the entity named Ego/ego/hero/Hero, else the first);
- the map: the OpenDRIVE file of the scenario (`carlos.run` metadata `scenarioFile`, its RoadNetwork LogicFile).
A recording with its own OSI channel (`spec.recording.osi`) for every step: those GroundTruth messages are
taken as they are (the engine's longitudinal acceleration instead of differences).

Needs the optional extra `carlos-sim[omega]` (betterosi); without it the export is bad input (exit 2) naming it.
"""

from __future__ import annotations

import io
import json
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simcore.errors import BadInput
from simcore.osi import (
    GROUND_TRUTH_SCHEMA,
    OSI_TOPIC,
    ObjectRow,
    betterosi,
    forward,
    ground_truth,
    osi_type,
    rpy,
)
from simcore.results import RunResults
from simcore.store import FileStore

__all__ = ["export_omega_prime", "omega_prime_bytes", "osi_rows"]

TF_TOPIC = "/tf"
OBJECTS_TOPIC = "/carlos/objects"
#: The largest OpenDRIVE file embedded (bytes): a map is a few MB; more is a mistake, not a map.
MAX_MAP_BYTES = 256 * 1024 * 1024


@dataclass(frozen=True, slots=True)
class _Seen:
    """What the recording says of one entity at one step."""

    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # quaternion x, y, z, w
    center: tuple[float, float, float] | None = None
    size: tuple[float, float, float] | None = None
    category: str = ""
    speed: float = 0.0


def osi_rows(steps: Sequence[tuple[int, Mapping[str, _Seen]]], names: Sequence[str]) -> list[list[ObjectRow]]:
    """The OSI moving objects of every step (pure): `steps` in time order as (ns, entity → what was seen),
    `names` the entities in id order. An entity is written at the steps it has both a /tf pose and a box."""
    ids = {name: i for i, name in enumerate(names)}
    # velocity per entity and step, then central differences over the steps each entity is present
    velocity: dict[tuple[str, int], tuple[float, float, float]] = {}
    series: dict[str, list[tuple[int, tuple[float, float, float]]]] = {}
    for step, (nanos, seen) in enumerate(steps):
        for name, s in seen.items():
            if s.size is None or name not in ids:
                continue
            fx, fy, fz = forward(s.rotation)
            v = (s.speed * fx, s.speed * fy, s.speed * fz)
            velocity[(name, step)] = v
            series.setdefault(name, []).append((nanos, v))
    acceleration: dict[tuple[str, int], tuple[float, float, float]] = {}
    step_of = {nanos: step for step, (nanos, _) in enumerate(steps)}
    for name, points in series.items():
        times = np.array([p[0] for p in points], dtype=np.float64) * 1e-9
        values = np.array([p[1] for p in points], dtype=np.float64)
        grads = np.gradient(values, times, axis=0) if len(points) > 1 else np.zeros_like(values)
        for (nanos, _), g in zip(points, grads, strict=True):
            acceleration[(name, step_of[nanos])] = (float(g[0]), float(g[1]), float(g[2]))
    out: list[list[ObjectRow]] = []
    for step, (nanos, seen) in enumerate(steps):
        rows = []
        for name in names:
            got = seen.get(name)
            if got is None or got.size is None or got.center is None:
                continue
            rows.append(
                ObjectRow(
                    nanos=nanos,
                    idx=ids[name],
                    name=name,
                    position=got.center,
                    orientation=rpy(got.rotation),
                    velocity=velocity[(name, step)],
                    acceleration=acceleration[(name, step)],
                    dimension=got.size,
                    types=osi_type(got.category),
                )
            )
        out.append(rows)
    return out


@dataclass
class _Recorded:
    """What the export takes from a recording: the steps (time order, ns → entity → what was seen), the
    entities in order of first appearance, the metadata records, the recorded OSI GroundTruth by ns."""

    steps: list[tuple[int, dict[str, _Seen]]]
    names: list[str]
    metadata: dict[str, dict[str, str]]
    osi: dict[int, bytes]


def _read_recording(data: bytes) -> _Recorded:
    """The ground truth of a CARLOS recording (see `_Recorded`)."""
    from mcap.reader import make_reader

    from simcore.transport.messages import base_link, deserialize, odometry_topic

    reader = make_reader(io.BytesIO(data))
    metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
    poses: dict[int, dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float]]]] = {}
    boxes: dict[int, list[tuple[str, tuple[float, float, float], tuple[float, float, float], str]]] = {}
    speeds: dict[int, dict[str, float]] = {}
    names: dict[str, None] = {}
    recorded: dict[int, bytes] = {}
    summary = reader.get_summary()
    channels = summary.channels.values() if summary is not None else ()
    topics = [
        c.topic
        for c in channels
        if c.topic in (TF_TOPIC, OBJECTS_TOPIC, OSI_TOPIC)
        or (c.topic.startswith("/carlos/") and c.topic.endswith("/odometry"))
    ]
    # file order (no heap merge by time: each step is keyed by its time below, names by the objects' order)
    for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=False):
        topic = channel.topic
        if schema is None:
            continue
        if topic == OSI_TOPIC:  # spec.recording.osi: the engine's own ground truth, taken as it is
            if schema.name == GROUND_TRUTH_SCHEMA:
                recorded[int(message.log_time)] = bytes(message.data)
            continue
        msg = deserialize(message.data, schema.name)
        nanos = int(message.log_time)
        if topic == TF_TOPIC:
            frame = poses.setdefault(nanos, {})
            for t in msg.transforms:
                name = str(t.child_frame_id)  # `<ros name>/base_link`
                tr, rot = t.transform.translation, t.transform.rotation
                frame[name] = (
                    (float(tr.x), float(tr.y), float(tr.z)),
                    (float(rot.x), float(rot.y), float(rot.z), float(rot.w)),
                )
        elif topic == OBJECTS_TOPIC:
            listed = boxes.setdefault(nanos, [])
            for d in msg.detections:
                c, size = d.bbox.center.position, d.bbox.size
                category = str(d.results[0].hypothesis.class_id) if d.results else ""
                listed.append(
                    (
                        str(d.id),
                        (float(c.x), float(c.y), float(c.z)),
                        (float(size.x), float(size.y), float(size.z)),
                        category,
                    )
                )
                names.setdefault(str(d.id))
        else:
            speeds.setdefault(nanos, {})[topic] = float(msg.twist.twist.linear.x)
    steps: list[tuple[int, dict[str, _Seen]]] = []
    for nanos in sorted(set(poses) & set(boxes)):
        pose, speed = poses[nanos], speeds.get(nanos, {})
        seen: dict[str, _Seen] = {}
        for name, center, size, category in boxes[nanos]:
            # /tf and odometry name the entity by its ROS token, /carlos/objects by its scenario name
            found = pose.get(base_link(name))
            if found is not None:
                translation, rotation = found
                seen[name] = _Seen(
                    translation, rotation, center, size, category, speed.get(odometry_topic(name), 0.0)
                )
        steps.append((nanos, seen))
    return _Recorded(steps, list(names), metadata, recorded)


def _ego(metadata: Mapping[str, Mapping[str, str]], names: Sequence[str]) -> str | None:
    """The host vehicle: `spec.simulation.ego` of the recorded manifest, else the engine's default rule."""
    import yaml

    manifest = metadata.get("carlos.spec", {}).get("manifest")
    if manifest:
        spec = (yaml.safe_load(manifest) or {}).get("spec", {})
        ego = (spec.get("simulation") or {}).get("ego")
        if isinstance(ego, str) and ego in names:
            return ego
    for candidate in ("Ego", "ego", "hero", "Hero"):
        if candidate in names:
            return candidate
    return names[0] if names else None


def _scenario_file(
    metadata: Mapping[str, Mapping[str, str]], index: int, results: RunResults, scratch: Path
) -> Path:
    """The recorded scenario's OpenSCENARIO file here: the path the run used (`carlos.run` scenarioFile)
    when it is on this machine, else the run's `spec.scenarios[].openscenario` (an s3:// scenario and its
    road are downloaded into `scratch`; a relative path is taken from the working directory)."""
    run = metadata.get("carlos.run", {})
    recorded = run.get("scenarioFile")
    if recorded and Path(recorded).is_file():
        return Path(recorded)
    refs = [s for s in results.spec.spec.scenarios if s.name == run.get("scenario")] if results.spec else []
    if not refs or not refs[0].openscenario:
        raise BadInput(
            f"index {index}: scenario {recorded or run.get('scenario')!r} is not on this machine and the run's "
            "spec names no openscenario for it: export where the scenario files are",
            field="--format",
        )
    from simcore.plan import RunPoint
    from simcore.runner import resolve_scenario_file
    from simcore.store import open_store

    parameters = json.loads(run.get("parameters") or "{}")
    point = RunPoint(index, refs[0], 0, 0, {}, parameters, 0)
    path = resolve_scenario_file(point, Path.cwd(), scratch, open_store)
    if not path.is_file():
        raise BadInput(f"index {index}: scenario {path} not found", field=f"spec.scenarios[{refs[0].name}]")
    return path


def _map_file(
    metadata: Mapping[str, Mapping[str, str]], index: int, results: RunResults, scratch: Path
) -> Path:
    """The OpenDRIVE file of the recorded scenario (its RoadNetwork LogicFile, relative to the scenario)."""
    from simcore.scenario.xosc import load_scenario

    path = _scenario_file(metadata, index, results, scratch)
    parameters = json.loads(metadata.get("carlos.run", {}).get("parameters") or "{}")
    odr = load_scenario(path, parameters).road_file
    if odr is None:
        raise BadInput(f"{path}: no RoadNetwork/LogicFile: the scenario has no OpenDRIVE map", file=str(path))
    if not odr.is_file():
        raise BadInput(
            f"{path}: OpenDRIVE map {odr} not found", file=str(path), field="RoadNetwork.LogicFile"
        )
    return odr


def omega_prime_bytes(
    recorded: _Recorded, ego: str | None, odr: tuple[str, str] | None, description: str
) -> bytes:
    """The omega-prime MCAP file (betterosi's writer): GroundTruth per step, the map once. When the
    recording has its own OSI channel for every step (spec.recording.osi), those messages are taken."""
    bo = betterosi("--format omega-prime")
    steps, names = recorded.steps, recorded.names
    host = names.index(ego) if ego is not None and ego in names else None
    own = all(nanos in recorded.osi for nanos, _ in steps)
    with tempfile.TemporaryDirectory(prefix="carlos-omega-") as tmp:
        target = Path(tmp) / "index.mcap"
        # creation_time fixed: the same recording gives the same bytes
        meta = {"creation_time": "1970-01-01T00:00:00Z", "description": description, "data_sources": "CARLOS"}
        with bo.Writer(target, metadata=meta, library="carlos") as writer:
            first: int | None = None
            for rows, (nanos, _) in zip(osi_rows(steps, names), steps, strict=True):
                first = nanos if first is None else first
                gt = (
                    bo.GroundTruth.from_binary(recorded.osi[nanos])
                    if own
                    else ground_truth(bo, nanos, rows, host)
                )
                writer.add(gt, topic="ground_truth", log_time=nanos)
            if odr is not None:
                reference, xml = odr
                writer.add(
                    bo.MapAsamOpenDrive(map_reference=reference, open_drive_xml_content=xml),
                    topic="ground_truth_map",
                    log_time=first or 0,
                )
        return target.read_bytes()


def _indexes(results: RunResults) -> Iterator[int]:
    for summary in results.indexes:
        if results.store.exists(f"{summary['index']}/recording.mcap"):
            yield int(summary["index"])


def export_omega_prime(
    results: RunResults, out: Path, indexes: Iterable[int] | None = None
) -> tuple[Path, int]:
    """Write `out/<run>/<index>.mcap` (omega-prime) per index with a recording; (that folder, files written)."""
    betterosi("--format omega-prime")
    root = out.expanduser().absolute() / results.name
    store = FileStore(root)
    written = 0
    maps: dict[Path, tuple[str, str]] = {}
    scratch = Path(tempfile.mkdtemp(prefix="carlos-export-"))
    try:
        for index in indexes if indexes is not None else _indexes(results):
            written += _export_index(results, index, store, maps, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return root, written


def _export_index(
    results: RunResults, index: int, store: FileStore, maps: dict[Path, tuple[str, str]], scratch: Path
) -> int:
    """Write one index's omega-prime file; 1."""
    data = results.store.get_bytes(f"{index}/recording.mcap")
    recorded = _read_recording(data)
    metadata = recorded.metadata
    if not recorded.steps:
        raise BadInput(
            f"index {index}: the recording has no /tf and /carlos/objects: record them "
            "(spec.recording.topics) to export omega-prime",
            field="spec.recording.topics",
        )
    odr_path = _map_file(metadata, index, results, scratch)
    if odr_path not in maps:
        if odr_path.stat().st_size > MAX_MAP_BYTES:
            raise BadInput(f"{odr_path}: larger than {MAX_MAP_BYTES} bytes", file=str(odr_path))
        maps[odr_path] = (odr_path.name, odr_path.read_text(encoding="utf-8"))
    run = metadata.get("carlos.run", {})
    description = json.dumps(
        {"run": results.name, "index": index, "scenario": run.get("scenario"), "seed": run.get("seed")},
        sort_keys=True,
    )
    blob = omega_prime_bytes(recorded, _ego(metadata, recorded.names), maps[odr_path], description)
    store.put_bytes(f"{index}.mcap", blob)
    return 1
