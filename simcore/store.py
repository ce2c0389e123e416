"""Object store for results: `file://PATH` and `s3://bucket/prefix` (DESIGN.md, "Object store layout").

Keys are relative, `/`-separated (`<run>/<index>/summary.json`). Writes are atomic in both backends: a
reader never sees a half-written object under its final key.

- :class:`FileStore`: a temporary file in the target's directory, then `os.replace`: a process that dies
  (a crash, Ctrl-C) never leaves a half object under its final key. `sync` makes everything written so far
  durable with one flush of the file system (the executor calls it after `run.yaml` and after the
  run-level summary), instead of an fsync per object, which cost more than a short run itself on a busy
  disk. After a power cut during a run, an index whose summary is missing or unreadable runs again.
  Relative paths are taken from the working directory when the store is opened.
- :class:`S3Store` (boto3): a PUT is atomic; `put_file` uses `upload_file`, multipart above the threshold,
  and S3 makes the key visible only when the multipart upload completes (a failed upload is aborted).
  The endpoint comes from the argument, else `AWS_ENDPOINT_URL_S3` / `AWS_ENDPOINT_URL`, else AWS. The
  credentials come only from the environment (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, optional
  `AWS_SESSION_TOKEN`); they are never logged, and error messages are scrubbed of the secret.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any, Protocol, TypeVar, runtime_checkable

from simcore.errors import BadInput, CarlosError, ExitCode

T = TypeVar("T")

__all__ = [
    "FileStore",
    "NotFoundError",
    "S3Store",
    "Store",
    "StoreError",
    "open_store",
]

_TMP_PREFIX = ".carlos-tmp-"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: mode of the files a FileStore writes: 0666 less the process umask, as `open()` would create them
_FILE_MODE = 0o666 & ~_umask()
#: a FileStore's temporary files: created, never opened if they exist, not inherited by child processes
_CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
#: numbers the temporary files of this process (`<prefix><name>.<pid>.<n>`)
_TMP_COUNTER = itertools.count()


class StoreError(CarlosError, RuntimeError):
    """An object-store operation failed; the message names the object and the cause (never a secret). An
    infrastructure error (exit code 3): a run ending on it is retried, its finished indexes are kept."""

    exit_code = ExitCode.INFRASTRUCTURE


#: how long an S3 operation is retried while the server is unreachable, answers 5xx or throttles
#: (CARLOS_STORE_OUTAGE_SECONDS overrides); then the operation fails with StoreError
DEFAULT_OUTAGE_SECONDS = 300.0
_TRANSIENT_CODES = frozenset(
    {"SlowDown", "Throttling", "ThrottlingException", "RequestTimeout", "ServiceUnavailable", "InternalError"}
)


def outage_seconds() -> float:
    """The retry budget of an S3 operation: CARLOS_STORE_OUTAGE_SECONDS, else DEFAULT_OUTAGE_SECONDS."""
    raw = os.environ.get("CARLOS_STORE_OUTAGE_SECONDS", "")
    try:
        value = float(raw) if raw.strip() else DEFAULT_OUTAGE_SECONDS
    except ValueError:
        raise BadInput(f"{raw!r} is not a number of seconds", field="CARLOS_STORE_OUTAGE_SECONDS") from None
    if not 0 <= value <= 86_400:
        raise BadInput(f"{raw!r} is not between 0 and 86400 seconds", field="CARLOS_STORE_OUTAGE_SECONDS")
    return value


def backoff_delays(budget: float, first: float = 0.5, cap: float = 10.0) -> Iterator[float]:
    """Sleeps between attempts: doubling from `first` up to `cap`, as long as their sum stays in `budget`."""
    spent, delay = 0.0, first
    while spent + delay <= budget:
        yield delay
        spent += delay
        delay = min(delay * 2, cap)


def is_transient(exc: BaseException) -> bool:
    """Whether an S3 failure may pass by itself: no connection, a timeout, a 5xx answer or throttling
    (searched along the exception's causes; boto3's upload errors wrap the botocore one)."""
    from botocore.exceptions import ClientError, ConnectionError, HTTPClientError

    cause: BaseException | None = exc
    seen = 0
    while cause is not None and seen < 10:
        if isinstance(cause, ConnectionError | HTTPClientError):  # refused, reset, timed out
            return True
        if isinstance(cause, ClientError):
            code = str(cause.response.get("Error", {}).get("Code", ""))
            status = cause.response.get("ResponseMetadata", {}).get("HTTPStatusCode") or 0
            return code in _TRANSIENT_CODES or int(status) >= 500
        cause = cause.__cause__ or cause.__context__
        seen += 1
    return "Max retries exceeded" in str(exc) or "Connection was closed" in str(exc)


class NotFoundError(StoreError):
    """The object does not exist."""


@runtime_checkable
class Store(Protocol):
    """What the executor, the pods and the reports need from an object store."""

    def put_file(self, key: str, local_path: str | os.PathLike[str]) -> None: ...

    def put_bytes(self, key: str, data: bytes) -> None: ...

    def get_bytes(self, key: str) -> bytes: ...

    def exists(self, key: str) -> bool: ...

    def list(self, prefix: str = "") -> list[str]: ...

    def url_for(self, key: str) -> str: ...

    def sync(self) -> None: ...


def _check_key(key: str) -> str:
    if not isinstance(key, str) or not key:
        raise ValueError(f"object key must be a non-empty string, not {key!r}")
    if key.startswith("/") or "\\" in key or "\x00" in key:
        raise ValueError(f"object key {key!r} must be relative and use '/' as separator")
    parts = key.split("/")
    if any(part in ("", ".", "..") for part in parts):
        raise ValueError(f"object key {key!r} has an empty, '.' or '..' component")
    return key


def _check_prefix(prefix: str) -> str:
    if prefix.startswith("/") or "\\" in prefix or ".." in prefix.split("/"):
        raise ValueError(f"prefix {prefix!r} must be relative, without '..'")
    return prefix


def open_store(url: str, *, endpoint: str | None = None, region: str | None = None) -> Store:
    """The store for an `output.url`: `file://PATH` (relative to the working directory) or
    `s3://bucket/prefix`. An S3 store checks at once that the bucket exists and is accessible."""
    if url.startswith("file://"):
        path = url[len("file://") :]
        if not path:
            raise ValueError(f"{url!r}: file:// needs a path, e.g. file://./results")
        return FileStore(path)
    if url.startswith("s3://"):
        store = S3Store.from_url(url, endpoint=endpoint, region=region)
        store.check_bucket()
        return store
    raise ValueError(f"unsupported store URL {url!r}: use file://PATH or s3://bucket/prefix")


# --- file:// --------------------------------------------------------------------------------------------


def _syncfs(fd: int) -> None:
    """syncfs(2) of the file system holding `fd` (Linux); elsewhere sync(2)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    syncfs = getattr(libc, "syncfs", None)
    if syncfs is None:  # pragma: no cover - platforms without syncfs (macOS)
        os.sync()
        return
    if syncfs(fd) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))


def fsync_dir(path: Path) -> None:
    """Make a rename in `path` durable (fsync of the directory)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class FileStore:
    """A directory as object store (atomic writes, directories created as needed)."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root).expanduser().absolute()
        self._root = str(self.root)

    def __repr__(self) -> str:
        return f"FileStore({str(self.root)!r})"

    def _path(self, key: str) -> Path:
        return self.root.joinpath(*_check_key(key).split("/"))

    def _create(self, key: str) -> tuple[int, str, str]:
        """(descriptor, temporary path, final path) of a new object: an empty temporary file next to where
        the object goes (its folders made when missing), opened for writing, with an ordinary file's mode."""
        target = os.path.join(self._root, *_check_key(key).split("/"))
        directory, name = os.path.split(target)
        for _ in range(100):  # a name taken (left by a killed process of the same pid): the next one
            tmp = os.path.join(directory, f"{_TMP_PREFIX}{name}.{os.getpid()}.{next(_TMP_COUNTER)}")
            try:
                return os.open(tmp, _CREATE_FLAGS, _FILE_MODE), tmp, target
            except FileNotFoundError:  # the object's folder does not exist yet
                try:
                    os.makedirs(directory, exist_ok=True)
                except OSError as exc:
                    raise StoreError(f"cannot write {target}: {exc.strerror or exc}") from exc
            except FileExistsError:
                continue
            except OSError as exc:
                raise StoreError(f"cannot write {target}: {exc.strerror or exc}") from exc
        raise StoreError(f"cannot write {target}: no free temporary name next to it")

    @contextlib.contextmanager
    def _written(self, key: str) -> Iterator[int]:
        """A descriptor to write a new object's bytes to. When the block ends the object is under its key;
        when it fails, nothing is (the temporary file removed; an OSError raised as a StoreError)."""
        fd, tmp, target = self._create(key)
        try:
            try:
                yield fd
            finally:
                os.close(fd)
            os.replace(tmp, target)
        except BaseException as exc:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            if isinstance(exc, OSError):
                raise StoreError(f"cannot write {target}: {exc.strerror or exc}") from exc
            raise

    @contextlib.contextmanager
    def _atomic(self, key: str) -> Iterator[IO[bytes]]:
        with self._written(key) as fd, os.fdopen(fd, "wb", closefd=False) as f:
            yield f

    def put_bytes(self, key: str, data: bytes) -> None:
        # the object's bytes in one write (a loop for what one write leaves), no file object around them
        with self._written(key) as fd:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]

    def sync(self) -> None:
        """Make every object written so far (by any process) durable: one syncfs of the store's file system
        (sync where there is no syncfs)."""
        try:
            fd = os.open(self.root if self.root.is_dir() else self.root.parent, os.O_RDONLY)
            try:
                _syncfs(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            raise StoreError(f"cannot flush {self.root} to disk: {exc.strerror or exc}") from exc

    def put_file(self, key: str, local_path: str | os.PathLike[str]) -> None:
        try:
            src = open(local_path, "rb")  # noqa: SIM115 - closed below
        except OSError as exc:
            raise StoreError(f"cannot read {local_path}: {exc.strerror or exc}") from exc
        with src, self._atomic(key) as f:
            shutil.copyfileobj(src, f, 1024 * 1024)

    def get_bytes(self, key: str) -> bytes:
        path = self._path(key)
        try:
            return path.read_bytes()
        except FileNotFoundError:
            raise NotFoundError(f"{self.url_for(key)} does not exist") from None
        except OSError as exc:
            raise StoreError(f"cannot read {path}: {exc.strerror or exc}") from exc

    def exists(self, key: str) -> bool:
        return self._path(key).is_file()

    def list(self, prefix: str = "") -> list[str]:
        """Keys starting with `prefix` (a plain string prefix, as in S3), sorted."""
        _check_prefix(prefix)
        # walk only below the deepest directory the prefix names
        head = prefix.rsplit("/", 1)[0] if "/" in prefix else ""
        start = self.root.joinpath(*head.split("/")) if head else self.root
        if not start.is_dir():
            return []
        keys: list[str] = []
        for dirpath, _dirnames, filenames in os.walk(start):
            rel = Path(dirpath).relative_to(self.root).as_posix()
            for name in filenames:
                if name.startswith(_TMP_PREFIX):
                    continue
                key = name if rel == "." else f"{rel}/{name}"
                if key.startswith(prefix):
                    keys.append(key)
        return sorted(keys)

    def url_for(self, key: str) -> str:
        return self._path(key).as_uri()


# --- s3:// ----------------------------------------------------------------------------------------------

_CREDENTIAL_HINT = "check AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY"


class S3Store:
    """An S3 bucket (AWS, MinIO, Ceph, SeaweedFS) under an optional key prefix."""

    #: seconds a transiently failing operation is retried (set by __init__ from CARLOS_STORE_OUTAGE_SECONDS;
    #: a store assembled around a shared client, as the operator's, keeps 0: its reconcile loop retries)
    outage: float = 0.0

    def __init__(
        self,
        bucket: str,
        prefix: str = "",
        *,
        endpoint: str | None = None,
        region: str | None = None,
        max_attempts: int = 5,
        connect_timeout: float = 10.0,
        read_timeout: float = 60.0,
        multipart_threshold: int = 64 * 1024 * 1024,
        multipart_chunksize: int = 16 * 1024 * 1024,
        outage: float | None = None,
    ) -> None:
        import boto3
        from boto3.s3.transfer import TransferConfig
        from botocore.config import Config

        if not bucket:
            raise ValueError("S3 bucket name is empty")
        self.bucket = bucket
        self.prefix = prefix.strip("/")
        self.outage = outage_seconds() if outage is None else outage
        env = os.environ
        self.endpoint = endpoint or env.get("AWS_ENDPOINT_URL_S3") or env.get("AWS_ENDPOINT_URL") or None
        self.region = region or env.get("AWS_REGION") or env.get("AWS_DEFAULT_REGION") or "us-east-1"
        access_key = env.get("AWS_ACCESS_KEY_ID")
        secret_key = env.get("AWS_SECRET_ACCESS_KEY")
        session_token = env.get("AWS_SESSION_TOKEN") or None
        if not access_key or not secret_key:
            raise StoreError(
                f"no S3 credentials for s3://{bucket}: set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY "
                "in the environment"
            )
        self._secrets = tuple(s for s in (secret_key, session_token) if s)
        config = Config(
            retries={"mode": "standard", "max_attempts": max_attempts},
            connect_timeout=connect_timeout,
            read_timeout=read_timeout,
            # MinIO, Ceph and SeaweedFS are addressed by path; AWS itself picks virtual hosts
            s3={"addressing_style": "path"} if self.endpoint else {},
        )
        session = boto3.session.Session(
            aws_access_key_id=access_key,
            aws_secret_access_key=secret_key,
            aws_session_token=session_token,
            region_name=self.region,
        )
        self._client: Any = session.client("s3", endpoint_url=self.endpoint, config=config)
        self._transfer = TransferConfig(
            multipart_threshold=multipart_threshold,
            multipart_chunksize=multipart_chunksize,
            max_concurrency=4,
        )

    @classmethod
    def from_url(
        cls, url: str, *, endpoint: str | None = None, region: str | None = None, **kwargs: Any
    ) -> S3Store:
        if not url.startswith("s3://"):
            raise ValueError(f"{url!r} is not an s3:// URL")
        bucket, _, prefix = url[len("s3://") :].partition("/")
        if not bucket:
            raise ValueError(f"{url!r}: no bucket, write s3://bucket/prefix")
        return cls(bucket, prefix, endpoint=endpoint, region=region, **kwargs)

    def __repr__(self) -> str:
        return f"S3Store(s3://{self.bucket}/{self.prefix}, endpoint={self.endpoint or 'AWS'})"

    # --- helpers -----------------------------------------------------------------------------------------

    def _key(self, key: str) -> str:
        _check_key(key)
        return f"{self.prefix}/{key}" if self.prefix else key

    def _redact(self, text: str) -> str:
        for secret in self._secrets:
            text = text.replace(secret, "***")
        return text

    def _where(self) -> str:
        return self.endpoint or "AWS"

    def _error(self, op: str, target: str, exc: BaseException) -> StoreError:
        from botocore.exceptions import ClientError, EndpointConnectionError

        cause: BaseException | None = exc
        while cause is not None and not isinstance(cause, (ClientError, EndpointConnectionError)):
            cause = cause.__cause__ or cause.__context__
        error_class: type[StoreError] = StoreError
        if isinstance(cause, ClientError):
            err = cause.response.get("Error", {})
            code = str(err.get("Code", ""))
            status = cause.response.get("ResponseMetadata", {}).get("HTTPStatusCode")
            if code == "NoSuchBucket":
                reason = f"bucket {self.bucket!r} does not exist"
            elif code in ("NoSuchKey", "NotFound", "404"):
                reason = "no such object"
                error_class = NotFoundError
            elif code == "InvalidAccessKeyId":
                reason = f"the access key id is not known to the server ({_CREDENTIAL_HINT})"
            elif code == "SignatureDoesNotMatch":
                reason = f"the request signature does not match: wrong secret key ({_CREDENTIAL_HINT})"
            elif code in ("AccessDenied", "403", "Forbidden") or status == 403:
                reason = f"access denied ({_CREDENTIAL_HINT} and the bucket policy)"
            else:
                reason = f"{code or status}: {err.get('Message', '')}".rstrip(": ")
        elif isinstance(cause, EndpointConnectionError):
            reason = f"cannot connect to the endpoint {self._where()}"
        else:
            reason = f"{type(exc).__name__}: {exc}"
        return error_class(self._redact(f"S3 {op} {target} (endpoint {self._where()}) failed: {reason}"))

    def _retrying(self, op: str, target: str, call: Callable[[], T]) -> T:
        """`call()`, retried with backoff while it fails transiently (is_transient), for at most
        `self.outage` seconds; other failures and the last one raise StoreError naming the object."""
        from boto3.exceptions import S3UploadFailedError
        from botocore.exceptions import BotoCoreError, ClientError

        started = time.monotonic()
        delays = backoff_delays(self.outage)
        while True:
            try:
                return call()
            except (BotoCoreError, ClientError, S3UploadFailedError) as exc:
                delay = next(delays, None) if is_transient(exc) else None
                if delay is None or time.monotonic() - started + delay > self.outage:
                    error = self._error(op, target, exc)
                    if is_transient(exc):
                        waited = time.monotonic() - started
                        error = type(error)(f"{error} (still failing after {waited:.0f} s of retries)")
                    raise error from exc
                time.sleep(delay)

    # --- API ---------------------------------------------------------------------------------------------

    def check_bucket(self) -> None:
        """Raise StoreError unless the bucket exists and the credentials may use it."""
        from botocore.exceptions import ClientError

        try:
            self._retrying(
                "access to bucket",
                f"s3://{self.bucket}",
                lambda: self._client.head_bucket(Bucket=self.bucket),
            )
        except StoreError as exc:
            cause = exc.__cause__
            code = (
                str(cause.response.get("Error", {}).get("Code", "")) if isinstance(cause, ClientError) else ""
            )
            if code in ("404", "NoSuchBucket", "NotFound"):
                raise StoreError(
                    f"S3 bucket {self.bucket!r} does not exist at {self._where()}: create it first"
                ) from cause
            raise

    def put_bytes(self, key: str, data: bytes) -> None:
        full = self._key(key)
        self._retrying(
            "put", self.url_for(key), lambda: self._client.put_object(Bucket=self.bucket, Key=full, Body=data)
        )

    def put_file(
        self,
        key: str,
        local_path: str | os.PathLike[str],
        *,
        progress: Callable[[int], None] | None = None,
    ) -> None:
        """Upload a file (multipart above the threshold); `progress` is called with bytes sent so far
        per part (boto3's Callback). The key appears only once the whole upload has completed."""
        full = self._key(key)
        if not Path(local_path).is_file():
            raise StoreError(f"cannot upload {local_path} to {self.url_for(key)}: not a file")
        self._retrying(
            "upload",
            self.url_for(key),
            lambda: self._client.upload_file(
                os.fspath(local_path), self.bucket, full, Config=self._transfer, Callback=progress
            ),
        )

    def get_bytes(self, key: str) -> bytes:
        full = self._key(key)
        return self._retrying(
            "get",
            self.url_for(key),
            lambda: bytes(self._client.get_object(Bucket=self.bucket, Key=full)["Body"].read()),
        )

    def exists(self, key: str) -> bool:
        full = self._key(key)
        try:
            self._retrying(
                "head", self.url_for(key), lambda: self._client.head_object(Bucket=self.bucket, Key=full)
            )
        except NotFoundError:
            return False
        return True

    def list(self, prefix: str = "") -> list[str]:
        """Keys (relative to the store's prefix) starting with `prefix`, sorted."""
        _check_prefix(prefix)
        base = f"{self.prefix}/" if self.prefix else ""

        def keys() -> list[str]:
            found: list[str] = []
            paginator = self._client.get_paginator("list_objects_v2")
            for page in paginator.paginate(Bucket=self.bucket, Prefix=base + prefix):
                found.extend(obj["Key"][len(base) :] for obj in page.get("Contents", []))
            return found

        return sorted(self._retrying("list", f"s3://{self.bucket}/{base}{prefix}", keys))

    def url_for(self, key: str) -> str:
        return f"s3://{self.bucket}/{self._key(key)}"

    def sync(self) -> None:
        """Nothing to do: an object S3 acknowledged is durable."""
