"""YAML for Kubernetes: what kubectl, the API server and Helm read with Go's YAML 1.1 rules.

PyYAML writes the strings `y`, `n`, `on`, `off`, `yes`, `no` (and their capitalised forms) without quotes,
but Go's YAML 1.1 parser reads them as booleans: a CRD whose schema has a property `y` is then refused by the
API server ("cannot unmarshal bool into Go struct field … of type string"). `dump` quotes them, and every
other string that YAML 1.1 would not read back as the same string.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

#: plain scalars that YAML 1.1 (Go's sigs.k8s.io/yaml, yaml.v2) reads as booleans or null
_YAML11_SPECIAL = re.compile(
    r"^(y|Y|yes|Yes|YES|n|N|no|No|NO|true|True|TRUE|false|False|FALSE|on|On|ON|off|Off|OFF|null|Null|NULL|~)$"
)


class _Dumper(yaml.SafeDumper):
    pass


def _str(dumper: yaml.SafeDumper, value: str) -> yaml.ScalarNode:
    if _YAML11_SPECIAL.match(value):
        return dumper.represent_scalar("tag:yaml.org,2002:str", value, style="'")
    return dumper.represent_str(value)


_Dumper.add_representer(str, _str)


class _FastDumper(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):  # type: ignore[misc]
    pass


_FastDumper.add_representer(str, _str)


def dump_fast(data: Any, **kwargs: Any) -> str:
    """`dump` written by libyaml's emitter (about five times faster) where PyYAML has it: the same data, but
    long strings may wrap at other places than `dump` wraps them, so never compare its bytes with `dump`'s."""
    return str(yaml.dump(data, Dumper=_FastDumper, **kwargs))


def dump(data: Any, **kwargs: Any) -> str:
    """`yaml.safe_dump` whose output Go's YAML parser reads back as the same data."""
    return str(yaml.dump(data, Dumper=_Dumper, **kwargs))


def dump_all(documents: Any, **kwargs: Any) -> str:
    return str(yaml.dump_all(documents, Dumper=_Dumper, **kwargs))
