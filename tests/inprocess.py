"""`carlos …` in this process (typer's CliRunner): fast enough for fuzzing, and a traceback shows up as an
exception instead of a line on stderr."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from typer.testing import CliRunner

from simcore.cli import app


@dataclass(frozen=True)
class Outcome:
    exit_code: int
    stdout: str
    stderr: str
    exception: BaseException | None  # an exception that escaped the command (a traceback for a user)


def carlos_in_process(*args: str | Path) -> Outcome:
    result = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=True)
    escaped = result.exception if not isinstance(result.exception, SystemExit) else None
    return Outcome(int(result.exit_code), result.stdout, result.stderr, escaped)
