"""Workflow commands of `carlos` (registered in simcore.cli). They raise CarlosError for bad input and
infrastructure errors; `simcore.cli.main` prints it as one line with its exit code."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from simcore.errors import BadInput


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
