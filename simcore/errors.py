"""Errors and exit codes shared by the CLI, the executor and every pod role (DESIGN.md, exit codes)."""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    PASSED = 0  # ran, every required criterion passed
    FAILED = 1  # ran, a required criterion failed (a test failure: never retried)
    BAD_INPUT = 2  # manifest, scenario, road file or parameters are wrong: never retried
    INFRASTRUCTURE = 3  # simulator or infrastructure error: retried up to execution.retries


class CarlosError(Exception):
    """Base of CARLOS' own errors; `exit_code` is what a process ending on it returns."""

    exit_code: ExitCode = ExitCode.INFRASTRUCTURE


class BadInput(CarlosError):
    """Untrusted input is wrong. The message names the file, the field and what to do; never a traceback."""

    exit_code = ExitCode.BAD_INPUT

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None) -> None:
        self.file = file
        self.field = field
        self.detail = message
        where = ": ".join(part for part in (file, field) if part)
        super().__init__(f"{where}: {message}" if where else message)


class SimulationError(CarlosError):
    """The simulator failed (SUMO, a crash in a step): an infrastructure error, retried."""

    exit_code = ExitCode.INFRASTRUCTURE
