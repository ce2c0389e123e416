"""Points as an OpenSCENARIO ParameterValueDistribution (a ValueSetDistribution, one set per point).

The same file runs a search's rounds (as the derived sweep's `distribution`) and exports its failing
points as a regression suite: `spec.sweep.distribution: failing.xosc` runs each of them again.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

from simcore.scenario.parameters import format_value
from simcore.spec import ParameterValue


def distribution_xml(
    scenario_file: Path, points: Sequence[Mapping[str, ParameterValue]], description: str
) -> bytes:
    root = ET.Element("OpenSCENARIO")
    ET.SubElement(
        root,
        "FileHeader",
        revMajor="1",
        revMinor="2",
        date="2026-01-01T00:00:00",
        author="CARLOS search",
        description=description,
    )
    pvd = ET.SubElement(root, "ParameterValueDistribution")
    ET.SubElement(pvd, "ScenarioFile", filepath=str(scenario_file))
    deterministic = ET.SubElement(pvd, "Deterministic")
    multi = ET.SubElement(deterministic, "DeterministicMultiParameterDistribution")
    sets = ET.SubElement(multi, "ValueSetDistribution")
    for point in points:
        values = ET.SubElement(sets, "ParameterValueSet")
        for name, value in point.items():
            ET.SubElement(values, "ParameterAssignment", parameterRef=name, value=format_value(value))
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"
