"""Workflow commands of `carlos` (registered in simcore.cli). They raise CarlosError for bad input and
infrastructure errors; `simcore.cli.main` prints it as one line with its exit code."""

# Annotations are evaluated as the module loads (no `from __future__ import annotations`): typer reads
# every command's parameters at each start, and string annotations would be compiled one by one (~25 ms).
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from simcore.errors import BadInput

if TYPE_CHECKING:
    from simcore.results import RunResults
    from simcore.workflow.status import RunState


def report(
    results_url: Annotated[
        str, typer.Argument(help="The run's results: file://…/<run> or s3://bucket/prefix/<run>.")
    ],
    out_file: Annotated[
        Path | None,
        typer.Option(
            "--out", help="Write the HTML here (default: report.html next to the run's summary.json)."
        ),
    ] = None,
    worst: Annotated[int, typer.Option(min=0, help="Bird's-eye plots of this many worst runs.")] = 6,
) -> None:
    """Write the run's self-contained HTML report: verdict, criteria, failures, plots, every index."""
    from simcore.report.html import render, write_next_to_summary
    from simcore.results import open_results

    results = open_results(results_url)
    if out_file is None:
        where = write_next_to_summary(results, worst=worst)
    else:
        if out_file.is_dir():
            raise BadInput("is a directory: give the HTML file's path", file=str(out_file), field="--out")
        from simcore.store import FileStore

        target = out_file.expanduser().absolute()
        FileStore(target.parent).put_bytes(target.name, render(results, worst=worst).encode())
        where = str(target)
    typer.echo(f"report: {where}")


def submit(
    manifest: Annotated[Path, typer.Argument(help="SimulationRun manifest (YAML), as for `carlos run`.")],
    namespace: Annotated[
        str | None, typer.Option("--namespace", "-n", help="Default: the kubeconfig context's, else default.")
    ] = None,
    dry_run: Annotated[
        bool, typer.Option("--dry-run", help="Print the objects instead of creating them.")
    ] = False,
    output_format: Annotated[str, typer.Option("--output", "-o", help="With --dry-run: yaml.")] = "yaml",
    results: Annotated[
        str | None,
        typer.Option(
            "--results",
            help="s3://bucket/prefix for the results (default: spec.output.url if s3://, else "
            "the operator's default output).",
        ),
    ] = None,
) -> None:
    """Create the run on the cluster of the kubeconfig (as kubectl reads it): local scenarios, roads and
    catalogs go into a ConfigMap owned by the run (too large: into the run's object store)."""
    from simcore.checks import check_criteria_metrics
    from simcore.manifest import load_manifest
    from simcore.workflow.submit import create, current_namespace, objects_yaml, pack

    if output_format != "yaml":
        raise BadInput(f"unknown output format {output_format!r}: use yaml", field="--output")
    simulation_run = load_manifest(manifest)
    check_criteria_metrics(simulation_run.spec, str(manifest))
    packed = pack(simulation_run, manifest, namespace or current_namespace(), results)
    if dry_run:
        typer.echo(objects_yaml(packed), nl=False)
        return
    create(packed)
    where = packed.run["metadata"]["namespace"]
    typer.echo(f"simulationrun.carlos.dev/{simulation_run.name} created in namespace {where}")


_RUN_HELP = "A run: its results URL (file://…/<run>, s3://…/<run>) or its name on the cluster."
_NAMESPACE = typer.Option("--namespace", "-n", help="Cluster namespace (default: the kubeconfig context's).")


def _results_of(run: str, namespace: str | None) -> "RunResults":
    """The results of `run`: a URL directly, a cluster run through its status.resultsURL."""
    from simcore.results import open_results
    from simcore.workflow.status import cluster_runs, state_of_object
    from simcore.workflow.submit import current_namespace

    if "://" in run:
        return open_results(run, field_name="RUN")
    state = state_of_object(cluster_runs(namespace or current_namespace(), run)[0])
    if not state.results_url:
        raise BadInput(f"run {run!r} has no results yet (phase {state.phase})", field="RUN")
    return open_results(state.results_url, field_name="status.resultsURL")


def _states(run: str | None, namespace: str | None) -> list["RunState"]:
    from simcore.workflow.status import cluster_runs, state_of_object, state_of_results
    from simcore.workflow.submit import current_namespace

    if run is not None and "://" in run:
        return [state_of_results(_results_of(run, namespace))]
    return [state_of_object(o) for o in cluster_runs(namespace or current_namespace(), run)]


def get(
    run: Annotated[
        str | None, typer.Argument(help=_RUN_HELP + " Default: every run of the namespace.")
    ] = None,
    namespace: Annotated[str | None, _NAMESPACE] = None,
) -> None:
    """Show runs: phase, progress, passed/failed/errors and the first failures."""
    states = _states(run, namespace)
    if not states:
        typer.echo("no SimulationRuns")
    for state in states:
        typer.echo(state.line())
        for line in state.failures if run is not None else ():
            typer.echo(f"  {line}")


def watch(
    run: Annotated[str, typer.Argument(help=_RUN_HELP)],
    namespace: Annotated[str | None, _NAMESPACE] = None,
    interval: Annotated[float, typer.Option(min=0.1, help="Seconds between polls.")] = 2.0,
    timeout: Annotated[float, typer.Option(min=0, help="Give up after this many seconds (0: never).")] = 0.0,
) -> None:
    """Follow a run until it ends, one line per change; exit code as `carlos run` (0 passed, 1 failed)."""
    import time

    started = time.monotonic()
    last = None
    while True:
        state = _states(run, namespace)[0]
        if state.line() != last:
            last = state.line()
            typer.echo(last)
        if state.finished:
            for line in state.failures:
                typer.echo(f"  {line}")
            raise typer.Exit(0 if state.phase == "Succeeded" else 1)
        if timeout and time.monotonic() - started > timeout:
            raise typer.Exit(3)
        time.sleep(interval)


def logs(
    run: Annotated[str, typer.Argument(help=_RUN_HELP)],
    index: Annotated[int, typer.Option("--index", "-i", min=0, help="The index whose log.txt to print.")],
    namespace: Annotated[str | None, _NAMESPACE] = None,
) -> None:
    """Print one index's log.txt from the run's results."""
    from simcore.store import StoreError

    results = _results_of(run, namespace)
    try:
        text = results.store.get_bytes(f"{index}/log.txt").decode("utf-8", "replace")
    except StoreError:
        raise BadInput(f"no log of index {index} in {results.url}", field="--index") from None
    typer.echo(text, nl=False)


def results(
    run: Annotated[str, typer.Argument(help=_RUN_HELP)],
    download: Annotated[Path | None, typer.Option("--download", help="Copy every file here.")] = None,
    namespace: Annotated[str | None, _NAMESPACE] = None,
) -> None:
    """List the run's result files (URLs), or download them all (`--download DIR`)."""
    from simcore.store import FileStore

    found = _results_of(run, namespace)
    keys = found.store.list()
    if download is None:
        for key in keys:
            typer.echo(found.store.url_for(key))
        return
    target = FileStore(download / found.name)
    for key in keys:
        target.put_bytes(key, found.store.get_bytes(key))
    typer.echo(f"{len(keys)} files → {download / found.name}")


def export(
    results_url: Annotated[str, typer.Argument(help="The run's results: file://…/<run> or s3://…/<run>.")],
    output_format: Annotated[str, typer.Option("--format", help="parquet, kitti or omega-prime.")],
    out_dir: Annotated[Path, typer.Option("--out", help="Folder (or a .parquet file) to write.")] = Path("."),
) -> None:
    """Export the results: `parquet` (one row per index), `kitti` (lidar frames, labels, calibration) or
    `omega-prime` (ASAM OSI ground truth and the OpenDRIVE map, one MCAP file per index)."""
    from simcore.export import export_kitti, export_parquet
    from simcore.results import open_results

    if output_format not in ("parquet", "kitti", "omega-prime"):
        raise BadInput(
            f"unknown format {output_format!r}: use parquet, kitti or omega-prime", field="--format"
        )
    results = open_results(results_url)
    if output_format == "omega-prime":
        from simcore.export_omega import export_omega_prime

        folder, files = export_omega_prime(results, out_dir)
        typer.echo(f"{files} omega-prime files → {folder}")
        return
    if output_format == "parquet":
        typer.echo(f"{len(results.indexes)} rows → {export_parquet(results, out_dir)}")
        return
    where, frames = export_kitti(results, out_dir)
    typer.echo(f"{frames} lidar frames → {where}")


def rerun(
    run_ref: Annotated[str, typer.Argument(metavar="RUN", help=_RUN_HELP)],
    failed: Annotated[bool, typer.Option("--failed", help="Rerun the failed and errored indexes.")] = False,
    base_dir: Annotated[
        Path | None,
        typer.Option("--base-dir", help="Folder of the original manifest (relative scenario paths)."),
    ] = None,
    parallel: Annotated[int | None, typer.Option("--parallel", "-j", min=1, help="Worker processes.")] = None,
    namespace: Annotated[str | None, _NAMESPACE] = None,
) -> None:
    """A new run `<run>-rerun` over the failed indexes only: of a local run, run here beside the old one
    (exit code as `carlos run`); of a cluster run, a new SimulationRun created on the cluster."""
    from simcore.executor import execute
    from simcore.results import open_results
    from simcore.workflow.rerun import rerun_spec
    from simcore.workflow.terminal import failure_lines

    if not failed:
        raise BadInput("say what to rerun: --failed", field="--failed")
    if "://" not in run_ref:
        _rerun_on_cluster(run_ref, namespace)
        return
    results = open_results(run_ref)
    run, indexes, base = rerun_spec(results, base_dir)
    typer.echo(f"{run.name}: rerunning indexes {', '.join(map(str, indexes))} of {results.name}")
    report = execute(
        run,
        base_dir=base,
        output_url=results.url.rsplit("/", 1)[0],
        parallel=parallel,
        indexes=indexes,
        fresh=True,
    )
    for line in failure_lines(list(report.outcomes.values())):
        typer.echo(line)
    typer.echo(f"{report.summary['status']} · results: {report.output_url}")
    raise typer.Exit(report.exit_code)


def _rerun_on_cluster(name: str, namespace: str | None) -> None:
    """`carlos rerun NAME --failed` of a cluster run: a new SimulationRun over its failed indexes."""
    from kubernetes.client.exceptions import ApiException

    from simcore.errors import SimulationError
    from simcore.workflow.rerun import cluster_rerun, failed_indexes, rerun_name
    from simcore.workflow.status import cluster_runs
    from simcore.workflow.submit import create, current_namespace, inputs_name, kube_clients

    namespace = namespace or current_namespace()
    obj = cluster_runs(namespace, name)[0]
    failed = failed_indexes(_results_of(name, namespace))
    _, core = kube_clients()

    def taken(candidate: str) -> bool:
        try:
            cluster_runs(namespace, candidate)
        except BadInput:
            return False
        return True

    try:
        inputs = core.read_namespaced_config_map(inputs_name(name), namespace).data or {}
    except ApiException as exc:
        if exc.status != 404:
            raise SimulationError(f"Kubernetes API: {exc.status} {exc.reason}") from None
        inputs = None  # not submitted by `carlos submit`: its ConfigMaps are the user's
    packed = cluster_rerun(obj, failed, rerun_name(name, taken), inputs)
    create(packed)
    new = packed.run["metadata"]["name"]
    typer.echo(f"{new}: rerunning indexes {', '.join(map(str, failed))} of {name}")
    typer.echo(f"simulationrun.carlos.dev/{new} created in namespace {namespace}")
