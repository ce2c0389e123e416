"""OpenSCENARIO files against the official ASAM XSD of the revision they declare (1.0–1.3).

The scenario engine is lenient where esmini is (it reads what it understands and warns about the rest);
the XSD check is the strict view a catalogue maintainer wants before handing files to other tools:
`carlos validate --schema`. The schemas are the ones ASAM publishes, shipped in the PyPI package
`asam-qc-openscenarioxml` (`qc_openscenario/schema/<version>/OpenSCENARIO.xsd`); they are loaded once per
revision and process (about 0.8 s each), then a file takes milliseconds.

The file is untrusted: it is first parsed with defusedxml (`simcore.scenario.xosc_xml.read_xml`: size bound, no
entities, no external references), then with lxml without entity resolution or network access, only to
get the source line of every element for the report. Heavy imports (xmlschema, lxml) happen on first use.
"""

from __future__ import annotations

import functools
import importlib.resources
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simcore.errors import BadInput
from simcore.scenario.xosc_xml import read_xml

# revMinor → the newest published schema of that revision
SCHEMA_VERSIONS = {0: "1.0.0", 1: "1.1.1", 2: "1.2.0", 3: "1.3.0"}
SCHEMA_PACKAGE = "qc_openscenario"
SCHEMA_DISTRIBUTION = "asam-qc-openscenarioxml"
MAX_ISSUES = 100


@dataclass(frozen=True)
class SchemaIssue:
    """One XSD violation: the source line, the element's path and the schema's reason."""

    line: int | None
    path: str
    reason: str

    def __str__(self) -> str:
        where = f"line {self.line}" if self.line is not None else "?"
        return f"{where}: {self.path}: {self.reason}"


@dataclass
class SchemaReport:
    file: str
    version: str  # the schema version checked against, e.g. "1.2.0"
    declared: str  # the FileHeader's revMajor.revMinor, as written
    issues: list[SchemaIssue] = field(default_factory=list)
    truncated: bool = False  # more than MAX_ISSUES violations; only the first are listed
    note: str = ""  # e.g. an undeclared or unknown revision: which schema was used instead

    @property
    def valid(self) -> bool:
        return not self.issues


def schema_version(rev_major: str | None, rev_minor: str | None) -> tuple[str, str]:
    """(schema version, note) for a FileHeader's revision; unknown revisions get the newest schema."""
    newest = SCHEMA_VERSIONS[max(SCHEMA_VERSIONS)]
    try:
        major, minor = int(rev_major or ""), int(rev_minor or "")
    except ValueError:
        return newest, f"FileHeader revMajor/revMinor missing or not numbers: checked against {newest}"
    if major == 1 and minor in SCHEMA_VERSIONS:
        return SCHEMA_VERSIONS[minor], ""
    return newest, f"OpenSCENARIO {major}.{minor} has no published schema here: checked against {newest}"


@functools.lru_cache(maxsize=len(SCHEMA_VERSIONS))
def _schema(version: str) -> Any:
    try:
        import xmlschema

        root = importlib.resources.files(SCHEMA_PACKAGE)
    except ModuleNotFoundError:
        raise BadInput(
            f"the official OpenSCENARIO XSDs are not installed: pip install {SCHEMA_DISTRIBUTION} xmlschema",
            field="--schema",
        ) from None
    return xmlschema.XMLSchema(str(root / "schema" / version / "OpenSCENARIO.xsd"))


def check_openscenario(path: Path, max_issues: int = MAX_ISSUES) -> SchemaReport:
    """Validate one OpenSCENARIO file (scenario, catalog or ParameterValueDistribution) against the XSD
    of its declared revision. Raises BadInput when the file cannot be read or parsed at all."""
    root = read_xml(path, what="OpenSCENARIO file")  # the safe parse: size, entities, well-formedness
    header = root.find("FileHeader")
    declared_major = header.get("revMajor") if header is not None else None
    declared_minor = header.get("revMinor") if header is not None else None
    version, note = schema_version(declared_major, declared_minor)
    report = SchemaReport(
        file=str(path), version=version, declared=f"{declared_major}.{declared_minor}", note=note
    )

    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
    try:
        tree = etree.parse(str(path), parser)
    except (
        etree.XMLSyntaxError
    ) as exc:  # libxml2 is stricter than expat in a few places (the XML declaration)
        raise BadInput(f"OpenSCENARIO file is not well-formed XML: {exc}", file=str(path)) from None
    for error in _schema(version).iter_errors(tree):
        if len(report.issues) >= max_issues:
            report.truncated = True
            break
        line = getattr(error, "sourceline", None)
        report.issues.append(
            SchemaIssue(
                line=int(line) if isinstance(line, int) else None,
                path=str(error.path or ""),
                reason=str(error.reason or error.message).strip(),
            )
        )
    for issue in _integer_parameters(tree):
        if len(report.issues) >= max_issues:
            report.truncated = True
            break
        report.issues.append(issue)
    return report


INTEGER_TYPES = ("integer", "int", "unsignedInt", "unsignedShort")


def _integer_parameters(tree: Any) -> list[SchemaIssue]:
    """Integer parameters declared with a value that is no integer (`330.91`): the XSD types every value as
    a string, the standard's types do not allow it (`carlos run` reads the number, as esmini, and warns)."""
    issues = []
    for element in tree.iter("ParameterDeclaration"):
        kind, value = element.get("parameterType", ""), element.get("value", "")
        if kind not in INTEGER_TYPES or value[:1] == "$":
            continue
        try:
            int(value.strip())
        except ValueError:
            issues.append(
                SchemaIssue(
                    line=element.sourceline,
                    path=tree.getpath(element),
                    reason=f"parameter {element.get('name')!r} is declared {kind} but its value {value!r} "
                    "is not an integer",
                )
            )
    return issues
