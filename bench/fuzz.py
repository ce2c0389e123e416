"""`make fuzz`: the mutation fuzzer of tests/test_fuzz.py with a bigger budget, and its figures.

    python bench/fuzz.py [CASES] [SEED]

Prints the inputs tried, tracebacks, hangs, wrong exit codes and errors that name no file (each listed), the
exit codes seen, and as its last line one JSON object. Exit code 1 when any invariant failed."""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.test_fuzz import run_fuzz


def main() -> int:
    cases = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 15
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="carlos-fuzz-") as tmp:
        figures = run_fuzz(Path(tmp), cases, seed)
    wall = time.monotonic() - started
    for failure in figures.failures():
        print(failure)
    print(f"{'inputs tried':<28}{figures.tried:>8}")
    print(f"{'tracebacks':<28}{len(figures.tracebacks):>8}")
    print(f"{'hangs':<28}{len(figures.hangs):>8}")
    print(f"{'exit codes outside 0-3':<28}{len(figures.bad_exit):>8}")
    print(f"{'errors naming no file':<28}{len(figures.unnamed):>8}")
    print(f"{'exit codes seen':<28}{json.dumps(dict(sorted(figures.exit_codes.items()))):>8}")
    print(f"{'wall seconds':<28}{wall:>8.1f}")
    print(
        json.dumps(
            {
                "tried": figures.tried,
                "tracebacks": len(figures.tracebacks),
                "hangs": len(figures.hangs),
                "badExit": len(figures.bad_exit),
                "unnamed": len(figures.unnamed),
                "casesPerSecond": round(figures.tried / wall, 1),
            }
        )
    )
    return 1 if figures.failures() else 0


if __name__ == "__main__":
    sys.exit(main())
