"""report.html after `carlos run` and from `carlos report`: content, self-containment, and how it renders in
a real headless Chromium (skipped when Debian's `chromium` is not installed)."""

from __future__ import annotations

import io
import json
import math
import re
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simcore.report.html import constant_parameters, criteria_rows, margin, swept_parameters, worst_runs
from tests.chromium import find_chromium, load_page
from tests.test_cli import RUNS, carlos

SELECTED = (0, 5, 6, 11)  # not 0..k-1: the run-level summary must accept any selection


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path]:
    out = tmp_path_factory.mktemp("results")
    selection = [arg for i in SELECTED for arg in ("-i", str(i))]
    result = carlos("run", RUNS / "data-generation.yaml", "--output", f"file://{out}", "-j", "2", *selection)
    return result, out / "data-generation"


def test_a_selection_of_indexes_runs_and_writes_the_report_next_to_the_summary(
    demo: tuple[subprocess.CompletedProcess[str], Path],
) -> None:
    result, run_dir = demo
    assert result.returncode == 0, result.stderr + result.stdout
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["counts"] == {
        "total": 4,
        "passed": 4,
        "failed": 0,
        "errors": 0,
        "optionalFailed": 0,
        "missing": 0,
    }
    assert f"report: {(run_dir / 'report.html').as_uri()}" in result.stdout
    page = (run_dir / "report.html").read_text()
    assert "<h1>SimulationRun data-generation</h1>" in page
    # relative links to every index's recording and log, next to the summary
    for i in SELECTED:
        assert f'href="{i}/recording.mcap"' in page and f'href="{i}/log.txt"' in page


def test_report_is_self_contained(demo: tuple[subprocess.CompletedProcess[str], Path]) -> None:
    page = (demo[1] / "report.html").read_text()
    assert "<script" not in page and "<link" not in page and "<img" not in page
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", page)
    assert not re.search(r"url\((?!#)", page)  # only references to the page's own SVG definitions
    assert page.count('<svg role="img"') >= 2 + 4  # heat map, distributions, a bird's-eye plot per index


def test_report_command_writes_the_file_with_absolute_links(
    demo: tuple[subprocess.CompletedProcess[str], Path], tmp_path: Path
) -> None:
    _, run_dir = demo
    target = tmp_path / "r.html"
    result = carlos("report", run_dir.parent.as_uri(), "--out", target, "--worst", "2")
    assert result.returncode == 0, result.stderr
    page = target.read_text()
    assert f'href="{(run_dir / "5" / "recording.mcap").as_uri()}"' in page
    assert page.count("bird&#x27;s-eye view") == 2
    assert "pass/fail heat map over" in page


def test_report_on_a_path_without_results_is_bad_input(tmp_path: Path) -> None:
    result = carlos("report", tmp_path.as_uri())
    assert result.returncode == 2
    assert "RESULTS_URL" in result.stderr and "not the results of one run" in result.stderr
    assert "Traceback" not in result.stderr
    result = carlos("report", "ftp://x/y")
    assert result.returncode == 2 and "unsupported store URL" in result.stderr


@pytest.mark.skipif(
    find_chromium() is None, reason="Debian's chromium is not installed (apt-get install chromium)"
)
def test_report_renders_its_plots_in_headless_chromium(
    demo: tuple[subprocess.CompletedProcess[str], Path], tmp_path: Path
) -> None:
    from PIL import Image

    probe = """[...document.querySelectorAll('svg.plot')].map(s => {
        const r = s.getBoundingClientRect();
        return {w: r.width, h: r.height, paths: s.querySelectorAll('path').length,
                label: s.getAttribute('aria-label')};
    })"""
    page = load_page(demo[1] / "report.html", probe)
    assert page.errors == []
    plots = page.probe
    assert len(plots) >= 6
    assert all(p["w"] > 300 and p["h"] > 150 and p["paths"] > 10 for p in plots), plots
    (tmp_path / "report.png").write_bytes(page.screenshot)
    image = Image.open(io.BytesIO(page.screenshot)).convert("RGB")
    assert image.height > 2000
    colours = {colour for _, colour in image.getcolors(maxcolors=1 << 20) or []}
    # drawn, not blank: the pass colour of the heat map, the histogram bars, the first trajectory's colour
    for wanted in ((0x2E, 0x7D, 0x32), (0x15, 0x65, 0xC0), (0x1F, 0x77, 0xB4)):
        assert wanted in colours, wanted


def _criterion(
    name: str, expected: str, actual: float | None, metric: str = "minTimeHeadway"
) -> dict[str, object]:
    passed = actual is not None and margin(expected, actual) is not None and margin(expected, actual) >= 0  # type: ignore[operator]
    return {"name": name, "metric": metric, "expected": expected, "actual": actual, "passed": passed}


def test_worst_runs_rank_errors_failures_by_margin_collisions_then_the_tightest_per_criterion_and_ttc() -> (
    None
):
    assert margin(">= 2", 1.0) == -0.5 and margin("< 5", 4.0) == 0.2 and margin(">= 0.5", 1.0) == 0.5
    assert margin(">= 2", None) is None
    indexes = [
        {"index": 0, "status": "passed", "metrics": {"minDistance": 0.5, "minTimeHeadway": 3.0},
         "criteria": [_criterion("THW", "> 1", 3.0)]},
        {"index": 1, "status": "passed", "metrics": {"minDistance": 6.0, "minTimeHeadway": 1.1},
         "criteria": [_criterion("THW", "> 1", 1.1)]},
        {"index": 2, "status": "failed", "metrics": {"minDistance": 9.0, "minTimeHeadway": 0.9},
         "criteria": [_criterion("THW", "> 1", 0.9)]},
        {"index": 3, "status": "failed", "metrics": {"minDistance": 9.0, "minTimeHeadway": 0.2},
         "criteria": [_criterion("THW", "> 1", 0.2)]},
        {"index": 4, "status": "passed", "metrics": {"collision": 1.0, "minDistance": 0.0}, "criteria": []},
        {"index": 5, "status": "error", "metrics": {}},
        {"index": 6, "status": "passed", "metrics": {"minTimeToCollision": 0.8, "minDistance": 3.0}},
    ]  # fmt: skip
    ranked = [(s["index"], reason) for s, reason in worst_runs(indexes, 7)]
    assert ranked == [
        (5, "error"),
        (3, "failed THW (minTimeHeadway = 0.2 s)"),  # further outside the threshold than index 2
        (2, "failed THW (minTimeHeadway = 0.9 s)"),
        (4, "collision"),
        (
            1,
            "closest to THW (minTimeHeadway = 1.1 s)",
        ),  # the tightest passed headway, not the smallest distance
        (6, "smallest minTimeToCollision (0.8 s)"),
        (0, "next tightest"),  # the smallest headway (3) and distance (4) are already shown
    ]
    assert [s["index"] for s, _ in worst_runs(indexes, 3)] == [5, 3, 2]
    # an equality that holds is close to nothing: no "margin -0" title
    held = [
        {
            "index": 0,
            "status": "passed",
            "metrics": {},
            "criteria": [_criterion("collision == 0", "== 0", 0.0, "collision")],
        }
    ]
    assert worst_runs(held, 1) == [(held[0], "next tightest")]


def test_constant_parameters_are_those_every_run_shares() -> None:
    runs = [{"parameters": {"a": 1, "b": 2, "c": 3}}, {"parameters": {"a": 1, "b": 5, "c": 3}}]
    assert constant_parameters(runs) == {"a": 1, "c": 3}
    assert constant_parameters([]) == {}


def test_criteria_rows_and_swept_parameters() -> None:
    def summary(i: int, speed: float, actual: float | None, passed: bool) -> dict[str, object]:
        return {
            "index": i,
            "scenario": "s",
            "parameters": {"speed": speed, "gap": 1.0, "mode": "a"},
            "criteria": [
                {
                    "name": "minDistance >= 2",
                    "metric": "minDistance",
                    "expected": ">= 2",
                    "actual": actual,
                    "passed": passed,
                    "optional": False,
                }
            ],
        }

    rows = criteria_rows(
        [summary(0, 10.0, 3.0, True), summary(1, 20.0, 1.0, False), summary(2, 30, None, False)]
    )
    assert rows == [
        {
            "scenario": "s",
            "criterion": "minDistance >= 2",
            "metric": "minDistance",
            "expected": ">= 2",
            "optional": False,
            "passed": 1,
            "failed": 2,
            "values": [3.0, 1.0],
        }
    ]
    assert swept_parameters([summary(0, 10.0, 1, True), summary(1, 20.0, 1, True)]) == ["speed"]
    # manifest order, not the number of values nor the order the summaries happen to list them in
    two = [{"parameters": {"b": b, "a": a}} for a in (1, 2, 3) for b in (1, 2)]
    assert swept_parameters(two, ["a", "b"]) == ["a", "b"]
    assert swept_parameters(two, ["b", "a"]) == ["b", "a"]


def test_sweep_plots_are_svg_with_a_cell_per_value_pair_and_a_bar_per_bin() -> None:
    from simcore.report.plots import distributions, heat_map, share_colour

    assert (share_colour(0.0), share_colour(0.5), share_colour(1.0)) == ("#c62828", "#fdd835", "#2e7d32")
    points = [(x, y, x + y < 4 or i == 0) for i in range(2) for x in (1.0, 2.0, 3.0) for y in (0.5, 1.5)]
    svg = heat_map("speed", "gap", points)
    assert svg.startswith('<svg role="img" aria-label="pass/fail heat map over speed and gap" class="plot"')
    # x + y < 4 in 5 of the 6 cells; the sixth passed in one of its two runs
    assert svg.count(">2/2<") == 5 and svg.count(">1/2<") == 1 and svg.count(">0/2<") == 0
    assert svg.count(f'fill="{share_colour(1.0)}"') == 5  # the cells where every run passed
    assert f'fill="{share_colour(0.5)}"' in svg
    many = heat_map("a", "b", [(float(i), float(i % 3), i % 2 == 0) for i in range(30)])  # scatter
    assert many.count("a2.4 2.4") == 2 * 30
    hist = distributions({"minDistance": [1.0, 2.0, 2.5, 3.0, 9.0], "flat": [0.0, 1.0]})
    assert hist.count('fill="#1565c0"') >= 4 and ">minDistance<" in hist and ">flat<" in hist


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(-1e6, 1e6, allow_nan=False),
            st.sampled_from([0.0, -0.0, 0.1, 0.2, 0.30000000000000004, 1.0, 2.5, 1e-300]),
        ),
        max_size=60,
    ),
    st.integers(1, 25),
)
def test_a_histogram_is_numpys_without_numpy(values: list[float], bins: int) -> None:
    """The report's metric distributions count what `numpy.histogram` counts, with its very edges."""
    np = pytest.importorskip("numpy")
    from simcore.report.plots import histogram

    counts, edges = histogram(values, bins)
    expected_counts, expected_edges = np.histogram(np.asarray(values, dtype=float), bins=bins)
    assert counts == expected_counts.tolist()
    assert edges == expected_edges.tolist()


def test_a_histogram_refuses_what_numpy_refuses() -> None:
    from simcore.report.plots import histogram

    for bad in ([1.0, math.inf], [math.nan, 2.0], [2.0, math.nan]):
        with pytest.raises(ValueError):
            histogram(bad, 5)
    assert histogram([3.0], 2) == ([0, 1], [2.5, 3.0, 3.5])  # one value: its bins span it ± 0.5


def test_runs_table_columns_are_stable_with_units_and_a_missing_birds_eye_says_why(tmp_path: Path) -> None:
    """The same metric columns in every report (the criteria's other metrics after them), units in the
    headers, headers never broken inside a word; without recordings the bird's-eye section says why."""
    from simcore.report.html import RUNS_TABLE_METRICS
    from tests.test_cli import carlos
    from tests.test_compare import _manifest

    done = carlos("run", _manifest(tmp_path, "plain", [20.0, 28.0], 0.5), "-q", "-j", "1")
    assert done.returncode == 0, done.stderr
    page = (tmp_path / "results" / "plain" / "report.html").read_text()
    assert "overflow-wrap:anywhere" not in page
    header = page[page.index("<table class=runs>") :].split("</tr>")[0]
    columns = re.findall(r"<th>([A-Za-z.]+)", header)
    assert columns[-len(RUNS_TABLE_METRICS) :] == list(RUNS_TABLE_METRICS)
    assert "minTimeToCollision<br><span class=unit>(s)</span>" in header
    assert "Not drawn: this run recorded nothing" in page and "spec.recording.enabled: false" in page
    assert "margin -0" not in page and "margin +" not in page
