"""`carlos compare`: runs of two real result folders (written by `carlos run`) matched by scenario,
parameters and seed; verdicts, exit codes, Markdown, JUnit and the candidate's report section."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from simcore.compare import classify, compare, markdown, metric_changes, run_key
from tests.s3server import S3Server
from tests.test_cli import ROOT, carlos

SCENARIO = ROOT / "examples" / "scenarios" / "cut-in.xosc"


def _manifest(directory: Path, name: str, speeds: list[float], threshold: float) -> Path:
    path = directory / f"{name}.yaml"
    path.write_text(
        "\n".join(
            [
                "apiVersion: carlos.dev/v1alpha1",
                "kind: SimulationRun",
                f"metadata: {{name: {name}}}",
                "spec:",
                f"  scenarios: [{{name: cut-in, openscenario: {json.dumps(str(SCENARIO))}}}]",
                f'  evaluation: {{criteria: ["minDistance >= {threshold}"]}}',
                f"  sweep: {{matrix: {{EgoSpeed: {json.dumps(speeds)}}}}}",
                "  simulation: {stepSeconds: 0.1, maxSeconds: 8, seed: 3}",
                "  recording: {enabled: false}",
                f"  output: {{url: {json.dumps((directory / 'results').as_uri())}}}",
            ]
        )
        + "\n"
    )
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """baseline: EgoSpeed 20 and 28, every run passes; candidate: 20 and 24, an impossible threshold."""
    work = tmp_path_factory.mktemp("compare")
    for name, speeds, threshold, code in (("base", [20.0, 28.0], 0.0, 0), ("cand", [20.0, 24.0], 1000.0, 1)):
        done = carlos("run", _manifest(work, name, speeds, threshold), "-q", "-j", "2")
        assert done.returncode == code, done.stderr + done.stdout
    return work / "results" / "base", work / "results" / "cand"


def test_new_failure_added_and_removed_runs_exit_1_with_markdown_and_junit(
    runs: tuple[Path, Path], tmp_path: Path
) -> None:
    base, cand = runs
    md, junit = tmp_path / "c.md", tmp_path / "c.xml"
    done = carlos("compare", base.as_uri(), cand.as_uri(), "--markdown", md, "--junit", junit)
    assert done.returncode == 1, done.stderr
    assert "1 new failure · 0 fixed · 0 still failing · 0 still passing · 1 added · 1 removed" in done.stdout
    assert "new failure: cut-in[0] EgoSpeed=20: minDistance >= 1000" in done.stdout
    text = md.read_text()
    assert text.startswith("### CARLOS compare: ❌ 1 new failure\n")
    assert "#### New failures (1)" in text and "| cut-in[0] EgoSpeed=20 | passed | failed |" in text
    assert "#### Added runs (1)" in text and "cut-in[1] EgoSpeed=24" in text
    assert "#### Removed runs (1)" in text and "cut-in[1] EgoSpeed=28" in text
    root = ET.parse(junit).getroot()
    cases = {c.get("name"): c for c in root.iter("testcase")}
    assert set(cases) == {"cut-in[0] EgoSpeed=20", "cut-in[1] EgoSpeed=24", "cut-in[1] EgoSpeed=28"}
    assert cases["cut-in[0] EgoSpeed=20"].find("failure") is not None
    assert cases["cut-in[1] EgoSpeed=24"].find("failure") is None  # added: failing, but not a regression
    assert cases["cut-in[1] EgoSpeed=28"].find("skipped") is not None  # removed


def test_the_spec_differences_come_first(runs: tuple[Path, Path], tmp_path: Path) -> None:
    """A changed threshold explains a changed verdict: it is listed before the verdicts, in the terminal and
    in the Markdown."""
    base, cand = runs
    done = carlos("compare", base.as_uri(), cand.as_uri(), "--markdown", tmp_path / "c.md")
    lines = done.stdout.splitlines()
    assert lines[0].startswith("the specs differ"), done.stdout
    assert (
        "  criteria: removed 'minDistance >= 0.0'" in lines
        and "  criteria: added 'minDistance >= 1000.0'" in lines
    )
    assert "  sweep.matrix EgoSpeed: [20.0, 28.0] → [20.0, 24.0]" in lines
    assert lines.index("  sweep.matrix EgoSpeed: [20.0, 28.0] → [20.0, 24.0]") < next(
        i for i, line in enumerate(lines) if "new failure" in line
    )
    text = (tmp_path / "c.md").read_text()
    assert text.index("#### The specs differ") < text.index("| verdict | runs |")
    # the same spec, the same scenario file: nothing listed
    same = carlos("compare", cand.as_uri(), cand.as_uri())
    assert "the specs differ" not in same.stdout


def test_a_changed_scenario_file_is_listed_by_its_digest(tmp_path: Path) -> None:
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "maps").symlink_to(ROOT / "examples" / "maps")
    scenario = tmp_path / "scenarios" / "s.xosc"
    scenario.write_bytes(SCENARIO.read_bytes())
    outputs = []
    for name in ("one", "two"):
        manifest = _manifest(tmp_path, name, [20.0], 0.0)
        text = manifest.read_text().replace(json.dumps(str(SCENARIO)), json.dumps(str(scenario)))
        manifest.write_text(text.replace(f"name: {name}", "name: same"))
        done = carlos("run", manifest, "-q", "--output", (tmp_path / name).as_uri())
        assert done.returncode == 0, done.stderr
        outputs.append(tmp_path / name / "same")
        scenario.write_bytes(scenario.read_bytes() + b"\n")  # the same scenario, other bytes
    done = carlos("compare", outputs[0].as_uri(), outputs[1].as_uri())
    assert done.returncode == 0, done.stderr
    assert "  scenario cut-in: file contents differ" in done.stdout


def test_nothing_matched_is_bad_input_not_a_pass(runs: tuple[Path, Path], tmp_path: Path) -> None:
    """A gate that compared nothing must not pass: two runs with no run in common are exit 2, one line."""
    manifest = _manifest(tmp_path, "other", [21.0, 22.0], 0.0)
    assert carlos("run", manifest, "-q").returncode == 0
    done = carlos("compare", runs[0].as_uri(), (tmp_path / "results" / "other").as_uri())
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "nothing was compared" in lines[0] and "2 added, 2 removed" in lines[0]
    assert "EgoSpeed" in lines[0] and "Traceback" not in done.stderr


def test_fixed_and_still_failing_exit_0(runs: tuple[Path, Path]) -> None:
    base, cand = runs
    done = carlos("compare", cand.as_uri(), base.as_uri(), "--markdown", "-")
    assert done.returncode == 0, done.stderr
    assert "0 new failures · 1 fixed" in done.stdout and "✅ no new failures" in done.stdout
    done = carlos("compare", cand.as_uri(), cand.as_uri())
    assert done.returncode == 0, done.stderr
    assert "0 new failures · 0 fixed · 2 still failing · 0 still passing · 0 added · 0 removed" in done.stdout
    assert "0 with metric changes" in done.stdout  # the same results: no metric moved


def test_report_option_adds_a_comparison_section_to_the_candidates_report(runs: tuple[Path, Path]) -> None:
    base, cand = runs
    done = carlos("compare", base.as_uri(), cand.as_uri(), "--report")
    assert done.returncode == 1, done.stderr
    assert f"report: {(cand / 'report.html').as_uri()}" in done.stdout
    stored = json.loads((cand / "comparison.json").read_text())
    assert stored["counts"]["new failure"] == 1 and stored["exitCode"] == 1
    page = (cand / "report.html").read_text()
    assert "<h2>Compared with the baseline</h2>" in page and "new failure" in page
    # `carlos report` keeps the section (it reads comparison.json)
    assert carlos("report", cand.as_uri()).returncode == 0
    assert "<h2>Compared with the baseline</h2>" in (cand / "report.html").read_text()
    # the candidate run again (a new summary.json): its report no longer shows the old comparison
    (cand / "summary.json").write_text((cand / "summary.json").read_text().replace("{", "{ ", 1))
    assert carlos("report", cand.as_uri()).returncode == 0
    assert "Compared with the baseline" not in (cand / "report.html").read_text()


def test_bad_input_is_one_line_and_exit_2(runs: tuple[Path, Path], tmp_path: Path) -> None:
    done = carlos("compare", tmp_path.as_uri(), runs[1].as_uri())
    assert done.returncode == 2 and "BASELINE" in done.stderr and "Traceback" not in done.stderr
    done = carlos("compare", runs[0].as_uri(), "ftp://x/y")
    assert done.returncode == 2 and "unsupported store URL" in done.stderr


def _summary(index: int, status: str, seed: int = 0, **metrics: float) -> dict[str, object]:
    return {"index": index, "scenario": "s", "parameters": {"a": 1, "b": 2}, "seed": seed, "status": status,
            "metrics": metrics}  # fmt: skip


def test_matching_is_by_scenario_parameters_and_seed_and_repeats_pair_in_order() -> None:
    assert run_key({"scenario": "s", "parameters": {"a": 1, "b": 2}, "seed": 0}) == run_key(
        {"scenario": "s", "parameters": {"b": 2, "a": 1}, "seed": 0}
    )
    assert [classify(a, b) for a, b in (("passed", "failed"), ("error", "passed"), ("failed", "error"))] == [
        "new failure",
        "fixed",
        "still failing",
    ]
    baseline = [_summary(0, "passed"), _summary(1, "passed"), _summary(2, "passed", seed=1)]
    candidate = [_summary(5, "passed"), _summary(6, "failed"), _summary(7, "passed", seed=2)]
    result = compare(baseline, candidate)
    assert [(r.verdict, r.baseline and r.baseline["index"]) for r in result.runs] == [
        ("still passing", 0),
        ("new failure", 1),
        ("added", None),
        ("removed", 2),
    ]
    assert result.exit_code == 1


def test_metric_changes_beyond_the_tolerance() -> None:
    changes = metric_changes({"minDistance": 10.0, "maxSpeed": 20.0, "gone": 1.0}, {"minDistance": 10.4,
                             "maxSpeed": 23.0, "new": 2.0}, 0.05)  # fmt: skip
    assert [(c.metric, c.baseline, c.candidate) for c in changes] == [("maxSpeed", 20.0, 23.0)]
    result = compare([_summary(0, "passed", minDistance=1.0)], [_summary(0, "passed", minDistance=2.0)])
    assert len(result.changed_metrics) == 1 and result.exit_code == 0
    # near-zero noise is no change: 14 % relative, but 0.0035 m/s² absolute
    assert metric_changes({"maxAcceleration": 0.0254}, {"maxAcceleration": 0.0289}) == ()
    assert metric_changes({"maxAcceleration": 0.0254}, {"maxAcceleration": 0.0289}, absolute=0.001) != ()
    text = markdown(result)
    assert "| 1 m | 2 m | +1 m |" in text  # with units


def test_counts_read_as_words() -> None:
    baseline = [_summary(i, "passed", seed=i) for i in range(3)]
    result = compare(baseline, [_summary(i, "failed", seed=i) for i in range(3)])
    assert result.counts_line().startswith("3 new failures · 0 fixed")
    assert markdown(result).startswith("### CARLOS compare: ❌ 3 new failures")
    one = compare(baseline[:1], [_summary(0, "failed")])
    assert one.counts_line().startswith("1 new failure · 0 fixed")


pytest_plugins = ["tests.s3server"]


@pytest.mark.s3
def test_baseline_in_s3_against_a_local_candidate(
    runs: tuple[Path, Path], s3_server: S3Server, monkeypatch: pytest.MonkeyPatch
) -> None:
    from simcore.store import open_store

    base, cand = runs
    for name in ("AWS_SESSION_TOKEN", "AWS_ENDPOINT_URL_S3", "AWS_PROFILE", "AWS_DEFAULT_REGION"):
        monkeypatch.delenv(name, raising=False)
    for name, value in s3_server.env().items():  # open_store reads the endpoint and keys from here
        monkeypatch.setenv(name, value)
    url = f"s3://{s3_server.bucket}/compare/base"
    store = open_store(url)
    for path in sorted(base.rglob("*")):
        if path.is_file():
            store.put_file(path.relative_to(base).as_posix(), path)
    done = carlos("compare", url, cand.as_uri(), env=s3_server.env())
    assert done.returncode == 1, done.stderr
    assert "1 new failure · 0 fixed · 0 still failing · 0 still passing · 1 added · 1 removed" in done.stdout
