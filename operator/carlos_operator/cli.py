"""The operator's `carlos` subcommands (`carlos operator`, `carlos crds`), provided to simcore's CLI through
the `carlos.commands` entry points (pyproject.toml): simcore never imports this package; the CLI loads a
command from here only when it is asked for (or listed in `carlos --help`)."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from simcore.errors import BadInput

operator_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
crds_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


@operator_app.command()
def operator(
    namespace: Annotated[
        list[str] | None, typer.Option("--namespace", "-n", help="Watch this namespace (repeatable).")
    ] = None,
    all_namespaces: Annotated[
        bool, typer.Option("--all-namespaces", "-A", help="Watch every namespace (cluster-wide).")
    ] = False,
    liveness_port: Annotated[int, typer.Option(help="Port of the liveness endpoint /healthz.")] = 8080,
    metrics_port: Annotated[int, typer.Option(help="Port of the Prometheus metrics (0: off).")] = 9090,
) -> None:
    """Run the Kubernetes operator: SimulationRun → ConfigMap + Indexed Job → status."""
    if bool(namespace) == all_namespaces:
        raise BadInput("give --namespace NS (repeatable) or --all-namespaces", field="--namespace")
    from carlos_operator.main import run_operator

    raise typer.Exit(
        run_operator(
            namespaces=list(namespace or []),
            liveness_port=liveness_port,
            metrics_port=metrics_port,
        )
    )


@crds_app.command()
def crds() -> None:
    """Print the SimulationRun CustomResourceDefinition (YAML, generated from the spec models)."""
    from carlos_operator.crd import crd_yaml

    sys.stdout.write(crd_yaml())
