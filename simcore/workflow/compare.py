"""`carlos compare BASELINE CANDIDATE`: two runs' results side by side (the decisions: simcore.compare)."""

# Annotations are evaluated as the module loads (see simcore.workflow.commands).
from pathlib import Path
from typing import Annotated

import typer

from simcore.errors import BadInput


def _write(path: Path, text: str, option: str) -> None:
    if str(path) == "-":
        typer.echo(text, nl=False)
        return
    if path.is_dir():
        raise BadInput("is a directory: give the file's path", file=str(path), field=option)
    from simcore.store import FileStore

    target = path.expanduser().absolute()
    FileStore(target.parent).put_bytes(target.name, text.encode())


def compare(
    baseline_url: Annotated[
        str, typer.Argument(metavar="BASELINE", help="The baseline run's results: file://…/<run> or s3://….")
    ],
    candidate_url: Annotated[
        str,
        typer.Argument(metavar="CANDIDATE", help="The candidate run's results: file://…/<run> or s3://…."),
    ],
    tolerance: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="A metric has changed when it differs by more than this share of the baseline's value "
            "and by more than --absolute-tolerance.",
        ),
    ] = 0.05,
    absolute_tolerance: Annotated[
        float,
        typer.Option(
            "--absolute-tolerance",
            min=0.0,
            help="A metric has changed only when it differs by more than this, in the metric's unit "
            "(m, s, m/s, m/s²): near-zero noise is not a change.",
        ),
    ] = 0.01,
    markdown_file: Annotated[
        Path | None, typer.Option("--markdown", help="Write the comparison as Markdown here ('-': stdout).")
    ] = None,
    junit_file: Annotated[
        Path | None, typer.Option("--junit", help="Write the regressions as JUnit XML here ('-': stdout).")
    ] = None,
    report: Annotated[
        bool,
        typer.Option(
            "--report",
            help="Store comparison.json next to the candidate's summary.json and rewrite its report.html "
            "with a comparison section.",
        ),
    ] = False,
) -> None:
    """Compare a candidate run with a baseline: first what differs between the two specs, then the runs
    matched by scenario, parameters and seed (new failures, fixed, still failing, added, removed, metric
    changes). Exit 1 on a new failure of a required run, 2 when no run matches, else 0."""
    import json

    from simcore import compare as cmp
    from simcore.results import RunResults, open_results
    from simcore.spec_diff import SCENARIO_DIGESTS_KEY, spec_differences

    def digests(results: RunResults) -> dict[str, object] | None:
        if not results.store.exists(SCENARIO_DIGESTS_KEY):
            return None
        try:
            loaded = json.loads(results.store.get_bytes(SCENARIO_DIGESTS_KEY))
        except ValueError:
            return None
        return loaded if isinstance(loaded, dict) else None

    baseline = open_results(baseline_url, field_name="BASELINE")
    candidate = open_results(candidate_url, field_name="CANDIDATE")
    for results, name in ((baseline, "BASELINE"), (candidate, "CANDIDATE")):
        if not results.indexes:
            raise BadInput(f"{results.url} holds no finished run (no <index>/summary.json)", field=name)
    differences = spec_differences(baseline.spec, candidate.spec, digests(baseline), digests(candidate))
    comparison = cmp.compare(
        baseline.indexes,
        candidate.indexes,
        tolerance=tolerance,
        absolute=absolute_tolerance,
        baseline_name=baseline.url,
        candidate_name=candidate.url,
        spec_differences=differences,
    )
    if comparison.matched == 0:
        counts = comparison.counts
        why = f"; the specs differ: {'; '.join(differences[:3])}" if differences else ""
        raise BadInput(
            f"no run of the candidate matches a run of the baseline by scenario, parameters and seed "
            f"({counts['added']} added, {counts['removed']} removed): nothing was compared{why}. Compare two "
            "runs of the same manifest",
            field="CANDIDATE",
        )
    if differences:
        typer.echo(
            f"the specs differ ({len(differences)}): a changed criterion or input changes verdicts by itself"
        )
        for line in differences:
            typer.echo(f"  {line}")
    typer.echo(comparison.counts_line())
    for r in comparison.of("new failure"):
        typer.echo(f"new failure: {r.name}: {cmp.failure_text(r.candidate)}")
    if markdown_file is not None:
        _write(markdown_file, cmp.markdown(comparison), "--markdown")
    if junit_file is not None:
        _write(junit_file, cmp.junit_xml(comparison), "--junit")
    if report:
        import hashlib

        from simcore.report.html import write_next_to_summary

        # the results compared: a later run into the same folder leaves this comparison out of its report
        summary = candidate.store.get_bytes("summary.json") if candidate.store.exists("summary.json") else b""
        stored = {**comparison.as_dict(), "candidateSummarySha256": hashlib.sha256(summary).hexdigest()}
        data = json.dumps(stored, indent=2, sort_keys=True) + "\n"
        candidate.store.put_bytes(cmp.COMPARISON_KEY, data.encode())
        typer.echo(f"report: {write_next_to_summary(candidate)}")
    raise typer.Exit(comparison.exit_code)
