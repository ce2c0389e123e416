"""The commands of `carlos` (a typer app). simcore.cli.main runs it; bad input ends in one clear line and exit
code 2, never a traceback. Imported only when a command runs (not by the worker processes a run spawns, which
start from simcore.cli)."""

# Annotations are evaluated as the module loads (no `from __future__ import annotations`): typer reads
# every command's parameters at each start, and string annotations would be compiled one by one (~25 ms).
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
import typer.main
from rich.console import Console
from rich.table import Table
from rich.text import Text
from typer.core import TyperGroup

from simcore import startup as entry  # the collector's pause (entry.resume_gc: looked up there, at each call)
from simcore.errors import BadInput, CarlosError, ExitCode, SimulationError, shorten
from simcore.wording import plural
from simcore.workflow import commands as workflow
from simcore.workflow import compare as workflow_compare

if TYPE_CHECKING:
    from typer.core import _click  # typer's click (vendored in typer >= 0.29); annotations only

    from simcore.transport.bus import Bus

COMMAND_ENTRY_POINTS = "carlos.commands"


class _Commands(TyperGroup):
    """simcore's commands, plus those other installed packages provide as `carlos.commands` entry points
    (`carlos operator`, `carlos crds` from carlos_operator): one is imported only when it is run or listed."""

    def _plugins(self) -> dict[str, Any]:
        from importlib.metadata import entry_points

        return {ep.name: ep for ep in entry_points(group=COMMAND_ENTRY_POINTS)}

    def format_commands(self, ctx: "_click.Context", formatter: "_click.HelpFormatter") -> None:
        """Each command with its first sentence whole (click would cut it to the terminal's width)."""
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command.get_short_help_str(limit=1_000)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def list_commands(self, ctx: "_click.Context") -> list[str]:
        return sorted({*super().list_commands(ctx), *self._plugins()})

    def get_command(self, ctx: "_click.Context", cmd_name: str) -> "_click.Command | None":
        if cmd_name != "run":  # `carlos run` resumes the collector itself, after its start-up
            entry.resume_gc()
        command = super().get_command(ctx, cmd_name)
        if command is not None:
            return command
        entry_point = self._plugins().get(cmd_name)
        if entry_point is None:
            return None
        loaded = entry_point.load()
        command = typer.main.get_command(loaded) if isinstance(loaded, typer.Typer) else loaded
        command.name = cmd_name
        return command


app = typer.Typer(
    cls=_Commands,
    name="carlos",
    help="CARLOS: simulation runs for cooperative intelligent transport systems, locally or on Kubernetes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # click's plain help: it wraps at word boundaries and never cuts a field name or URL short ("…"), as
    # rich's help panels do in an 80-column terminal
    rich_markup_mode=None,
)
# no emoji codes: the messages hold file, run and entity names (`:x:` stays `:x:`; nor is rich's emoji table
# loaded for the report table)
console = Console(stderr=True, emoji=False)
out = Console(emoji=False)


def _print_version(value: bool) -> None:
    if value:
        from simcore import DISTRIBUTION, compiled, version

        build = "compiled" if compiled() else "pure Python"
        out.print(Text(f"carlos {version()} ({DISTRIBUTION}, {build})"), highlight=False)
        raise typer.Exit(0)


@app.callback()
def _main(
    show_version: Annotated[
        bool,
        typer.Option("--version", callback=_print_version, is_eager=True, help="Print the version and exit."),
    ] = False,
) -> None:
    """CARLOS: simulation runs for cooperative intelligent transport systems, locally or on Kubernetes."""


def _line(label: str, style: str, text: object) -> Text:
    """`label text` with the label styled and the text literal: file names, entity names and messages are
    user-controlled, so never read as rich markup (`[/x]`) or emoji codes (`:100:`)."""
    return Text.assemble((label, style), " ", str(text))


def _fail(exc: CarlosError) -> typer.Exit:
    console.print(_line("error:", "bold red", exc), highlight=False, soft_wrap=True)
    return typer.Exit(int(exc.exit_code))


@app.command()
def run(
    manifest: Annotated[Path, typer.Argument(help="SimulationRun manifest (YAML).")],
    output: Annotated[
        str | None,
        typer.Option("--output", "-o", help="Output URL (file://… or s3://…); overrides spec.output.url."),
    ] = None,
    parallel: Annotated[
        int | None,
        typer.Option(
            "--parallel",
            "-j",
            min=1,
            help="Worker processes (default: spec.execution.parallelism, else the number of cores).",
        ),
    ] = None,
    index: Annotated[
        list[int] | None, typer.Option("--index", "-i", help="Run only these indexes (repeatable).")
    ] = None,
    repeat: Annotated[
        int | None,
        typer.Option(
            "--repeat",
            min=1,
            max=100,
            help="Run every point this many times to find flaky runs (overrides spec.execution.repeat).",
        ),
    ] = None,
    fresh: Annotated[
        bool, typer.Option("--fresh", help="Replace existing results of this run instead of resuming.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    live: Annotated[
        bool,
        typer.Option(
            "--live",
            help="Serve the run live (Foxglove WebSocket on 127.0.0.1), paced to real time; the index runs "
            "again even if it has finished.",
        ),
    ] = False,
    live_port: Annotated[
        int, typer.Option("--live-port", min=0, max=65535, help="Port of the live view.")
    ] = 8765,
    live_speed: Annotated[
        float,
        typer.Option(
            "--live-speed",
            min=0.0,
            help="Simulated seconds per wall second of the live view (0: as fast as possible).",
        ),
    ] = 1.0,
    transport: Annotated[
        str,
        typer.Option(
            "--transport",
            help=(
                "How nodes in other processes reach the run's topics (one run, e.g. a closed-loop "
                "controller): `none` (default), `loopback` (a topic hub on 127.0.0.1:--bus-port, "
                "simcore.transport.loopback.LoopbackBus clients) or `dds` (ROS 2 topics on DDS: ROS 2 "
                "nodes with RMW_IMPLEMENTATION=rmw_cyclonedds_cpp on the same domain see them; "
                "configuration from CYCLONEDDS_URI, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keeps them on "
                "this host)."
            ),
        ),
    ] = "none",
    bus_port: Annotated[
        int, typer.Option("--bus-port", min=0, max=65535, help="Port of the loopback topic hub.")
    ] = 7447,
    ros_domain_id: Annotated[
        int | None,
        typer.Option(
            "--ros-domain-id",
            min=0,
            max=232,
            help="DDS domain of --transport dds (default: ROS_DOMAIN_ID, else 0).",
        ),
    ] = None,
) -> None:
    """Run every scenario × permutation of a SimulationRun on this machine.

    Exit codes: 0 every required run passed, 1 a required test failed, 2 bad input, 3 infrastructure error."""
    from simcore.executor import Events, execute
    from simcore.manifest import load_manifest
    from simcore.plan import Plan

    server = None
    hub = None
    try:
        simulation_run = load_manifest(manifest)
        if repeat is not None:
            spec = simulation_run.spec
            execution = spec.execution.model_copy(update={"repeat": repeat})
            simulation_run = simulation_run.model_copy(
                update={"spec": spec.model_copy(update={"execution": execution})}
            )
        total = len(Plan(simulation_run.spec))
        _preflight(simulation_run, manifest)
        live = live or simulation_run.spec.live
        if transport not in ("none", "loopback", "dds"):
            raise BadInput(f"unknown transport {transport!r}: use none, loopback or dds", field="--transport")
        if ros_domain_id is not None and transport != "dds":
            raise BadInput("--ros-domain-id is for --transport dds", field="--ros-domain-id")
        from simcore.checks import check_controller_reachable

        check_controller_reachable(simulation_run.spec, transport, str(manifest))
        bus: Bus | None = None
        for flag, wanted in (("--live", live), ("--transport", transport != "none")):
            selected = len(set(index)) if index else total
            if wanted and selected != 1:
                raise BadInput(
                    f"{flag} serves one run, and this selects {selected}: choose one with --index N",
                    field=flag if flag != "--live" or not simulation_run.spec.live else "spec.live",
                )
        if transport == "loopback":
            from simcore.transport.loopback import LoopbackBus, LoopbackHub

            try:
                hub = LoopbackHub(port=bus_port).start()
            except OSError as exc:
                raise BadInput(
                    f"cannot serve the topic hub on 127.0.0.1:{bus_port}: {exc}", field="--bus-port"
                ) from None
            bus = LoopbackBus(port=hub.port)
            console.print(f"topics: loopback hub on 127.0.0.1:{hub.port}", highlight=False)
        elif transport == "dds":
            bus = _dds_bus(ros_domain_id)
        if live:
            from simcore.live import LiveServer
            from simcore.transport.bus import InProcessBus

            server = LiveServer(port=live_port, speed=live_speed).start()
            bus = bus if bus is not None else InProcessBus()
            bus.subscribe("*", server)
            console.print(
                f"live view: {server.url} (Foxglove: Open connection → Foxglove WebSocket; "
                "layout examples/live/foxglove-layout.json)",
                highlight=False,
                soft_wrap=True,
            )
        progress = _progress(
            disable=quiet or (not console.is_terminal and os.environ.get("CARLOS_PROGRESS") != "1")
        )
        from simcore.workflow.terminal import ProgressLines

        lines = None if quiet or not progress.disable else ProgressLines(simulation_run.name, _plain)
        state = {"passed": 0, "failed": 0, "errors": 0, "sim": 0.0}
        live_sim: dict[int, float] = {}
        started = time.monotonic()

        def stats() -> str:
            wall = max(time.monotonic() - started, 1e-6)
            sim = state["sim"] + sum(live_sim.values())
            return f"passed {state['passed']:.0f} failed {state['failed']:.0f} errors {state['errors']:.0f} · {sim / wall:,.0f} sim-s/wall-s"

        task = progress.add_task(simulation_run.name, total=total, stats="")

        def on_start(count: int, skipped: int) -> None:
            progress.update(task, total=count, completed=skipped, stats=stats())
            if lines is not None:
                lines.start(count, skipped)
            if skipped:
                console.print(
                    f"resuming: {skipped} of {plural(count, 'run')} already complete (use --fresh to rerun them)"
                )

        def on_progress(i: int, sim_time: float) -> None:
            entry.resume_gc()  # a run is under way (its imports and set-up done): garbage is collected again
            live_sim[i] = sim_time
            progress.update(task, stats=stats())

        def on_done(outcome: object) -> None:
            entry.resume_gc()  # at the latest when the first run ends (one that failed before any progress)
            summary = outcome.summary  # type: ignore[attr-defined]
            live_sim.pop(summary["index"], None)
            state["sim"] += summary.get("simSeconds", 0.0)
            key = {"passed": "passed", "failed": "failed"}.get(summary["status"], "errors")
            state[key] += 1
            progress.update(task, advance=1, stats=stats())
            if lines is not None:
                lines.index_done(summary["status"])
            if summary["status"] == "error" and bus is not None and not progress.live.is_started:
                # one run with other processes on its topics: say why it failed (a controller died, …)
                console.print(
                    Text(f"index {summary['index']}: {summary['error']}"), highlight=False, soft_wrap=True
                )
                return
            if quiet or not progress.live.is_started:
                return
            if summary["status"] == "error":
                progress.console.print(
                    Text(f"index {summary['index']} ({summary['scenario']}): {summary['error']}", "red"),
                    highlight=False,
                )

        def on_retry(i: int, attempt: int, reason: str) -> None:
            progress.console.print(
                Text(f"index {i}: attempt {attempt} failed ({reason}); retrying", "yellow"), highlight=False
            )

        with progress:
            if simulation_run.spec.search is not None:
                entry.resume_gc()
                report = _search(simulation_run, manifest, output, parallel, fresh or bool(index) or live)
                _print_report(report)
                raise typer.Exit(report.exit_code)
            report = execute(
                simulation_run,
                base_dir=manifest.parent.resolve(),
                output_url=output,
                parallel=parallel,
                fresh=fresh or live,  # a live view runs its index again: a finished one is not resumed
                indexes=list(index) if index else None,
                events=Events(on_start=on_start, on_progress=on_progress, on_done=on_done, on_retry=on_retry),
                bus=bus,
            )
    except CarlosError as exc:
        raise _fail(exc) from None
    except KeyboardInterrupt:
        console.print("interrupted: completed runs are kept; run the same command again to resume")
        raise typer.Exit(130) from None
    finally:
        if server is not None:
            server.stop()
        if hub is not None:
            hub.close()
    _record_scenario_digests(simulation_run, manifest, report.output_url)
    _print_report(report)
    raise typer.Exit(report.exit_code)


def _record_scenario_digests(simulation_run: Any, manifest: Path, run_url: str) -> None:
    """The SHA-256 of every local scenario file next to run.yaml (`carlos compare` lists changed ones)."""
    from simcore.spec_diff import SCENARIO_DIGESTS_KEY, scenario_digests
    from simcore.store import open_store

    try:
        files = {
            s.name: (str(s.openscenario), path) for _, s, path in _local_scenarios(simulation_run, manifest)
        }
        data = json.dumps(scenario_digests(files), indent=2, sort_keys=True) + "\n"
        open_store(run_url).put_bytes(SCENARIO_DIGESTS_KEY, data.encode())
    except (CarlosError, OSError, ValueError) as exc:  # the run's verdict stands; compare will not know them
        console.print(_line("note:", "yellow", f"scenario file digests not stored: {exc}"), highlight=False)


class _NotLive:
    is_started = False


class _NoProgress:
    """What `carlos run` uses of rich's Progress when no bar is shown (quiet, or not a terminal): rich.progress
    is then not imported (~15 ms of start-up)."""

    disable = True

    def __init__(self) -> None:
        self.console = console
        self.live = _NotLive()

    def __enter__(self) -> "_NoProgress":
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def add_task(self, description: str, **fields: Any) -> int:
        return 0

    def update(self, task: int, **fields: Any) -> None:
        return None


def _progress(*, disable: bool) -> Any:
    """The progress bar of `carlos run` on the console (rich), or _NoProgress when none is shown."""
    if disable:
        return _NoProgress()
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[stats]}"),
        TimeElapsedColumn(),
        console=console,
    )


def _plain(line: str) -> None:
    console.print(line, highlight=False, soft_wrap=True, markup=False)


def _dds_bus(domain_id: int | None) -> "Bus":
    """The run's DDS bus (`--transport dds`): ROS_DOMAIN_ID unless --ros-domain-id, configured as a ROS 2
    node with rmw_cyclonedds_cpp would be in this environment (simcore.transport.dds_config)."""
    from simcore.transport.dds_config import config_from_env, describe, domain_id_from_env

    domain = domain_id_from_env() if domain_id is None else domain_id
    try:
        from simcore.transport.dds import DdsBus, DdsError
    except ImportError as exc:  # cyclonedds is a dependency; a broken install is the machine's problem
        raise SimulationError(f"--transport dds: cyclonedds cannot be imported: {exc}") from None
    config = config_from_env()
    try:
        bus = DdsBus(domain, config=config)
    except DdsError as exc:
        if os.environ.get("CYCLONEDDS_URI", "").strip():
            raise BadInput(f"{exc}", field="CYCLONEDDS_URI") from None
        raise SimulationError(f"--transport dds: {exc}") from None
    console.print(f"topics: {describe(domain)}", highlight=False, soft_wrap=True)
    return bus


def _local_scenarios(simulation_run: object, manifest: Path) -> list[tuple[int, Any, Path]]:
    """(position, scenario reference, file) of every scenario the manifest names on this machine; ConfigMaps
    (cluster) and s3:// objects are checked by the run itself. A named file that is missing is bad input."""
    from simcore.spec import SimulationRun

    assert isinstance(simulation_run, SimulationRun)
    base_dir = manifest.parent.resolve()
    found = []
    for position, scenario in enumerate(simulation_run.spec.scenarios):
        source = scenario.openscenario
        if source is None or source.startswith("s3://"):
            continue
        path = Path(
            os.path.normpath(
                Path(source.removeprefix("file://")).expanduser()
                if source.startswith("file://")
                else base_dir / source
            )
        )
        if not path.is_file():
            raise BadInput(
                f"scenario file {str(path)!r} not found",
                file=str(manifest),
                field=f"spec.scenarios[{position}].openscenario",
            )
        found.append((position, scenario, path))
    return found


def _preflight(simulation_run: object, manifest: Path) -> None:
    """Check what can be checked before any worker starts, so a typo fails at once with exit code 2: every
    local scenario file parses with the first permutation's parameters (all matrix, spec and scenario
    parameter names declared, every manifest value of the declared type, every element supported) and its
    road network file is one and parses safely (simcore.preflight)."""
    from simcore.spec import SimulationRun

    assert isinstance(simulation_run, SimulationRun)
    try:
        _preflight_scenarios(simulation_run, manifest)
    except OSError as exc:  # a path the file system refuses (too long, a loop, no permission)
        raise BadInput(
            f"cannot read {shorten(str(exc.filename))!r}: {exc.strerror or exc}", file=str(manifest)
        ) from None


def _preflight_scenarios(simulation_run: Any, manifest: Path) -> None:
    from simcore.checks import check_criteria_metrics, check_system_under_test
    from simcore.plan import Plan
    from simcore.preflight import check_parameter_types, check_road_file
    from simcore.scenario.xosc import load_scenario, parameter_declarations

    spec = simulation_run.spec
    check_criteria_metrics(spec, str(manifest))
    check_system_under_test(spec, manifest.parent.resolve(), str(manifest))
    plan = Plan(spec)
    for position, scenario, path in _local_scenarios(simulation_run, manifest):
        declared = parameter_declarations(path)
        names = {**spec.parameters, **scenario.parameters, **spec.sweep.matrix}
        unknown = sorted(set(names) - set(declared))
        if unknown:
            where = (
                "spec.sweep.matrix"
                if set(unknown) & set(spec.sweep.matrix)
                else f"spec.scenarios[{position}].parameters"
                if set(unknown) & set(scenario.parameters)
                else "spec.parameters"
            )
            raise BadInput(
                f"parameter(s) {', '.join(unknown)} not declared in {path.name} "
                f"(declared: {', '.join(sorted(declared)) or 'none'})",
                file=str(manifest),
                field=where,
            )
        check_parameter_types(spec, position, declared, source=str(manifest))
        if spec.search is not None:
            from simcore.search.driver import search_space

            search_space(simulation_run, path)
            continue
        parsed = load_scenario(path, plan.sweep_point(plan.indexes_of(scenario.name).start).parameters)
        if parsed.road_file is not None:
            check_road_file(parsed.road_file, scenario_file=str(path))


def _initial_states(simulation_run: Any, manifest: Path) -> None:
    """`carlos validate` goes on where a run would: each local scenario's initial state is built (nothing
    stepped), so what a run rejects only there is rejected here too (simcore.preflight.check_initial_states).
    A search's points are chosen while it runs: its scenarios are checked by their parse only."""
    from simcore.preflight import check_initial_states

    if simulation_run.spec.search is not None:
        return
    for position, _scenario, path in _local_scenarios(simulation_run, manifest):
        check_initial_states(simulation_run, position, path, source=str(manifest))


def _search(
    simulation_run: Any, manifest: Path, output: str | None, parallel: int | None, selective: bool
) -> Any:
    """`carlos run` of a manifest with spec.search: the search's rounds; returns the final RunReport."""
    from simcore.search.driver import run_search

    if selective:
        raise BadInput(
            "a search runs all its rounds: --index, --fresh and --live are for sweeps", field="spec.search"
        )
    found = _local_scenarios(simulation_run, manifest)
    if not found:
        raise BadInput(
            "a search runs a local scenario file (not a ConfigMap or s3://)", field="spec.scenarios"
        )
    result = run_search(
        simulation_run,
        base_dir=manifest.parent.resolve(),
        scenario_file=found[0][2],
        output_url=output,
        parallel=parallel,
        on_round=lambda d: console.print(
            f"round {d['rounds'][-1]['round']}: {plural(d['runs'], 'run')}, {d['failures']} failing",
            highlight=False,
        ),
    )
    document = result.document
    best = document["best"]
    out.print(
        f"search: {plural(document['runs'], 'run')} in {plural(len(document['rounds']), 'round')} · "
        f"{document['failures']} failing · "
        f"best {document['objective']['metric']} "
        f"{'n/a' if best is None else format(best['objective'], '.3g')}"
        + (f" · failing points: {document['failingScenarios']}" if "failingScenarios" in document else ""),
        highlight=False,
        soft_wrap=True,
    )
    return result.run


def _print_report(report: object) -> None:
    from simcore.executor import RunReport

    assert isinstance(report, RunReport)
    summary = report.summary
    table = Table(title=f"SimulationRun {report.run_name}", show_edge=False)
    table.add_column("scenario")
    table.add_column("runs", justify="right")
    table.add_column("passed", justify="right", style="green")
    table.add_column("failed", justify="right", style="red")
    table.add_column("errors", justify="right", style="red")
    table.add_column("optional")
    optional = {s.name for s in report.optional_scenarios}
    for name, scenario in summary.get("scenarios", {}).items():
        counts = scenario.get("counts", {})
        table.add_row(
            name,
            str(counts.get("runs", 0)),
            str(counts.get("passed", 0)),
            str(counts.get("failed", 0)),
            str(counts.get("errors", 0)),
            "yes" if name in optional else "",
        )
    out.print(table)
    from simcore.workflow.terminal import failure_lines

    for line in failure_lines(list(report.outcomes.values())):
        out.print(line, highlight=False, soft_wrap=True, markup=False)
    status = summary["status"]
    colour = "green" if status == "passed" else "red"
    out.print(
        Text.assemble(
            (status, f"bold {colour}"),
            f" · {plural(summary['counts']['total'], 'run')} in {report.wall_seconds:.1f} s "
            f"({report.skipped} resumed) · results: {report.output_url}",
        ),
        highlight=False,
        soft_wrap=True,
    )
    if report.report_url is not None:
        out.print(f"report: {report.report_url}", highlight=False, soft_wrap=True)
    else:
        console.print(f"report.html not written: {report.report_error}", highlight=False, soft_wrap=True)


@app.command()
def validate(
    manifest: Annotated[
        Path,
        typer.Argument(help="SimulationRun manifest (YAML), or OpenSCENARIO files (.xosc) with --schema."),
    ],
    more: Annotated[list[Path] | None, typer.Argument(help="More .xosc files (with --schema).")] = None,
    schema: Annotated[
        bool,
        typer.Option(
            "--schema",
            help="Also check every local scenario against the official ASAM XSD of the revision it declares "
            "(1.0–1.3); violations are listed with their line and fail the check (exit 2).",
        ),
    ] = False,
) -> None:
    """Check a manifest and its scenarios without running anything."""
    from simcore.manifest import load_manifest
    from simcore.plan import Plan

    files = [manifest, *(more or [])]
    if any(f.suffix == ".xosc" for f in files):
        if not schema or not all(f.suffix == ".xosc" for f in files):
            raise _fail(
                BadInput(
                    "OpenSCENARIO files are checked against the XSD: carlos validate FILE.xosc [FILE.xosc …] "
                    "--schema (a manifest is validated on its own)",
                    field="FILE",
                )
            )
        raise typer.Exit(_check_schemas(files))
    if more:
        raise _fail(BadInput("one manifest at a time", field="MANIFEST"))
    try:
        simulation_run = load_manifest(manifest)
        _preflight(simulation_run, manifest)
        _initial_states(simulation_run, manifest)
        paths = [path for _, _, path in _local_scenarios(simulation_run, manifest)] if schema else []
    except CarlosError as exc:
        raise _fail(exc) from None
    if schema and _check_schemas(list(dict.fromkeys(paths))) != 0:
        raise typer.Exit(int(ExitCode.BAD_INPUT))
    plan = Plan(simulation_run.spec)
    search = simulation_run.spec.search
    out.print(
        Text(
            f"{manifest}: valid · {plural(len(plan), 'run')} "
            f"({plural(len(simulation_run.spec.scenarios), 'scenario')} × {plan.per_scenario})"
            if search is None
            else f"{manifest}: valid · a {search.strategy} search of {plural(search.budget, 'run')} "
            f"in rounds of {search.batch_size}"
        ),
        highlight=False,
        soft_wrap=True,
    )


def _check_schemas(paths: list[Path]) -> int:
    """Print each file's XSD verdict and its violations; 0 when all are valid, else 2 (bad input)."""
    from simcore.scenario.schema import check_openscenario

    invalid = 0
    for path in paths:
        try:
            report = check_openscenario(path)
        except CarlosError as exc:
            console.print(_line("error:", "bold red", exc), highlight=False, soft_wrap=True)
            invalid += 1
            continue
        note = f" ({report.note})" if report.note else ""
        if report.valid:
            out.print(
                Text(f"{path}: valid against OpenSCENARIO {report.version} XSD{note}"),
                highlight=False,
                soft_wrap=True,
            )
            continue
        invalid += 1
        more = " (first ones)" if report.truncated else ""
        console.print(
            Text.assemble(
                (str(path), "bold red"),
                f": {len(report.issues)} violation(s){more} of the OpenSCENARIO {report.version} XSD{note}",
            ),
            highlight=False,
            soft_wrap=True,
        )
        for issue in report.issues:
            line = "?" if issue.line is None else issue.line
            console.print(
                f"  {path}:{line}: {issue.path}: {issue.reason}",
                highlight=False,
                soft_wrap=True,
                markup=False,
            )
    return int(ExitCode.BAD_INPUT) if invalid else 0


@app.command()
def plan(
    manifest: Annotated[Path, typer.Argument(help="SimulationRun manifest (YAML).")],
    index: Annotated[list[int] | None, typer.Option("--index", "-i", help="Show these indexes.")] = None,
    limit: Annotated[int, typer.Option(help="Show at most this many runs.")] = 20,
) -> None:
    """Show which scenario, parameters and seed each index runs (computed lazily, any sweep size)."""
    from simcore.manifest import load_manifest
    from simcore.plan import Plan, describe

    try:
        simulation_run = load_manifest(manifest)
    except CarlosError as exc:
        raise _fail(exc) from None
    search = simulation_run.spec.search
    if search is not None:  # its points are chosen while it runs: there is no plan to show
        out.print(
            Text(
                f"{simulation_run.name}: a search of {plural(search.budget, 'run')} in rounds of "
                f"{search.batch_size}, its points chosen as it runs (strategy {search.strategy}); each "
                "evaluated point is an index of the results"
            ),
            highlight=False,
        )
        return
    runs = Plan(simulation_run.spec)
    chosen = list(index) if index else list(range(min(limit, len(runs))))
    table = Table(title=f"{simulation_run.name}: {plural(len(runs), 'run')}", show_edge=False)
    for column in ("index", "scenario", "parameters", "seed"):
        table.add_column(column)
    for i in chosen:
        try:
            point = runs[i]
        except IndexError as exc:
            raise _fail(BadInput(str(exc), field="--index")) from None
        table.add_row(
            str(i), point.scenario.name, Text(describe(point.sweep_values) or "(defaults)"), str(point.seed)
        )
    out.print(table)


@app.command()
def schema() -> None:
    """Print the SimulationRun JSON schema (generated from the spec models)."""
    from simcore.spec import SimulationRun

    out.print_json(json.dumps(SimulationRun.model_json_schema(by_alias=True)))


@app.command()
def docs(
    page: Annotated[
        str,
        typer.Argument(
            help="fields (docs/simulationrun.md), cli (docs/reference/cli.md) or topics (docs/reference/topics.md)."
        ),
    ] = "fields",
) -> None:
    """Print a reference page generated from the code (Markdown): the SimulationRun fields from the spec models,
    the command line from this program's commands, or the topics and message types."""
    if page == "fields":
        from simcore.docs import reference

        sys.stdout.write(reference())
    elif page == "cli":
        from simcore.reference import cli_reference

        sys.stdout.write(cli_reference(app))
    elif page == "topics":
        from simcore.reference import topics_reference

        sys.stdout.write(topics_reference())
    else:
        raise _fail(BadInput(f"unknown page {shorten(page)!r}: fields, cli or topics", field="PAGE"))


@app.command()
def examples(
    directory: Annotated[
        Path, typer.Argument(help="Where to write: the files go to DIRECTORY/examples/.")
    ] = Path("."),
    force: Annotated[bool, typer.Option(help="Overwrite example files you changed.")] = False,
) -> None:
    """Write the example manifests, scenarios, maps and nodes (examples/) from the installed package, so that
    `carlos run examples/runs/prototyping.yaml` works from DIRECTORY. Unchanged files are kept; a changed one
    is refused (exit 2) unless --force."""
    from simcore.examples import write_examples

    try:
        result = write_examples(directory, force=force)
    except CarlosError as exc:
        raise _fail(exc) from None
    target = directory / "examples"
    out.print(
        Text(f"{target}: {len(result.write)} files written, {len(result.unchanged)} unchanged"),
        highlight=False,
    )
    where = "" if directory == Path(".") else f"cd {directory} && "
    out.print(Text(f"next: {where}carlos run examples/runs/prototyping.yaml"), highlight=False)


@app.command()
def pod(
    role: Annotated[str, typer.Option("--role", help="simcore, bridge or recorder.")],
) -> None:
    """Run one role of a SimulationRun pod (the Job's containers). Reads JOB_COMPLETION_INDEX, CARLOS_SPEC,
    CARLOS_OUTPUT_URL and the AWS_* environment. Exit codes as `carlos run`."""
    from simcore.pod import main as pod_main

    raise typer.Exit(pod_main(role))


@app.command()
def conformance(
    paths: Annotated[
        list[Path],
        typer.Argument(help="Scenario files, or directories searched recursively for .xosc scenarios."),
    ],
    reference: Annotated[
        Path | None,
        typer.Option(
            help="Reference trajectories (<folder>__<name>.csv.gz, e.g. the esmini corpus' reference/)."
        ),
    ] = None,
    against: Annotated[
        str | None,
        typer.Option(
            help="Compare with what a reference player makes of each same file (differential testing): "
            "esmini (found by --esmini, $ESMINI or PATH)."
        ),
    ] = None,
    esmini: Annotated[Path | None, typer.Option(help="The esmini binary for --against esmini.")] = None,
    out_file: Annotated[
        Path | None, typer.Option("--out", help="Write the table here: .csv or .json (by suffix).")
    ] = None,
    cap: Annotated[float, typer.Option(help="Simulated-time cap per scenario (s).", min=0.1)] = 1250.0,
    jobs: Annotated[int, typer.Option("--jobs", "-j", min=1, help="Worker processes.")] = 1,
    include: Annotated[
        list[str] | None,
        typer.Option(
            "--include", "-k", help="Only files whose relative path matches this glob (repeatable)."
        ),
    ] = None,
) -> None:
    """Run every scenario under PATHS headless (0.05 s steps) and compare with reference trajectories: the
    corpus' CSVs (--reference) or the esmini player run on the same files (--against esmini)."""
    from simcore import conformance as conf
    from simcore.reference_player import find_esmini

    files: list[Path] = []
    for path in paths:
        if path.is_dir():
            files.extend(conf.scenario_files(path, include))
        elif path.is_file():
            files.append(path)
        else:
            raise _fail(BadInput("no such file or directory", file=str(path)))
    directory = paths[0] if len(paths) == 1 and paths[0].is_dir() else _common_parent(files)
    if reference is not None and not reference.is_dir():
        raise _fail(BadInput("reference is not a directory", file=str(reference)))
    player: Path | None = None
    if against is not None:
        if against != "esmini":
            raise _fail(BadInput(f"unknown reference player {against!r} (known: esmini)", field="--against"))
        if esmini is not None and not (esmini.is_file() and os.access(esmini, os.X_OK)):
            raise _fail(BadInput("not an executable file", file=str(esmini), field="--esmini"))
        player = find_esmini(esmini)
        if player is None:
            raise _fail(CarlosError("no esmini binary: give --esmini PATH or set ESMINI=/path/to/esmini"))
    results = conf.run_files(files, reference, cap_seconds=cap, jobs=jobs, esmini=player)
    table = Table(title=f"conformance: {directory}", show_edge=False)
    for column in ("scenario", "status", "end s", "ref end s", "max RMSE m", "agreed", "message"):
        table.add_column(column, overflow="fold")
    for row in conf.iter_rows(results, directory):
        table.add_row(*row)
    out.print(table)
    out.print(conf.totals_line(results), highlight=False, soft_wrap=True)
    if out_file is not None:
        conf.write_results(results, out_file, directory)
        if out_file.suffix != ".json":
            conf.write_results(results, out_file.with_suffix(".json"), directory)


def _common_parent(files: list[Path]) -> Path:
    if not files:
        return Path(".")
    return Path(os.path.commonpath([str(f.resolve().parent) for f in files]))


for _command in (
    workflow.report,
    workflow.submit,
    workflow.get,
    workflow.watch,
    workflow.logs,
    workflow.results,
    workflow.export,
    workflow.rerun,
    workflow_compare.compare,
):
    app.command()(_command)
