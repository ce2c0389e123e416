"""The reference pages generated from the code must not drift: the command line (from the typer app) and the
topics and message types (from the modules that publish them)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import typer.main

from simcore.cli_app import app
from simcore.reference import cli_reference, topic_rows, topics_reference

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "docs" / "reference"


def test_cli_reference_matches_the_commands() -> None:
    assert (REFERENCE / "cli.md").read_text() == cli_reference(app), (
        "docs/reference/cli.md is stale: run `carlos docs cli > docs/reference/cli.md`"
    )


def test_cli_reference_documents_every_command_and_option() -> None:
    text = cli_reference(app)
    group = typer.main.get_command(app)
    context = group.make_context("carlos", [], resilient_parsing=True)
    names = group.list_commands(context)
    assert {"run", "validate", "examples", "docs", "operator", "crds", "submit"} <= set(names)
    for name in names:
        assert f"\n## carlos {name}\n" in text
    run = group.get_command(context, "run")
    assert run is not None
    for param in run.params:
        if param.param_type_name == "option" and not getattr(param, "hidden", False):
            assert f"`{param.opts[0]}`" in text, param.opts


def test_topics_reference_matches_the_code() -> None:
    assert (REFERENCE / "topics.md").read_text() == topics_reference(), (
        "docs/reference/topics.md is stale: run `carlos docs topics > docs/reference/topics.md`"
    )


def test_topic_rows_name_registered_types() -> None:
    from simcore.transport.messages import TYPESTORE

    rows = topic_rows()
    assert ("/carlos/<entity>/odometry", "nav_msgs/msg/Odometry") in {(t, ty) for t, ty, _ in rows}
    for _, typename, _ in rows:
        assert typename in TYPESTORE.types, typename


def test_docs_command_prints_each_page_and_refuses_an_unknown_one() -> None:
    for page, path in (("cli", REFERENCE / "cli.md"), ("topics", REFERENCE / "topics.md")):
        result = subprocess.run(
            [sys.executable, "-m", "simcore.cli", "docs", page], capture_output=True, text=True, timeout=120
        )
        assert result.returncode == 0, result.stderr
        assert result.stdout == path.read_text()
    bad = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "docs", "nope"], capture_output=True, text=True, timeout=120
    )
    assert bad.returncode == 2
    assert "unknown page 'nope'" in bad.stderr
    assert "Traceback" not in bad.stderr
