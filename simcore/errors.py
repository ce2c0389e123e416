"""Errors and exit codes shared by the CLI, the executor and every pod role (DESIGN.md, exit codes)."""

from __future__ import annotations

import re
from enum import IntEnum

MAX_SHOWN_CHARS = 200  # an untrusted value in a message: longer ones are cut (with their length)
MAX_MESSAGE_CHARS = 2000
_QUOTED = re.compile(rf"'[^']{{{MAX_SHOWN_CHARS},}}'|\"[^\"]{{{MAX_SHOWN_CHARS},}}\"")


def shorten(text: str, limit: int = MAX_SHOWN_CHARS) -> str:
    """Untrusted text cut to `limit` characters for a message, saying how long it was."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}… ({len(text)} characters)"


def cap_message(message: str) -> str:
    """A message with every quoted value longer than MAX_SHOWN_CHARS shortened, and at most
    MAX_MESSAGE_CHARS in all: an error never echoes a 300 KB attribute back."""
    capped = _QUOTED.sub(lambda m: m.group(0)[0] + shorten(m.group(0)[1:-1]) + m.group(0)[0], message)
    return shorten(capped, MAX_MESSAGE_CHARS)


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
        message = cap_message(message)
        self.detail = message
        where = ": ".join(part for part in (file, field) if part)
        super().__init__(f"{where}: {message}" if where else message)


class SimulationError(CarlosError):
    """The simulator failed (SUMO, a crash in a step): an infrastructure error, retried."""

    exit_code = ExitCode.INFRASTRUCTURE
