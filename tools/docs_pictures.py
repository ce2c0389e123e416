"""The documentation's pictures, made from a real run by `make docs` before the site is built (never drawn by
hand, never committed: docs/images/generated/ is git-ignored, so a page that shows one fails the strict
build when it is missing).

    python tools/docs_pictures.py [OUT_DIR]      (default: docs/images/generated)

Runs examples/runs/data-generation.yaml (the 12-run sweep of `make demo`) with one criterion added,
`minTimeHeadway >= 1.0` (so that some runs fail and the heat map shows where), into a scratch folder with the
`carlos` of this interpreter, then writes:
- report.png: the run's report.html in headless Chromium (Debian's `chromium`), its first screen;
- heat-map.svg, distributions.svg, birds-eye.svg: the report's own figures (inline SVG), as files.
Exit 1 with one line when a picture could not be made (no Chromium, a failed run, a figure missing).
"""

from __future__ import annotations

import html
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "examples" / "runs" / "data-generation.yaml"
#: what the pictured run adds to the example: a criterion that some of its runs miss
CRITERION = "minTimeHeadway >= 1.0"
#: file → the aria-label its figure starts with in report.html
FIGURES = {
    "heat-map.svg": "pass/fail heat map",
    "distributions.svg": "metric distributions",
    "birds-eye.svg": "bird's-eye view",
}
PICTURES = ("report.png", *FIGURES)
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--hide-scrollbars",
)


def fail(message: str) -> None:
    sys.exit(f"docs pictures: {message}")


def figures(page: str) -> dict[str, str]:
    """The first inline <svg> of each kind in a report page, by picture file name."""
    found: dict[str, str] = {}
    for match in re.finditer(r"<svg\b[^>]*aria-label=\"([^\"]*)\"[^>]*>.*?</svg>", page, re.S):
        label = html.unescape(match.group(1))
        for name, prefix in FIGURES.items():
            if name not in found and label.startswith(prefix):
                found[name] = '<?xml version="1.0" encoding="UTF-8"?>\n' + match.group(0) + "\n"
    return found


def screenshot(page: Path, out: Path, width: int = 1200, height: int = 1500) -> None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        fail(
            "needs Debian's chromium for report.png (apt-get install chromium; make docs installs it as root)"
        )
    with tempfile.TemporaryDirectory() as profile:
        done = subprocess.run(
            [
                chromium,
                *CHROMIUM_FLAGS,
                f"--user-data-dir={profile}",
                f"--window-size={width},{height}",
                f"--screenshot={out}",
                page.as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
    if done.returncode != 0 or not out.is_file() or out.stat().st_size == 0:
        fail(f"chromium made no screenshot of {page} (exit {done.returncode}): {done.stderr.strip()[-300:]}")


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name in PICTURES:
        (out / name).unlink(missing_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        results = Path(scratch) / "results"
        manifest = Path(scratch) / MANIFEST.name
        body = yaml.safe_load(MANIFEST.read_text(encoding="utf-8"))
        for scenario in body["spec"]["scenarios"]:
            scenario["openscenario"] = str((MANIFEST.parent / scenario["openscenario"]).resolve())
        body["spec"].setdefault("evaluation", {}).setdefault("criteria", []).append(CRITERION)
        manifest.write_text(yaml.safe_dump(body, sort_keys=False), encoding="utf-8")
        run = subprocess.run(
            [sys.executable, "-m", "simcore.cli", "run", str(manifest), "--output", results.as_uri(), "-q"],
            capture_output=True,
            text=True,
            timeout=900,
            cwd=scratch,
        )
        if run.returncode not in (0, 1):  # 1: a run missed the criterion, as meant
            fail(f"carlos run {MANIFEST.name} exited {run.returncode}: {run.stderr.strip()[-300:]}")
        report = results / "data-generation" / "report.html"
        page = report.read_text(encoding="utf-8")
        for name, svg in figures(page).items():
            (out / name).write_text(svg, encoding="utf-8")
        screenshot(report, out / "report.png")
    missing = [name for name in PICTURES if not (out / name).is_file()]
    if missing:
        fail(f"not made: {', '.join(missing)}")
    print(f"docs pictures: {', '.join(PICTURES)} in {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "images" / "generated")
