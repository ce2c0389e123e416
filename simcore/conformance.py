"""`carlos conformance DIR`: run every OpenSCENARIO file under DIR headless and compare with reference
trajectories (the esmini corpus: `reference/<folder>__<name>.csv.gz`, every entity every 0.1 s).

Per scenario: did it load, did it run to its own end (StopTrigger) within the simulated-time cap, and —
where a reference exists — per entity position RMSE over the common time span and the end time. A scenario
*agrees* only when every scripted entity (one no controller drives) is within `RMSE_LIMIT` metres and the end
time within `END_LIMIT` seconds. Numbers are meant to be honest: nothing is skipped silently; a scenario that
fails to load or crashes counts against every total.
"""

from __future__ import annotations

import csv
import gzip
import io
import json
import math
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simcore.errors import BadInput, CarlosError

if TYPE_CHECKING:
    from simcore.spec import SimulationRun

STEP_SECONDS = 0.05
REFERENCE_PERIOD = 0.1
DEFAULT_CAP_SECONDS = 1250.0
RMSE_LIMIT = 0.5
END_LIMIT = 0.1
#: the catalogue rule (issue #25): every compared entity's final position within FINAL_LIMIT m of the
#: reference's and the end time within FINAL_END_LIMIT s (`ScenarioResult.agreed_final`)
FINAL_LIMIT = 1.0
FINAL_END_LIMIT = 0.15
Track = list[tuple[float, float, float]]  # (time on the scenario's time axis, x, y)


@dataclass
class EntityResult:
    name: str
    scripted: bool
    rmse: float | None  # None: not in the reference or no common samples
    samples: int
    final_error: float | None = None  # distance at the last common sample time, m


@dataclass
class ScenarioResult:
    file: str
    kind: str = "scenario"  # scenario | distribution | catalog
    status: str = "bad_input"  # bad_input | error | capped | ended
    loaded: bool = False
    ended: bool = False
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    reference: str | None = None
    reference_end: float | None = None
    end_error: float | None = None
    max_rmse: float | None = None
    worst_entity: str | None = None
    agreed: bool = False
    message: str = ""
    reference_message: str = ""  # why the reference player gave no reference (differential runs)
    final_error: float | None = None  # largest distance between final positions of a compared entity, m
    agreed_final: bool = False  # the catalogue rule: final positions within FINAL_LIMIT, end FINAL_END_LIMIT
    warnings: list[str] = field(default_factory=list)
    entities: list[EntityResult] = field(default_factory=list)


# --- discovery and references ------------------------------------------------------------------------------


def scenario_files(directory: Path, include: list[str] | None = None) -> list[Path]:
    """Every .xosc under `directory` that is a scenario or a ParameterValueDistribution (catalogs skipped);
    with `include`, only those whose path relative to `directory` matches one of the glob patterns."""
    out = []
    for path in sorted(directory.rglob("*.xosc")):
        if include and not any(path.relative_to(directory).match(p) for p in include):
            continue
        kind = file_kind(path)
        if kind in ("scenario", "distribution"):
            out.append(path)
    return out


def file_kind(path: Path) -> str:
    """scenario, distribution, catalog or unknown, from the first elements (cheap, no full parse)."""
    try:
        head = path.read_bytes()[:65536].decode("utf-8", "replace")
    except OSError:
        return "unknown"
    if "<Catalog " in head or "<Catalog>" in head:
        return "catalog"
    if "<ParameterValueDistribution" in head:
        return "distribution"
    if "<OpenSCENARIO" in head:
        return "scenario"
    return "unknown"


def reference_name(path: Path) -> str:
    return f"{path.parent.name}__{path.stem}.csv.gz"


def read_reference(path: Path) -> dict[str, list[tuple[float, float, float]]]:
    """entity name → [(time, x, y)] from a reference CSV (gzip or plain)."""
    opener: Callable[..., Any] = gzip.open if path.suffix == ".gz" else open
    tracks: dict[str, list[tuple[float, float, float]]] = {}
    with opener(path, "rt", newline="") as handle:
        for row in csv.DictReader(handle):
            tracks.setdefault(row["name"], []).append((float(row["time"]), float(row["x"]), float(row["y"])))
    return tracks


def reference_end_times(reference_dir: Path) -> dict[str, float]:
    """Reference end times by reference file name, from an INDEX.tsv next to the reference directory (the
    exact end; the CSV only knows it to its 0.1 s sampling)."""
    out: dict[str, float] = {}
    for candidate in (reference_dir / "INDEX.tsv", reference_dir.parent / "INDEX.tsv"):
        if not candidate.is_file():
            continue
        with candidate.open(newline="") as handle:
            for row in csv.DictReader(handle, delimiter="\t"):
                ref = row.get("reference_csv") or ""
                value = row.get("esmini_sim_s") or ""
                if ref and value:
                    try:
                        out[Path(ref).name] = float(value)
                    except ValueError:
                        continue
        break
    return out


def uncompared_entities(scenario: Any) -> set[str]:
    """Entities of a loaded scenario that a controller CARLOS does not run as the reference player does
    drives (ObjectController or AssignControllerAction with a controller other than the default one and
    those of `simcore.scenario.model.MODELLED_CONTROLLERS`, e.g. esmini's SloppyDriver): their motion is the
    controller's, not the script's, so they are reported but do not decide agreement."""
    from simcore.scenario import model as m

    return {
        name
        for name, kinds in m.controller_kinds(scenario).items()
        if any(kind not in m.MODELLED_CONTROLLERS for kind in kinds)
    }


# --- running one scenario ----------------------------------------------------------------------------------


@dataclass
class Trace:
    """Our positions at every REFERENCE_PERIOD of simulated time."""

    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    controlled: set[str] | None = None  # entities not compared (`uncompared_entities`), once loaded

    def add(self, time_s: float, name: str, x: float, y: float) -> None:
        self.tracks.setdefault(name, []).append((time_s, x, y))


def conformance_run(path: Path, cap_seconds: float) -> SimulationRun:
    """The SimulationRun a conformance check makes of one file: 0.05 s steps up to the cap, seed 1, no
    recording (what the reference player did, headless)."""
    from simcore.spec import SimulationRun

    return SimulationRun.model_validate(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": "conformance"},
            "spec": {
                "scenarios": [{"name": "conformance", "openscenario": str(path)}],
                "simulation": {"stepSeconds": STEP_SECONDS, "maxSeconds": cap_seconds, "seed": 1},
                "recording": {"enabled": False},
            },
        }
    )


def run_scenario(path: Path, cap_seconds: float = DEFAULT_CAP_SECONDS) -> tuple[ScenarioResult, Trace]:
    """Run one scenario headless through the run pipeline (`simcore.pipeline`, as `carlos run` does) and
    trace it; never raises for problems of the scenario itself."""
    result = ScenarioResult(file=str(path), kind=file_kind(path))
    trace = Trace()
    if result.kind != "scenario":
        result.status = "skipped"
        result.message = f"{result.kind} file, not a scenario"
        return result, trace
    started = time.perf_counter()
    try:
        from simcore import pipeline
        from simcore.plan import Plan

        run = conformance_run(path, cap_seconds)
        every = round(REFERENCE_PERIOD / STEP_SECONDS)
        offset = 0.0

        def loaded(scenario: Any) -> None:
            result.warnings = list(scenario.warnings)
            trace.controlled = uncompared_entities(scenario)

        def sample(engine: Any) -> None:
            nonlocal offset
            if engine.step_index == 0:  # assembled: the scenario and its road loaded
                result.loaded = True
                offset = engine.output_time_offset
            if engine.step_index % every == 0:
                _sample(trace, engine, offset)

        # the run pipeline as `carlos run` runs it (`simcore.runner`): only the recording is off
        done = pipeline.simulate(run, Plan(run.spec)[0], path, path.parent, observe=sample, on_loaded=loaded)
        result.sim_seconds = done.sim_seconds + done.scenario_time_offset  # on the scenario's time axis
        result.ended = done.end_reason == "stopTrigger"
        result.status = "ended" if result.ended else "capped"
        if not result.ended:
            result.message = f"no end within {cap_seconds:g} s of simulated time"
        result.warnings = list(done.warnings)
    except CarlosError as exc:
        result.status = "bad_input" if isinstance(exc, BadInput) and not result.loaded else "error"
        result.message = str(exc)
    except Exception as exc:  # a crash is a result of the scenario, counted and shown (one line + where)
        result.status = "error"
        where = traceback.extract_tb(exc.__traceback__)[-1]
        result.message = f"{type(exc).__name__}: {exc} ({Path(where.filename).name}:{where.lineno})"
    result.wall_seconds = time.perf_counter() - started
    return result, trace


def _sample(trace: Trace, engine: Any, offset: float) -> None:
    t = round(engine.time + offset, 6)  # on the scenario's (the reference's) time axis
    for body in engine.bodies.values():
        if not getattr(body, "gone", False) and getattr(body, "placed", True):
            trace.add(t, body.name, body.x, body.y)


def track_error(ours: Track, theirs: Track) -> tuple[float | None, float | None, int]:
    """(position RMSE over the sample times both tracks have, distance at the last of them, how many) of two
    tracks sampled every REFERENCE_PERIOD s; (None, None, 0) when they share no sample time."""
    by_time = {round(t / REFERENCE_PERIOD): (x, y) for t, x, y in ours}
    total, count, last = 0.0, 0, 0.0
    for t, x, y in theirs:
        mine = by_time.get(round(t / REFERENCE_PERIOD))
        if mine is None:
            continue
        last = (mine[0] - x) ** 2 + (mine[1] - y) ** 2
        total += last
        count += 1
    if not count:
        return None, None, 0
    return math.sqrt(total / count), math.sqrt(last), count


def compare(
    result: ScenarioResult,
    trace: Trace,
    reference: dict[str, Track],
    reference_end: float | None,
    controlled: set[str],
) -> None:
    """Fill the comparison fields of `result`: per entity the RMSE over the common time span and the final
    position error (`track_error`), the end time, and both agreement rules (`agreed`: RMSE ≤ RMSE_LIMIT and
    end ±END_LIMIT; `agreed_final`: final positions ≤ FINAL_LIMIT and end ±FINAL_END_LIMIT). Entities in
    `controlled` are reported but decide neither."""
    if reference_end is None:
        reference_end = max((row[0] for rows in reference.values() for row in rows), default=0.0)
    result.reference_end = reference_end
    if not result.loaded:
        return
    result.end_error = abs(result.sim_seconds - reference_end)
    worst: tuple[float, str] | None = None
    for name, ours in trace.tracks.items():
        scripted = name not in controlled
        theirs = reference.get(name)
        if theirs is None:
            result.entities.append(EntityResult(name, scripted, None, 0))
            continue
        rmse, final, count = track_error(ours, theirs)
        if scripted and final is not None:
            result.final_error = max(result.final_error or 0.0, final)
        result.entities.append(EntityResult(name, scripted, rmse, count, final))
        if scripted and rmse is not None and (worst is None or rmse > worst[0]):
            worst = (rmse, name)
    # a scripted entity both runs have but at no common time disagrees
    missing = [e.name for e in result.entities if e.scripted and e.rmse is None and e.name in reference]
    if worst is not None:
        result.max_rmse, result.worst_entity = worst
    ran = result.ended and result.end_error is not None and not missing
    result.agreed = bool(
        ran
        and result.end_error is not None
        and result.end_error <= END_LIMIT + 1e-9
        and (worst is None or worst[0] <= RMSE_LIMIT)
    )
    result.agreed_final = bool(
        ran
        and result.end_error is not None
        and result.end_error <= FINAL_END_LIMIT + 1e-9
        and (result.final_error is None or result.final_error <= FINAL_LIMIT)
    )
    if missing and not result.message:
        result.message = f"not in CARLOS' run at the reference's times: {', '.join(sorted(missing))}"


# --- the whole directory -----------------------------------------------------------------------------------


def _one(args: tuple[str, str | None, float, float | None, str | None]) -> ScenarioResult:
    file, reference_dir, cap, reference_end, esmini = args
    path = Path(file)
    result, trace = run_scenario(path, cap)
    if result.kind != "scenario":
        return result
    controlled = trace.controlled if trace.controlled is not None else set()
    if esmini is not None:
        from simcore.reference_player import run_esmini

        played = run_esmini(Path(esmini), path, step=STEP_SECONDS)
        if played.ok:
            result.reference = "esmini"
            compare(result, trace, played.tracks, played.end, controlled)
        else:
            result.reference_message = played.message
    elif reference_dir is not None:
        ref_path = Path(reference_dir) / reference_name(path)
        if ref_path.is_file():
            result.reference = ref_path.name
            compare(result, trace, read_reference(ref_path), reference_end, controlled)
    return result


def run_directory(
    directory: Path,
    reference_dir: Path | None = None,
    *,
    cap_seconds: float = DEFAULT_CAP_SECONDS,
    jobs: int = 1,
    include: list[str] | None = None,
    on_result: Callable[[ScenarioResult], None] | None = None,
    esmini: Path | None = None,
) -> list[ScenarioResult]:
    return run_files(
        scenario_files(directory, include),
        reference_dir,
        cap_seconds=cap_seconds,
        jobs=jobs,
        on_result=on_result,
        esmini=esmini,
    )


def run_files(
    files: list[Path],
    reference_dir: Path | None = None,
    *,
    cap_seconds: float = DEFAULT_CAP_SECONDS,
    jobs: int = 1,
    on_result: Callable[[ScenarioResult], None] | None = None,
    esmini: Path | None = None,
) -> list[ScenarioResult]:
    """Run `files` and compare each with its reference: the CSV in `reference_dir`, or — with `esmini` — what
    the esmini player makes of the same file (differential testing)."""
    ends = reference_end_times(reference_dir) if reference_dir is not None else {}
    tasks = [
        (
            str(f),
            str(reference_dir) if reference_dir else None,
            cap_seconds,
            ends.get(reference_name(f)),
            str(esmini) if esmini else None,
        )
        for f in files
    ]
    results: list[ScenarioResult] = []
    if jobs <= 1:
        for task in tasks:
            r = _one(task)
            results.append(r)
            if on_result:
                on_result(r)
    else:
        from concurrent.futures import ProcessPoolExecutor

        # one scenario per worker task; libsumo holds one simulation per process, so processes, not threads
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for r in pool.map(_one, tasks):
                results.append(r)
                if on_result:
                    on_result(r)
    return results


def totals(results: list[ScenarioResult]) -> dict[str, Any]:
    scenarios = [r for r in results if r.kind == "scenario"]
    with_reference = [r for r in scenarios if r.reference is not None]
    ended = [r for r in scenarios if r.ended]
    return {
        "files": len(results),
        "scenarios": len(scenarios),
        "loaded": sum(r.loaded for r in scenarios),
        "ended": len(ended),
        "with_reference": len(with_reference),
        "agreed": sum(r.agreed for r in with_reference),
        # the catalogue rule: final positions within FINAL_LIMIT m, end within FINAL_END_LIMIT s
        "agreed_final": sum(r.agreed_final for r in with_reference),
        # agreed scenarios in which no scripted entity was compared (every entity controller-driven): they
        # agree on the end time only
        "agreed_end_time_only": sum(
            r.agreed and not any(e.scripted and e.rmse is not None for e in r.entities)
            for r in with_reference
        ),
        "sim_seconds": round(sum(r.sim_seconds for r in scenarios), 2),
        "wall_seconds": round(sum(r.wall_seconds for r in scenarios), 2),
        "warnings": sum(len(r.warnings) for r in scenarios),
    }


def relative_name(result: ScenarioResult, base: Path) -> str:
    try:
        return str(Path(result.file).resolve().relative_to(base.resolve()))
    except ValueError:
        return result.file


def totals_line(results: list[ScenarioResult]) -> str:
    """One sentence with the totals (the CLI's last line, the Markdown table's first)."""
    t = totals(results)
    return (
        f"{t['scenarios']} scenarios · loaded {t['loaded']} · ran to their own end {t['ended']} · "
        f"agreed {t['agreed']} of {t['with_reference']} with a reference "
        f"({t['agreed_end_time_only']} of them on the end time only: every entity controller-driven) "
        f"(RMSE ≤ {RMSE_LIMIT} m, end ±{END_LIMIT} s) · agreed {t['agreed_final']} by final positions "
        f"(≤ {FINAL_LIMIT} m, end ±{FINAL_END_LIMIT} s) · {t['sim_seconds']:.0f} simulated s in "
        f"{t['wall_seconds']:.1f} s · {t['warnings']} warnings"
    )


def markdown(results: list[ScenarioResult], base: Path) -> str:
    """The totals and one table row per file, as Markdown (what the README embeds)."""
    lines = [
        f"Totals: {totals_line(results)}.",
        "",
        "| scenario | status | end s (CARLOS / reference) | max RMSE m | worst entity | agreed |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        name = relative_name(r, base)
        status = r.status if r.kind == "scenario" else f"{r.kind} (not run)"
        if r.status in ("bad_input", "error") and r.message:
            message = r.message.replace(r.file, name)  # the file is the row's first cell
            status += ": " + (message[:100] + "…" if len(message) > 100 else message)
        end = f"{r.sim_seconds:.2f} / {'—' if r.reference_end is None else f'{r.reference_end:.2f}'}"
        rmse = "" if r.max_rmse is None else f"{r.max_rmse:.3f}"
        agreed = "yes" if r.agreed else ("" if r.reference is None else "no")
        cells = [name, status, end if r.loaded else "", rmse, r.worst_entity or "", agreed]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def write_results(results: list[ScenarioResult], out: Path, base: Path) -> None:
    """CSV (one row per file), JSON (rows, entities and totals) or Markdown (totals and table), by suffix."""
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix == ".md":
        out.write_text(markdown(results, base))
        return
    if out.suffix == ".json":
        payload = {
            "totals": totals(results),
            "limits": {"rmse_m": RMSE_LIMIT, "end_s": END_LIMIT, "step_s": STEP_SECONDS},
            "scenarios": [{**asdict(r), "file": relative_name(r, base)} for r in results],
        }
        out.write_text(json.dumps(payload, indent=1) + "\n")
        return
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(
        [
            "file",
            "kind",
            "status",
            "loaded",
            "ended",
            "sim_s",
            "ref_end_s",
            "end_error_s",
            "max_rmse_m",
            "worst_entity",
            "agreed",
            "agreed_final",
            "final_error_m",
            "wall_s",
            "warnings",
            "message",
        ]
    )
    for r in results:
        writer.writerow(
            [
                relative_name(r, base),
                r.kind,
                r.status,
                int(r.loaded),
                int(r.ended),
                f"{r.sim_seconds:.2f}",
                "" if r.reference_end is None else f"{r.reference_end:.2f}",
                "" if r.end_error is None else f"{r.end_error:.2f}",
                "" if r.max_rmse is None else f"{r.max_rmse:.3f}",
                r.worst_entity or "",
                int(r.agreed),
                int(r.agreed_final),
                "" if r.final_error is None else f"{r.final_error:.3f}",
                f"{r.wall_seconds:.3f}",
                len(r.warnings),
                r.message,
            ]
        )
    out.write_text(buffer.getvalue())


def iter_rows(results: list[ScenarioResult], base: Path) -> Iterator[list[str]]:
    for r in results:
        yield [
            relative_name(r, base),
            r.status,
            f"{r.sim_seconds:.2f}" if r.loaded else "",
            "" if r.reference_end is None else f"{r.reference_end:.2f}",
            "" if r.max_rmse is None else f"{r.max_rmse:.2f}",
            "yes" if r.agreed else ("" if r.reference is None else "no"),
            _short(r.message or r.reference_message),
        ]


def _short(message: str) -> str:
    return (message[:90] + "…") if len(message) > 90 else message


# --- what `carlos run` recorded ----------------------------------------------------------------------------


def recording_offset(metadata: dict[str, dict[str, str]]) -> float:
    """The scenario-time offset a recording's `carlos.run` metadata names (0 when absent: older recordings,
    no FollowGhost)."""
    try:
        return float(metadata.get("carlos.run", {}).get("scenarioTimeOffsetSeconds", "0"))
    except ValueError:
        return 0.0


def recording_tracks(mcap: Path, period: float = REFERENCE_PERIOD) -> tuple[dict[str, Track], float]:
    """(ROS entity name → [(scenario time, x, y)] every `period` s, scenario-time offset) from the
    `/carlos/<entity>/odometry` messages of a `carlos run` recording; scenario time = stamp + offset."""
    from mcap.reader import make_reader

    from simcore.transport.messages import deserialize

    with mcap.open("rb") as handle:
        reader = make_reader(handle)
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
        offset = recording_offset(metadata)
        summary = reader.get_summary()
        channels = summary.channels.values() if summary is not None else ()
        topics = [c.topic for c in channels if c.topic.endswith("/odometry") and c.topic.count("/") == 3]
        tracks: dict[str, Track] = {}
        for schema, channel, message in reader.iter_messages(topics=topics) if topics else ():
            topic = channel.topic
            if schema is None:
                continue
            stamp = message.log_time / 1e9
            if abs(stamp / period - round(stamp / period)) > 1e-6:
                continue
            position = deserialize(message.data, schema.name).pose.pose.position
            name = topic.split("/")[2]
            tracks.setdefault(name, []).append(
                (round(stamp + offset, 6), float(position.x), float(position.y))
            )
    return tracks, offset


def recorded_run(
    index_dir: Path, file: str, names: set[str] | frozenset[str] = frozenset()
) -> tuple[ScenarioResult, Trace]:
    """What `carlos run` wrote for one index (`<output>/<run>/<index>/`: summary.json, recording.mcap) as a
    conformance result and trace on the scenario's time axis: status, end time (simSeconds + the scenario-
    time offset), and every entity's odometry, by its name in `names` where its ROS name matches one."""
    from simcore.transport.messages import ros_name

    result = ScenarioResult(file=file, kind="scenario")
    trace = Trace()
    summary = json.loads((index_dir / "summary.json").read_text())
    if summary.get("error"):
        result.status = "bad_input" if summary.get("badInput") else "error"
        result.message = str(summary["error"])
        return result, trace
    recording = index_dir / "recording.mcap"
    tracks, offset = recording_tracks(recording) if recording.is_file() else ({}, 0.0)
    offset = float(summary.get("scenarioTimeOffsetSeconds", offset))
    result.loaded = True
    result.ended = summary.get("endReason") == "stopTrigger"
    result.status = "ended" if result.ended else "capped"
    result.sim_seconds = float(summary["simSeconds"]) + offset
    result.wall_seconds = float(summary.get("wallSeconds", 0.0))
    back = {ros_name(n): n for n in names}
    trace.tracks = {back.get(k, k): v for k, v in tracks.items()}
    return result, trace
