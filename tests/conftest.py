"""Shared fixtures: the S3 server (SeaweedFS on loopback, one per test worker), the helm binary and the
esmini corpus (tests/tooling.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.tooling import helm_binary

pytest_plugins = ["tests.s3server"]


@pytest.fixture(scope="session")
def helm() -> Path:
    return helm_binary()
