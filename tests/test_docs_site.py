"""The documentation site builds with `mkdocs build --strict` (a broken link or anchor fails, as `make docs` in
CI), every page of docs/ is in the nav, and a built page renders in headless Chromium (served over HTTP, as a
reader gets it) without a console error. Skips the browser part without Debian's chromium."""

from __future__ import annotations

import functools
import http.server
import os
import re
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from tests.chromium import find_chromium, load_page
from tools.docs_pictures import PICTURES

ROOT = Path(__file__).resolve().parents[1]


def nav_pages(nav: object) -> Iterator[str]:
    if isinstance(nav, str):
        yield nav
    elif isinstance(nav, list):
        for item in nav:
            yield from nav_pages(item)
    elif isinstance(nav, dict):
        for value in nav.values():
            yield from nav_pages(value)


def test_every_page_is_in_the_nav() -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    listed = set(nav_pages(config["nav"]))
    pages = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    assert pages - listed == set(), "pages missing from mkdocs.yml's nav"
    assert listed - pages == set(), "nav entries without a page"


def mkdocs_build(source: Path, out: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=source,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """mkdocs.yml and docs/ with the pictures made as `make docs` makes them (tools/docs_pictures.py)."""
    if find_chromium() is None:
        pytest.skip(
            "Debian's chromium is not installed: the docs' report picture needs it (make docs installs it)"
        )
    source = tmp_path_factory.mktemp("docs-source")
    shutil.copy2(ROOT / "mkdocs.yml", source / "mkdocs.yml")
    shutil.copytree(ROOT / "docs", source / "docs", ignore=shutil.ignore_patterns("generated"))
    made = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "docs_pictures.py"),
            str(source / "docs" / "images" / "generated"),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert made.returncode == 0, made.stderr[-3000:]
    return source


@pytest.fixture(scope="module")
def site(sources: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    result = mkdocs_build(sources, out)
    assert result.returncode == 0, result.stderr[-3000:]
    return out


def test_the_pages_show_pictures_made_from_a_real_run(site: Path) -> None:
    """At least three pictures, every one made by the docs build (docs/images/generated/, git-ignored) and
    none drawn by hand: no other image is in docs/."""
    shown = {
        name
        for page in (ROOT / "docs").rglob("*.md")
        for name in re.findall(r"!\[[^\]]*\]\((?:\.\./)*images/generated/([^)]+)\)", page.read_text())
    }
    assert len(shown) >= 3 and shown <= set(PICTURES), shown
    for name in shown:
        assert (site / "images" / "generated" / name).stat().st_size > 1_000, name
    drawn = [p for p in (ROOT / "docs").rglob("*") if p.suffix.lower() in {".png", ".svg", ".jpg", ".gif"}]
    assert all("generated" in p.parts for p in drawn), drawn
    svg = (site / "images" / "generated" / "heat-map.svg").read_text()
    assert svg.lstrip().startswith("<?xml") and "pass/fail heat map over EgoSpeed and CutInGap" in svg


def test_the_docs_build_fails_when_a_picture_is_missing(sources: Path, tmp_path: Path) -> None:
    copy = tmp_path / "source"
    shutil.copytree(sources, copy)
    (copy / "docs" / "images" / "generated" / "heat-map.svg").unlink()
    result = mkdocs_build(copy, tmp_path / "site")
    assert result.returncode != 0
    assert "images/generated/heat-map.svg" in result.stderr


def test_site_builds_strict(site: Path) -> None:
    for page in (
        "index.html",
        "getting-started/index.html",
        "reference/cli/index.html",
        "troubleshooting/index.html",
    ):
        assert (site / page).is_file(), page


@pytest.mark.skipif(find_chromium() is None, reason="Debian's chromium is not installed")
def test_getting_started_renders_in_chromium(site: Path) -> None:
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/getting-started/"
        page = load_page(url, '[...document.querySelectorAll("h2")].map(h => h.textContent.trim())')
    finally:
        server.shutdown()
        server.server_close()
    assert page.errors == []
    assert [h.rstrip("¶") for h in page.probe][:2] == ["Prerequisites", "From a clone"]
    assert len(page.screenshot) > 10_000
