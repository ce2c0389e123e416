"""tools/same_results.py: what tools/wheel-check uses to hold the compiled wheel's results to the source's."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _results(root: Path, *, wall: float, mcap: bytes = b"\x89MCAP0\r\n") -> Path:
    run = root / "sweep" / "0"
    run.mkdir(parents=True)
    (run / "recording.mcap").write_bytes(mcap)
    summary = {"index": 0, "status": "passed", "metrics": {"minDistance": 3.25}, "wallSeconds": wall}
    (run / "summary.json").write_text(json.dumps({**summary, "outputUrl": root.as_uri()}))
    (root / "sweep" / "junit.xml").write_text(
        f'<testsuite name="sweep" time="{wall}"><testcase/></testsuite>'
    )
    (root / "sweep" / "run.yaml").write_text(f"output: {{url: {root.as_uri()}}}\n")
    (root / "sweep" / "report.html").write_text(f"<p>took {wall} s</p>")
    return root


def _same(a: Path, b: Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, str(ROOT / "tools" / "same_results.py"), str(a), str(b)]
    return subprocess.run(command, capture_output=True, text=True, check=False)


def test_runs_that_differ_only_in_wall_times_and_their_folder_are_the_same(tmp_path: Path) -> None:
    done = _same(_results(tmp_path / "a", wall=1.5), _results(tmp_path / "b", wall=2.75))
    assert done.returncode == 0 and "the same results: 4 files" in done.stdout, done.stderr


def test_a_recording_one_byte_off_or_a_metric_off_is_named(tmp_path: Path) -> None:
    a = _results(tmp_path / "a", wall=1.0)
    off = _same(a, _results(tmp_path / "b", wall=1.0, mcap=b"\x89MCAP0\r\x0b"))
    assert off.returncode == 1 and "differs: sweep/0/recording.mcap" in off.stderr
    b = _results(tmp_path / "c", wall=1.0)
    summary = json.loads((b / "sweep/0/summary.json").read_text())
    summary["metrics"]["minDistance"] = 3.2500000000000004
    (b / "sweep/0/summary.json").write_text(json.dumps(summary))
    metric = _same(a, b)
    assert metric.returncode == 1 and "differs: sweep/0/summary.json" in metric.stderr


def test_an_empty_or_lopsided_folder_is_no_match(tmp_path: Path) -> None:
    (tmp_path / "empty1").mkdir()
    (tmp_path / "empty2").mkdir()
    assert _same(tmp_path / "empty1", tmp_path / "empty2").returncode == 1
    a = _results(tmp_path / "a", wall=1.0)
    b = _results(tmp_path / "b", wall=1.0)
    (b / "sweep" / "0" / "summary.json").unlink()
    lopsided = _same(a, b)
    assert lopsided.returncode == 1 and "only in" in lopsided.stderr
