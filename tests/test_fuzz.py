"""A mutation fuzzer: the example manifests and scenarios (and the esmini corpus when it is here),
mutated the way a careless or hostile user would, through `carlos validate` in this process.

Invariants for every case: no exception escapes (a traceback for a user), no hang (each case has a time
bound), the exit code is one of 0/1/2/3, and an error is one line that names a file. The default suite runs
a bounded number of cases; `make fuzz` runs many more (CARLOS_FUZZ_CASES, CARLOS_FUZZ_SEED) and prints the
figures."""

from __future__ import annotations

import os
import random
import re
import shutil
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.inprocess import carlos_in_process
from tests.tooling import esmini_corpus

ROOT = Path(__file__).resolve().parents[1]
_CORPUS_ROOT = esmini_corpus()
CORPUS = (_CORPUS_ROOT / "resources") if _CORPUS_ROOT is not None else ROOT / "no-corpus"
CASES = int(os.environ.get("CARLOS_FUZZ_CASES", "120"))
SEED = int(os.environ.get("CARLOS_FUZZ_SEED", "15"))
CASE_SECONDS = float(os.environ.get("CARLOS_FUZZ_CASE_SECONDS", "20"))

HOSTILE = [
    "",
    "true",
    "-1",
    "0",
    "1e999",
    "nan",
    "9" * 400,
    "${10**10**10}",
    "${2 ** 1000000}",
    "${9e308*10}",
    "${(((1)))",
    "$Undeclared",
    "[/x]",
    ":100:",
    "[bold]x",
    "../../../../../etc/passwd",
    "x" * 20_000,
    "&a",
    "*a",
    "!!python/object:os.system",
    "{a: [",
    "'",
    '"',
    "\x00",
    "é\u202e",
]


class CaseTimeout(Exception):
    pass


@contextmanager
def time_bound(seconds: float) -> Iterator[None]:
    def expire(signum: int, frame: object) -> None:
        raise CaseTimeout

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def mutate_yaml(rng: random.Random, text: str) -> str:
    lines = text.splitlines()
    choice = rng.randrange(7)
    if choice == 0 and lines:  # a scalar value replaced
        candidates = [
            i
            for i, line in enumerate(lines)
            if re.search(r":\s*\S", line) and not line.lstrip().startswith("#")
        ]
        if candidates:
            i = rng.choice(candidates)
            key = lines[i].split(":", 1)[0]
            lines[i] = f"{key}: {rng.choice(HOSTILE)}"
    elif choice == 1 and lines:  # a line deleted
        del lines[rng.randrange(len(lines))]
    elif choice == 2 and lines:  # a line duplicated
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif choice == 3 and lines:  # indentation broken
        i = rng.randrange(len(lines))
        lines[i] = " " * rng.randrange(0, 7) + lines[i].lstrip()
    elif choice == 4:  # deep nesting
        depth = rng.choice([10, 100, 1000])
        lines.append("  extra: " + "[" * depth + "]" * depth)
    elif choice == 5:  # bytes flipped
        data = bytearray("\n".join(lines).encode())
        for _ in range(rng.randrange(1, 6)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        return data.decode("utf-8", errors="replace")
    else:  # a value of a list item replaced inline
        candidates = [i for i, line in enumerate(lines) if line.lstrip().startswith("- ")]
        if candidates:
            i = rng.choice(candidates)
            indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
            lines[i] = f"{indent}- {rng.choice(HOSTILE)}"
    return "\n".join(lines) + "\n"


_ATTRIBUTE = re.compile(r'(\s[A-Za-z]+=)"([^"]*)"')


def mutate_xml(rng: random.Random, text: str) -> str:
    choice = rng.randrange(6)
    if choice <= 1:  # attribute values replaced
        matches = list(_ATTRIBUTE.finditer(text))
        for match in rng.sample(matches, min(len(matches), rng.randrange(1, 4))):
            value = rng.choice(HOSTILE).replace('"', "&quot;").replace("<", "&lt;").replace("&a", "&amp;a")
            value = value.replace("\x00", "")
            text = text.replace(match.group(0), f'{match.group(1)}"{value}"', 1)
        return text
    if choice == 2:  # an element removed (from its start tag to the next end tag)
        starts = [m.start() for m in re.finditer(r"<[A-Z]", text)]
        if starts:
            start = rng.choice(starts)
            end = text.find(">", text.find("</", start))
            if end > start:
                return text[:start] + text[end + 1 :]
        return text
    if choice == 3:  # truncated
        return text[: rng.randrange(len(text) + 1)]
    if choice == 4:  # deep or wide structure inserted after the root's first child
        depth = rng.choice([50, 300])
        insert = rng.choice(
            ["<X>" * depth + "</X>" * depth, "<X " + " ".join(f'a{i}="1"' for i in range(2000)) + "/>"]
        )
        i = text.find(">", text.find("<OpenSCENARIO")) + 1
        return text[:i] + insert + text[i:]
    data = bytearray(text.encode())  # bytes flipped
    for _ in range(rng.randrange(1, 6)):
        if data:
            data[rng.randrange(len(data))] = rng.randrange(256)
    return bytes(data).decode("utf-8", errors="replace")


@dataclass
class Figures:
    tried: int = 0
    tracebacks: list[str] = field(default_factory=list)
    hangs: list[str] = field(default_factory=list)
    bad_exit: list[str] = field(default_factory=list)
    unnamed: list[str] = field(default_factory=list)
    exit_codes: dict[int, int] = field(default_factory=dict)

    def failures(self) -> list[str]:
        return self.tracebacks + self.hangs + self.bad_exit + self.unnamed


def check_case(figures: Figures, label: str, args: list[str | Path], files: list[Path]) -> None:
    figures.tried += 1
    try:
        with time_bound(CASE_SECONDS):
            outcome = carlos_in_process(*args)
    except CaseTimeout:
        figures.hangs.append(label)
        return
    if isinstance(outcome.exception, CaseTimeout):
        figures.hangs.append(label)
        return
    if outcome.exception is not None:
        figures.tracebacks.append(
            f"{label}: {type(outcome.exception).__name__}: {str(outcome.exception)[:200]}"
        )
        return
    figures.exit_codes[outcome.exit_code] = figures.exit_codes.get(outcome.exit_code, 0) + 1
    if outcome.exit_code not in (0, 1, 2, 3):
        figures.bad_exit.append(f"{label}: exit {outcome.exit_code}")
        return
    if outcome.exit_code != 0 and "--schema" not in args:
        lines = [line for line in outcome.stderr.splitlines() if line.strip()]
        named = any(str(f) in outcome.stderr or f.name in outcome.stderr for f in files) or _names_a_file(
            outcome.stderr
        )
        if len(lines) != 1 or not lines[0].startswith("error: ") or not named:
            figures.unnamed.append(f"{label}: {outcome.stderr.strip()[:300]!r}")


def _names_a_file(message: str) -> bool:
    """The error names an existing file first (`error: PATH[:LINE]: …`), e.g. a catalog the scenario uses."""
    match = re.match(r"error: (/[^:]+)", message.strip())
    return match is not None and Path(match.group(1)).is_file()


def _examples(tmp_path: Path) -> Path:
    copy = tmp_path / "examples"
    for part in ("runs", "scenarios", "maps"):
        shutil.copytree(ROOT / "examples" / part, copy / part)
    return copy


def _scenario_manifest(examples: Path, scenario: Path) -> Path:
    manifest = examples / "runs" / f"fuzz-{scenario.stem}.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: fuzz}\n"
        f"spec:\n  scenarios: [{{name: s, openscenario: {scenario}}}]\n"
    )
    return manifest


def run_fuzz(
    tmp_path: Path, cases: int, seed: int, progress: Callable[[Figures], None] | None = None
) -> Figures:
    rng = random.Random(seed)
    examples = _examples(tmp_path)
    manifests = sorted((examples / "runs").glob("*.yaml"))
    scenarios = sorted((examples / "scenarios").glob("*.xosc"))
    corpus_copy = tmp_path / "corpus"
    if CORPUS.is_dir():  # mutants are written beside their source (relative catalogs and roads): in a copy
        shutil.copytree(CORPUS, corpus_copy)
    corpus = sorted(corpus_copy.rglob("*.xosc")) if CORPUS.is_dir() else []
    figures = Figures()
    for case in range(cases):
        kind = rng.choice(["manifest", "scenario", "schema"] + (["corpus"] if corpus else []))
        if kind == "manifest":
            target = rng.choice(manifests)
            original = target.read_text()
            target.write_text(mutate_yaml(rng, original))
            check_case(figures, f"case {case} {kind} {target.name}", ["validate", target], [target])
            target.write_text(original)
            continue
        source = rng.choice(corpus) if kind == "corpus" else rng.choice(scenarios)
        target = (source.parent if kind == "corpus" else examples / "scenarios") / f"fuzz-{case}.xosc"
        target.write_text(mutate_xml(rng, source.read_text(errors="replace")))
        try:
            if kind == "schema":
                check_case(
                    figures, f"case {case} {kind} {source.name}", ["validate", target, "--schema"], [target]
                )
            else:
                manifest = _scenario_manifest(examples, target)
                road_files = list((examples / "maps").glob("*")) + list(source.parent.parent.glob("xodr/*"))
                check_case(
                    figures,
                    f"case {case} {kind} {source.name}",
                    ["validate", manifest],
                    [manifest, target, *road_files],
                )
        finally:
            target.unlink(missing_ok=True)
        if progress is not None:
            progress(figures)
    return figures


def test_mutated_inputs_never_crash_or_hang_validate(tmp_path: Path) -> None:
    started = time.monotonic()
    figures = run_fuzz(tmp_path, CASES, SEED)
    assert figures.tried == CASES
    assert not figures.failures(), "\n".join(figures.failures())
    assert time.monotonic() - started < 120


@pytest.mark.parametrize("kind", ["yaml", "xml"])
def test_mutators_change_their_input(kind: str) -> None:
    rng = random.Random(1)
    source = "runs/prototyping.yaml" if kind == "yaml" else "scenarios/braking.xosc"
    text = (ROOT / "examples" / source).read_text()
    mutate = mutate_yaml if kind == "yaml" else mutate_xml
    changed = sum(mutate(rng, text) != text for _ in range(50))
    assert changed >= 40
