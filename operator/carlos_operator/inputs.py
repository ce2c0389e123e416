"""The inputs the operator reads itself, before any pod starts: a search's scenario (to choose its points)
and a sweep's distribution file (to count and expand the sweep). Each comes from a ConfigMap key of the
run's namespace, from `s3://bucket/key` (with the run's credentials where its namespace may name Secrets,
else the operator's own, as for its results), or from a file the operator can read."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from carlos_operator.builders import Output
from carlos_operator.kube import NotFound
from simcore.errors import BadInput
from simcore.spec import ConfigMapKeyRef

if TYPE_CHECKING:
    from carlos_operator.hosting import Host


def read_input(
    c: Host,
    namespace: str,
    output: Output,
    *,
    ref: ConfigMapKeyRef | None,
    source: str | None,
    field: str,
    ref_field: str,
    why: str,
    configmap: Mapping[str, Any] | None = None,
) -> tuple[str, bytes]:
    """(file name, bytes) of an input given as a ConfigMap key (`ref`, the field `ref_field`; `configmap`: that
    ConfigMap when the caller has read it already) or a URL or path (`source`, the field `field`); BadInput
    naming the field when it cannot be read (`why`: what the operator reads it for)."""
    if ref is not None:
        if configmap is None:
            try:
                configmap = c.kube.read_configmap(namespace, ref.name)
            except NotFound:
                configmap = {}
        data = configmap.get("data") or {}
        if ref.key not in data:
            raise BadInput(f"ConfigMap {ref.name!r} has no key {ref.key!r}", field=f"{ref_field}.key")
        return ref.key, str(data[ref.key]).encode()
    source = source or ""
    name = source.rsplit("/", 1)[-1] or "input.xosc"
    if source.startswith("s3://"):
        from simcore.store import NotFoundError

        bucket, _, key = source.removeprefix("s3://").partition("/")
        allowed = namespace in c.settings.secret_namespaces
        where = dataclasses.replace(output, url=f"s3://{bucket}", secret=output.secret if allowed else None)
        store = c.store_factory(c.kube, namespace, where)
        try:
            return name, bytes(store.get_bytes(key))
        except NotFoundError:
            raise BadInput(f"{source} does not exist", field=field) from None
    path = source.removeprefix("file://")
    if os.path.isfile(path):
        return name, Path(path).read_bytes()
    raise BadInput(
        f"{source!r}: the operator reads this file {why}, and it is only inside the simcore image: give it as "
        "a ConfigMap key (carlos submit packs it) or as s3://bucket/key",
        field=field,
    )
