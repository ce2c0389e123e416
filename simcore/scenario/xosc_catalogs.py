"""Catalogs for the OpenSCENARIO parser: the directories of CatalogLocations and the entry a CatalogReference
names, with its parameter assignments (each catalog file read once per load, parsed once per process for its
content; its elements' file and lines kept for messages).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from simcore.scenario.parameters import ParamValue
from simcore.scenario.xosc_reader import _Reader
from simcore.scenario.xosc_xml import parsed_xml


def _catalog_dirs(reader: _Reader, root: ET.Element) -> dict[str, Path]:
    dirs: dict[str, Path] = {}
    block = root.find("CatalogLocations")
    if block is None:
        return dirs
    for location in block:
        directory = location.find("Directory")
        if directory is not None:
            raw = reader.attr(directory, "path")
            kind = location.tag.removesuffix("Catalog")
            dirs[kind] = (reader.path.parent / raw).resolve()
            line = reader.line(directory)
            reader.catalog_origins[kind] = f"CatalogLocations/{location.tag}/Directory path={raw!r}" + (
                f" (line {line})" if line else ""
            )
    return dirs


def _catalog_entry(
    reader: _Reader, ref: ET.Element, catalogs: dict[str, Path], kind: str | tuple[str, ...]
) -> tuple[ET.Element, dict[str, ParamValue]]:
    """The catalog entry a CatalogReference names (searched in the catalog locations of `kind`, then in all
    locations), with its parameter assignments."""
    catalog_name = reader.attr(ref, "catalogName")
    entry_name = reader.attr(ref, "entryName")
    kinds = (kind,) if isinstance(kind, str) else kind
    assignments: dict[str, ParamValue] = {}
    block = ref.find("ParameterAssignments")
    if block is not None:
        for item in block.findall("ParameterAssignment"):
            name = item.get("parameterRef") or ""
            if not name:
                raise reader.fail("ParameterAssignment without parameterRef", item)
            assignments[name.lstrip("$")] = reader.attr(item, "value")
    directories = [catalogs[k] for k in kinds if k in catalogs]
    directories += [d for k, d in catalogs.items() if k not in kinds]
    if not directories:
        raise reader.fail(
            f"CatalogReference to {catalog_name}/{entry_name} but no {kinds[0]}Catalog location", ref
        )
    for directory in dict.fromkeys(directories):
        # a directory of catalog files, or (as esmini accepts) the path of one catalog file
        files = sorted(directory.glob("*.xosc")) if directory.is_dir() else []
        if not files and directory.suffix == ".xosc" and directory.is_file():
            files = [directory]
        for file in files:
            if file not in reader._catalog_files:
                parsed = parsed_xml(file, what="catalog")
                reader.lines.update(parsed.lines)
                reader._catalog_files[file] = parsed.root.find("Catalog")
                reader._catalog_roots.append(parsed.root)  # alive while loading: element ids stay unique
                reader.files.update(dict.fromkeys(parsed.ids, file))
            catalog = reader._catalog_files[file]
            # by the catalog's name, or by its file name (esmini accepts both)
            if catalog is None or catalog_name not in (catalog.get("name"), file.stem):
                continue
            for entry in catalog:
                if entry.get("name") == entry_name:
                    return entry, assignments
    searched = []
    for k, d in catalogs.items():
        origin = reader.catalog_origins.get(k, f"{k}Catalog")
        state = "" if d.is_dir() else ": no such directory"
        searched.append(f"{d} ({origin}{state})")
    raise reader.fail(
        f"catalog entry {catalog_name}/{entry_name} not found: no catalog named {catalog_name!r} with an entry "
        f"{entry_name!r} in {'; '.join(searched)}. Add the catalog file or correct CatalogLocations",
        ref,
    )
