"""Object store: FileStore round trips and atomicity; S3Store against a real SeaweedFS S3 server."""

from __future__ import annotations

import hashlib
import os
import re
import time
from pathlib import Path
from typing import TYPE_CHECKING

import boto3
import pytest
from botocore.awsrequest import AWSPreparedRequest
from botocore.config import Config
from botocore.exceptions import ConnectionClosedError

from simcore.store import FileStore, NotFoundError, S3Store, Store, StoreError, open_store

if TYPE_CHECKING:
    from tests.s3server import S3Server

# the session fixture `s3_server` (registered once even when tests/conftest.py names the plugin too)
pytest_plugins = ["tests.s3server"]

MiB = 1024 * 1024


# --- file:// --------------------------------------------------------------------------------------------


def _files(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())


def test_file_store_round_trip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    store = open_store("file://./results")
    assert isinstance(store, FileStore)
    assert isinstance(store, Store)
    store.put_bytes("run-a/run.yaml", b"kind: SimulationRun\n")
    store.put_bytes("run-a/0/summary.json", b'{"index": 0}')
    src = tmp_path / "local.mcap"
    src.write_bytes(os.urandom(3 * MiB + 17))
    store.put_file("run-a/0/recording.mcap", src)
    store.put_bytes("run-b/0/summary.json", b"{}")
    os.chdir("/")  # the root was resolved when the store was opened
    assert store.get_bytes("run-a/0/recording.mcap") == src.read_bytes()
    assert store.get_bytes("run-a/0/summary.json") == b'{"index": 0}'
    store.put_bytes("run-a/0/summary.json", b'{"index": 0, "status": "passed"}')  # overwrite
    assert store.get_bytes("run-a/0/summary.json") == b'{"index": 0, "status": "passed"}'
    assert store.exists("run-a/run.yaml")
    assert not store.exists("run-a/1/summary.json")
    assert not store.exists("run-a/0")  # a directory is not an object
    assert store.list("run-a/") == ["run-a/0/recording.mcap", "run-a/0/summary.json", "run-a/run.yaml"]
    assert store.list("run-a/0/sum") == ["run-a/0/summary.json"]
    assert store.list("run") == [*store.list("run-a/"), "run-b/0/summary.json"]
    assert store.list("nothing/") == []
    assert store.url_for("run-a/run.yaml") == (tmp_path / "results/run-a/run.yaml").as_uri()
    with pytest.raises(NotFoundError, match="summary"):
        store.get_bytes("run-a/7/summary.json")
    # no temporary file is left behind
    assert _files(tmp_path / "results") == [
        "run-a/0/recording.mcap",
        "run-a/0/summary.json",
        "run-a/run.yaml",
        "run-b/0/summary.json",
    ]


def test_file_store_absolute_url(tmp_path: Path) -> None:
    store = open_store(f"file://{tmp_path}/out")
    store.put_bytes("x/y.txt", b"1")
    assert (tmp_path / "out/x/y.txt").read_bytes() == b"1"


@pytest.mark.parametrize("key", ["", "/abs", "a/../b", "a//b", "a/./b", "a\\b", "dir/"])
def test_file_store_rejects_bad_keys(tmp_path: Path, key: str) -> None:
    with pytest.raises(ValueError):
        FileStore(tmp_path).put_bytes(key, b"x")


def test_file_store_sync_flushes_the_file_system(tmp_path: Path) -> None:
    store = FileStore(tmp_path / "store")
    store.sync()  # before anything is written (the root does not exist yet)
    store.put_bytes("run/0/summary.json", b"{}")
    store.sync()
    assert store.get_bytes("run/0/summary.json") == b"{}"
    with pytest.raises(StoreError, match="cannot flush"):
        FileStore(tmp_path / "no" / "such" / "store").sync()


def test_file_store_failed_write_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    store = FileStore(tmp_path / "store")
    store.put_bytes("run/0/summary.json", b"old")

    def broken_replace(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(StoreError, match="No space left"):
        store.put_bytes("run/0/summary.json", b"new and longer")
    with pytest.raises(StoreError, match="No space left"):
        store.put_bytes("run/1/summary.json", b"new")
    monkeypatch.undo()
    assert store.get_bytes("run/0/summary.json") == b"old"  # the old object is intact
    assert not store.exists("run/1/summary.json")
    assert _files(tmp_path / "store") == ["run/0/summary.json"]  # and no temporary file is left


def test_file_store_reader_never_sees_partial_file(tmp_path: Path) -> None:
    """While a big put_file is copying, the final name does not exist (the data goes to a temp file)."""
    store = FileStore(tmp_path / "store")
    seen: list[bool] = []

    class SlowSource:
        def __init__(self) -> None:
            self.chunks = 5

        def read(self, n: int = -1) -> bytes:
            seen.append((tmp_path / "store/r/0/recording.mcap").exists())
            if self.chunks == 0:
                return b""
            self.chunks -= 1
            return b"x" * 1000

    with store._atomic("r/0/recording.mcap") as f:
        src = SlowSource()
        while data := src.read():
            f.write(data)
    assert seen and not any(seen)
    assert store.get_bytes("r/0/recording.mcap") == b"x" * 5000


def test_open_store_rejects_other_schemes() -> None:
    with pytest.raises(ValueError, match="unsupported"):
        open_store("gs://bucket/x")


# --- s3:// ----------------------------------------------------------------------------------------------


@pytest.fixture
def s3_env(s3_server: S3Server, monkeypatch: pytest.MonkeyPatch) -> S3Server:
    for name in ("AWS_SESSION_TOKEN", "AWS_ENDPOINT_URL_S3", "AWS_PROFILE", "AWS_DEFAULT_REGION"):
        monkeypatch.delenv(name, raising=False)
    for name, value in s3_server.env().items():
        monkeypatch.setenv(name, value)
    return s3_server


def _raw_client(server: S3Server) -> object:
    return boto3.client(
        "s3",
        endpoint_url=server.endpoint,
        aws_access_key_id=server.access_key,
        aws_secret_access_key=server.secret_key,
        region_name=server.region,
        config=Config(s3={"addressing_style": "path"}),
    )


@pytest.mark.s3
def test_s3_round_trip(s3_env: S3Server) -> None:
    store = open_store(f"s3://{s3_env.bucket}/results/rt")  # endpoint from AWS_ENDPOINT_URL
    assert isinstance(store, S3Store)
    assert isinstance(store, Store)
    assert store.endpoint == s3_env.endpoint
    store.put_bytes("run-a/run.yaml", b"kind: SimulationRun\n")
    store.put_bytes("run-a/0/summary.json", b'{"index": 0}')
    store.put_bytes("run-a/1/summary.json", b'{"index": 1}')
    store.put_bytes("run-b/0/summary.json", b"{}")
    assert store.get_bytes("run-a/0/summary.json") == b'{"index": 0}'
    assert store.exists("run-a/run.yaml")
    assert not store.exists("run-a/2/summary.json")
    assert store.list("run-a/") == ["run-a/0/summary.json", "run-a/1/summary.json", "run-a/run.yaml"]
    assert store.list("run-a/1") == ["run-a/1/summary.json"]
    assert len(store.list()) == 4
    assert store.url_for("run-a/run.yaml") == f"s3://{s3_env.bucket}/results/rt/run-a/run.yaml"
    with pytest.raises(NotFoundError, match=r"s3://carlos-test/results/rt/run-a/9/summary.json"):
        store.get_bytes("run-a/9/summary.json")
    # the prefix is honoured on the server side
    raw = _raw_client(s3_env)
    body = raw.get_object(Bucket=s3_env.bucket, Key="results/rt/run-a/run.yaml")["Body"].read()  # type: ignore[attr-defined]
    assert body == b"kind: SimulationRun\n"


@pytest.mark.s3
def test_s3_multipart_upload(s3_env: S3Server, tmp_path: Path) -> None:
    store = S3Store.from_url(
        f"s3://{s3_env.bucket}/mp", multipart_threshold=5 * MiB, multipart_chunksize=5 * MiB
    )
    src = tmp_path / "recording.mcap"
    data = os.urandom(12 * MiB)
    src.write_bytes(data)
    sent: list[int] = []
    start = time.perf_counter()
    store.put_file("run/0/recording.mcap", src, progress=sent.append)
    elapsed = time.perf_counter() - start
    print(f"S3 upload of 12 MiB in 3 parts: {elapsed:.3f} s ({12 / elapsed:.0f} MiB/s)")
    assert sum(sent) == len(data)
    assert hashlib.sha256(store.get_bytes("run/0/recording.mcap")).digest() == hashlib.sha256(data).digest()
    head = _raw_client(s3_env).head_object(Bucket=s3_env.bucket, Key="mp/run/0/recording.mcap")  # type: ignore[attr-defined]
    assert head["ContentLength"] == len(data)
    assert head["ETag"].strip('"').endswith("-3")  # a multipart object of 3 parts


@pytest.mark.s3
def test_s3_failed_multipart_upload_leaves_no_key(s3_env: S3Server, tmp_path: Path) -> None:
    """The connection drops on every try of part 2: the upload fails, is aborted, and no key appears."""
    store = S3Store.from_url(
        f"s3://{s3_env.bucket}/mp-fail",
        multipart_threshold=5 * MiB,
        multipart_chunksize=5 * MiB,
        max_attempts=2,
        outage=1.0,
    )
    src = tmp_path / "big.bin"
    src.write_bytes(os.urandom(12 * MiB))
    dropped: list[str] = []

    def drop_part_2(request: AWSPreparedRequest, **_: object) -> None:
        if "partNumber=2" in request.url:
            dropped.append(request.url)
            raise ConnectionClosedError(endpoint_url=request.url)

    store._client.meta.events.register("before-send.s3.UploadPart", drop_part_2)
    with pytest.raises(StoreError, match=r"upload s3://carlos-test/mp-fail/run/0/recording.mcap") as excinfo:
        store.put_file("run/0/recording.mcap", src)
    print(excinfo.value)
    assert len(dropped) >= 2  # retried (botocore, max_attempts=2; s3transfer may add its own), then given up
    assert not store.exists("run/0/recording.mcap")
    assert store.list("run/") == []
    uploads = _raw_client(s3_env).list_multipart_uploads(Bucket=s3_env.bucket, Prefix="mp-fail/")  # type: ignore[attr-defined]
    assert not uploads.get("Uploads")  # aborted, not left dangling


@pytest.mark.s3
def test_s3_wrong_credentials(s3_env: S3Server, monkeypatch: pytest.MonkeyPatch) -> None:
    wrong_secret = "not-the-secret-" + s3_env.secret_key[::-1]
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", wrong_secret)
    with pytest.raises(StoreError) as excinfo:
        open_store(f"s3://{s3_env.bucket}/x")
    message = str(excinfo.value)
    assert "access denied" in message and "AWS_SECRET_ACCESS_KEY" in message
    assert s3_env.bucket in message
    assert wrong_secret not in message and s3_env.secret_key not in message

    store = S3Store.from_url(f"s3://{s3_env.bucket}/x")
    with pytest.raises(StoreError) as excinfo:
        store.put_bytes("run/0/summary.json", b"{}")
    message = str(excinfo.value)
    assert "signature does not match" in message
    assert f"s3://{s3_env.bucket}/x/run/0/summary.json" in message
    assert wrong_secret not in message and s3_env.secret_key not in message
    # nor in the chained exceptions' messages
    cause: BaseException | None = excinfo.value
    while cause is not None:
        assert wrong_secret not in str(cause)
        cause = cause.__cause__ or cause.__context__

    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "nobody")
    with pytest.raises(StoreError, match=r"access key id is not known"):
        S3Store.from_url(f"s3://{s3_env.bucket}/x").get_bytes("run/0/summary.json")


@pytest.mark.s3
def test_s3_missing_credentials(s3_env: S3Server, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("AWS_SECRET_ACCESS_KEY")
    with pytest.raises(StoreError, match=r"no S3 credentials.*AWS_SECRET_ACCESS_KEY"):
        open_store(f"s3://{s3_env.bucket}/x")


@pytest.mark.s3
def test_s3_missing_bucket(s3_env: S3Server) -> None:
    with pytest.raises(StoreError, match="bucket 'no-such-bucket' does not exist") as excinfo:
        open_store("s3://no-such-bucket/results", endpoint=s3_env.endpoint)
    assert s3_env.endpoint in str(excinfo.value)
    store = S3Store.from_url("s3://no-such-bucket/results")
    with pytest.raises(StoreError, match="bucket 'no-such-bucket' does not exist"):
        store.get_bytes("a/b.json")
    with pytest.raises(StoreError, match="bucket 'no-such-bucket' does not exist"):
        store.put_bytes("a/b.json", b"{}")


@pytest.mark.s3
def test_s3_unreachable_endpoint(s3_env: S3Server) -> None:
    store = S3Store.from_url(
        f"s3://{s3_env.bucket}/x",
        endpoint="http://127.0.0.1:9",
        max_attempts=2,
        connect_timeout=1,
        outage=2.0,
    )
    started = time.monotonic()
    with pytest.raises(
        StoreError, match=re.escape("cannot connect to the endpoint http://127.0.0.1:9")
    ) as info:
        store.put_bytes("a.json", b"{}")
    assert "s of retries" in str(info.value)
    assert 1.0 <= time.monotonic() - started < 30  # retried with backoff for the bounded time, then given up


@pytest.mark.s3
def test_s3_transient_failures_are_retried_until_they_pass(s3_env: S3Server) -> None:
    """The connection drops on the first three PUTs (beyond botocore's own retries): the store backs off and
    tries again; the fourth succeeds and the object is there once."""
    store = S3Store.from_url(f"s3://{s3_env.bucket}/flaky", max_attempts=1, outage=30.0)
    dropped: list[str] = []

    def drop_three(request: AWSPreparedRequest, **_: object) -> None:
        if len(dropped) < 3:
            dropped.append(request.url)
            raise ConnectionClosedError(endpoint_url=request.url)

    store._client.meta.events.register("before-send.s3.PutObject", drop_three)
    store.put_bytes("run/0/summary.json", b"{}")
    assert len(dropped) == 3
    assert store.get_bytes("run/0/summary.json") == b"{}"


def test_backoff_delays_double_up_to_the_cap_within_the_budget() -> None:
    from simcore.store import backoff_delays

    assert list(backoff_delays(10.0)) == [0.5, 1.0, 2.0, 4.0]
    assert list(backoff_delays(0.0)) == []
    delays = list(backoff_delays(100.0, cap=10.0))
    assert max(delays) == 10.0 and sum(delays) <= 100.0


def test_the_outage_budget_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    from simcore.errors import BadInput
    from simcore.store import DEFAULT_OUTAGE_SECONDS, outage_seconds

    monkeypatch.delenv("CARLOS_STORE_OUTAGE_SECONDS", raising=False)
    assert outage_seconds() == DEFAULT_OUTAGE_SECONDS
    monkeypatch.setenv("CARLOS_STORE_OUTAGE_SECONDS", "12.5")
    assert outage_seconds() == 12.5
    monkeypatch.setenv("CARLOS_STORE_OUTAGE_SECONDS", "soon")
    with pytest.raises(BadInput, match="CARLOS_STORE_OUTAGE_SECONDS"):
        outage_seconds()


def test_file_store_writes_ordinary_file_modes(tmp_path: Path) -> None:
    store = open_store(f"file://{tmp_path}")
    store.put_bytes("a/b.txt", b"x")
    mode = (tmp_path / "a" / "b.txt").stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask


@pytest.mark.parametrize(
    ("code", "status", "transient"),
    [
        ("ServiceUnavailable", 503, True),
        ("InternalError", 500, True),
        ("SlowDown", 503, True),
        ("", 502, True),
        ("AccessDenied", 403, False),
        ("NoSuchKey", 404, False),
        ("SignatureDoesNotMatch", 403, False),
    ],
)
def test_5xx_and_throttling_are_transient_and_client_errors_are_not(
    code: str, status: int, transient: bool
) -> None:
    from botocore.exceptions import ClientError, EndpointConnectionError

    from simcore.store import is_transient

    error = ClientError(
        {"Error": {"Code": code}, "ResponseMetadata": {"HTTPStatusCode": status}}, "PutObject"
    )
    assert is_transient(error) is transient
    assert is_transient(EndpointConnectionError(endpoint_url="http://127.0.0.1:9"))
