"""Bad input on the documented paths (issue #18): one line naming the file and field, exit code 2, no
traceback; and what `carlos run` prints about failed runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from simcore.checks import unknown_metric
from tests.test_cli import ROOT, RUNS, carlos

CUT_IN = (ROOT / "examples" / "scenarios" / "cut-in.xosc").as_uri()


def _manifest(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / "run.yaml"
    path.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata:\n  name: t\nspec:\n"
        f"  scenarios:\n    - name: cut-in\n      openscenario: {CUT_IN}\n{extra}"
    )
    return path


def _bad_input(result: object, *needles: str) -> None:
    assert result.returncode == 2, result.stdout + result.stderr  # type: ignore[attr-defined]
    err = result.stderr  # type: ignore[attr-defined]
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


@pytest.mark.parametrize(
    ("url", "hint"), [("ftp://host/results", "use file://PATH or s3://"), ("./out", "file://./out")]
)
def test_unsupported_output_url(url: str, hint: str) -> None:
    _bad_input(carlos("run", RUNS / "data-generation.yaml", "--output", url), "--output", hint)


def test_run_on_a_directory() -> None:
    _bad_input(carlos("run", RUNS), "examples/runs", "is a directory")


def test_metric_typo_is_caught_by_validate(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, "  evaluation:\n    criteria: ['minDistanse >= 1']\n")
    _bad_input(
        carlos("validate", manifest),
        str(manifest),
        "spec.evaluation.criteria[0]",
        "unknown metric 'minDistanse': did you mean minDistance",
    )
    _bad_input(carlos("run", manifest, "--output", f"file://{tmp_path}/out"), "minDistanse")
    assert not (tmp_path / "out").exists()  # nothing simulated


def test_unknown_metrics() -> None:
    assert unknown_metric("minTimeHeadway", detection=False) is None
    assert unknown_metric("detection.recall.car.0-30m", detection=True) is None
    assert "needs spec.evaluation.detection" in (unknown_metric("detection.recall", detection=False) or "")


def test_system_under_test_that_cannot_be_imported_is_caught_by_validate(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, "  systemUnderTest:\n    module: no_such_package.node:Node\n")
    _bad_input(
        carlos("validate", manifest),
        str(manifest),
        "spec.systemUnderTest.module",
        "cannot import 'no_such_package.node'",
    )
    (tmp_path / "mynode.py").write_text("class Node:\n    def __init__(self, bus):\n        pass\n")
    manifest = _manifest(tmp_path, "  systemUnderTest:\n    module: mynode:Missing\n    pythonPath: ['.']\n")
    _bad_input(carlos("validate", manifest), "has no class 'Missing'")


def test_failed_runs_are_listed_with_criterion_value_and_message_and_progress_goes_to_logs(
    tmp_path: Path,
) -> None:
    result = carlos(
        "run", RUNS / "automated-testing-failing.yaml", "--output", f"file://{tmp_path}", "-j", "2"
    )
    assert result.returncode == 1, result.stderr
    assert "failed braking[1]: minTimeHeadway >= 30: minTimeHeadway = 0.97" in result.stdout, result.stdout
    assert "does not hold" in result.stdout
    # stdout is not a TTY: plain progress lines on stderr, the last one with every index
    assert "automated-testing-failing: 4 runs" in result.stderr
    assert "automated-testing-failing: 4/4 done · passed 3 failed 1 errors 0" in result.stderr
    # a new run over the failed index only, beside the old one; scenarios found through the recordings
    rerun = carlos("rerun", (tmp_path / "automated-testing-failing").as_uri(), "--failed")
    assert rerun.returncode == 1, rerun.stderr
    assert "automated-testing-failing-rerun: rerunning indexes 1 of automated-testing-failing" in rerun.stdout
    assert "failed braking[1]: minTimeHeadway >= 30" in rerun.stdout
    rerun_dir = tmp_path / "automated-testing-failing-rerun"
    assert sorted(p.name for p in rerun_dir.iterdir() if p.is_dir()) == ["1"]


def test_closed_loop_example_python_path_comment_names_the_folder_of_the_examples_package() -> None:
    import re

    text = (RUNS / "closed-loop.yaml").read_text()
    match = re.search(r'pythonPath:\s*#?\s*\[\s*"([^"]+)"\]', text)
    assert match is not None
    assert (RUNS / match.group(1) / "examples" / "controller" / "__init__.py").is_file()


def test_docs_list_every_lidar_point_field() -> None:
    from simcore.sensors.lidar import POINT_DTYPE

    topics = (ROOT / "docs" / "reference" / "topics.md").read_text()
    fields = ", ".join(POINT_DTYPE.names or ())
    assert f"sensor_msgs/PointCloud2 ({fields})" in topics
    for page in [ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]:
        text = page.read_text()
        for wording in ("this session", "The issue's", "session before", "previous release"):
            assert wording not in text, (page, wording)


def test_closed_loop_startup_timeout_is_reported_with_its_own_cause(tmp_path: Path) -> None:
    manifest = (RUNS / "closed-loop.yaml").read_text()
    manifest = manifest.replace("../scenarios/cut-in.xosc", CUT_IN).replace(
        "startupTimeoutSeconds: 120", "startupTimeoutSeconds: 1"
    )
    path = tmp_path / "closed-loop.yaml"
    path.write_text(manifest + "  execution:\n    retries: 2\n")
    result = carlos(
        "run", path, "--transport", "loopback", "--bus-port", "0", "--output", f"file://{tmp_path}/out"
    )
    assert result.returncode == 3, result.stdout + result.stderr
    assert "no node subscribed to /carlos/Ego/odometry within 1 s" in result.stdout
    assert "Bad file descriptor" not in result.stdout + result.stderr
    assert "retrying" not in result.stderr
