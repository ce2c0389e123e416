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
