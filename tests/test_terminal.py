"""Terminal output of `carlos run`: failed criteria and plain progress lines for logs."""

from __future__ import annotations

from simcore.workflow.terminal import ProgressLines, eta_seconds, failure_lines


def _failed(index: int, optional: bool = False) -> dict[str, object]:
    return {
        "index": index,
        "scenario": "braking",
        "parameters": {"speed": 20.0},
        "status": "failed",
        "optional": optional,
        "criteria": [
            {
                "name": "minDistance >= 2",
                "metric": "minDistance",
                "expected": ">= 2",
                "actual": 1.25,
                "passed": False,
                "optional": False,
                "message": "minDistance = 1.25: >= 2 does not hold",
            },
            {
                "name": "maxSpeed < 30",
                "metric": "maxSpeed",
                "expected": "< 30",
                "actual": 20.0,
                "passed": True,
                "optional": False,
                "message": "",
            },
            {
                "name": "meanSpeed > 99",
                "metric": "meanSpeed",
                "expected": "> 99",
                "actual": 1.0,
                "passed": False,
                "optional": True,
                "message": "optional",
            },
        ],
    }


def test_failure_lines_name_index_criterion_value_and_message() -> None:
    error = {"index": 3, "scenario": "cut-in", "parameters": {}, "status": "error", "error": "SUMO died"}
    passed = {"index": 0, "scenario": "cut-in", "parameters": {}, "status": "passed", "criteria": []}
    assert failure_lines([error, _failed(1), passed]) == [
        "failed braking[1] speed=20: minDistance >= 2: minDistance = 1.25: >= 2 does not hold",
        "error  cut-in[3]: SUMO died",
    ]


def test_failure_lines_are_capped() -> None:
    lines = failure_lines([_failed(i) for i in range(30)], limit=5)
    assert len(lines) == 6 and lines[-1].startswith("… and 25 more")


def test_eta_is_the_average_pace_times_what_is_left() -> None:
    assert eta_seconds(0, 10, 5.0) is None
    assert eta_seconds(2, 10, 5.0) == 20.0
    assert eta_seconds(10, 10, 5.0) == 0.0


def test_progress_lines_are_throttled_and_end_with_the_last_index() -> None:
    now = [0.0]
    lines: list[str] = []
    progress = ProgressLines("demo", lines.append, interval=10.0, clock=lambda: now[0])
    progress.start(4, 1)
    for t, status in ((2.0, "passed"), (5.0, "failed"), (9.0, "error")):
        now[0] = t
        progress.index_done(status)
    assert lines == [
        "demo: 4 runs (1 already complete)",
        "demo: 2/4 done · passed 1 failed 0 errors 0 · 2 s elapsed · ETA 4 s",
        "demo: 4/4 done · passed 1 failed 1 errors 1 · 9 s elapsed",
    ]
