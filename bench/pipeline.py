"""The run pipeline as a user meets it, side by side with the esmini player on the same files.

(a) single run: one scenario (the corpus' cut-in, 22 s simulated) with the defaults a user gets — recording
    on and report.html written (checked after the warm-up run) — through `carlos run` as a fresh process (the installed console script next to this Python) vs the esmini player as a fresh process
    on the same file; median of BENCH_REPEAT (default 3) runs each, interleaved.
(b) sweep: a BENCH_SWEEP-run (default 200) sweep of examples/scenarios/cut-in.xosc (EgoSpeed × CutInGap ×
    AdversarySpeed, recording off) through `carlos run --parallel 2` vs as many esmini processes two at a
    time, each on a copy of the file with that run's parameter values (esmini drives Ego by its script where
    CARLOS hands it to SUMO, as the file asks). Each of BENCH_SWEEP_ROUNDS rounds (default 1) runs carlos,
    esmini, esmini, carlos, so that a drift of the host's speed weighs on both sides alike; means are shown.
    Each carlos sweep writes into an output folder of its own (nothing deleted until the end).
(c) simulated seconds per wall second per core, warm, in one process: the run pipeline
    (`simcore.pipeline.simulate`, what `carlos run` workers and the simcore pod call) vs the bare engine
    (`ScenarioEngine.advance` in a loop) on the corpus cut-in: BENCH_PASS_ROUNDS rounds (default 15) of
    BENCH_PASSES passes (default 10) of each, interleaved; each rate from its median round. The pipeline's passes share one output folder
    (recording off: a pass writes nothing into it).

What runs is what a user installs: this checkout's wheel, built by tools/build-wheel (the step loop's modules
compiled by mypyc where a C compiler is found, as `pip install` builds it; CARLOS_COMPILE=0 for the
pure-Python build) and installed into a scratch folder that comes first on PYTHONPATH, for the `carlos`
processes and for the child process of (c). The table names the build. Wall seconds and CPU seconds (user +
system of the processes started) are both reported: on a shared machine the CPU seconds are the steadier
figure. BENCH_BEFORE=DIR (a checkout of an earlier revision, e.g. `git worktree add /tmp/before REV`)
measures (a) and (b) for that code too, interleaved with this checkout's, as the "before" figures;
BENCH_PURE=1 likewise measures this checkout's pure-Python wheel (CARLOS_COMPILE=0) as "pure".
Python's bytecode cache should be writable (PYTHONDONTWRITEBYTECODE unset), as in an installed package;
one untimed run per checkout warms it.

esmini: the player binary at $ESMINI; its rows are skipped when it is not set. The corpus:
$CARLOS_ESMINI_CORPUS (esmini's corpus directory with resources/xosc). Prints a table; the last line is one JSON
object with the figures and the ratios. No assertions: machines are noisy.
Usage: .venv/bin/python bench/pipeline.py
"""

from __future__ import annotations

import itertools
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

REPEAT = int(os.environ.get("BENCH_REPEAT", "3"))
SWEEP = int(os.environ.get("BENCH_SWEEP", "200"))
PASSES = int(os.environ.get("BENCH_PASSES", "10"))
SWEEP_ROUNDS = int(os.environ.get("BENCH_SWEEP_ROUNDS", "1"))
PASS_ROUNDS = int(os.environ.get("BENCH_PASS_ROUNDS", "15"))
BEFORE = Path(os.environ["BENCH_BEFORE"]).resolve() if os.environ.get("BENCH_BEFORE") else None
PURE = os.environ.get("BENCH_PURE") == "1"
CORPUS = Path(os.environ.get("CARLOS_ESMINI_CORPUS", ""))
CARLOS = Path(sys.executable).parent / "carlos"
EXAMPLE = ROOT / "examples" / "scenarios" / "cut-in.xosc"


def esmini_binary() -> Path | None:
    env = os.environ.get("ESMINI")
    return Path(env) if env and Path(env).is_file() else None


def manifest(
    directory: Path,
    name: str,
    scenario: Path,
    sweep: dict[str, list[float]] | None = None,
    *,
    recording: bool = False,
) -> Path:
    lines = [
        "apiVersion: carlos.dev/v1alpha1",
        "kind: SimulationRun",
        f"metadata: {{name: {name}}}",
        "spec:",
        f"  scenarios: [{{name: {name}, openscenario: {json.dumps(str(scenario))}}}]",
        "  simulation: {stepSeconds: 0.05, maxSeconds: 60, seed: 1}",
        *([] if recording else ["  recording: {enabled: false}"]),
        f"  output: {{url: {json.dumps((directory / 'results').as_uri())}}}",
    ]
    if sweep:
        lines.append("  sweep:")
        lines.append("    matrix:")
        lines.extend(f"      {key}: {json.dumps(values)}" for key, values in sweep.items())
    path = directory / f"{name}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(command: list[str], cwd: Path, env: dict[str, str] | None = None) -> float:
    started = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, check=False, env=env)
    wall = time.perf_counter() - started
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(command)} exited {done.returncode}: {done.stderr.strip()[-400:]}")
    return wall


def measured(job: Callable[[], object]) -> tuple[float, float]:
    """(wall s, CPU s of the child processes) of `job`."""
    cpu = _children_cpu()
    started = time.perf_counter()
    job()
    return time.perf_counter() - started, _children_cpu() - cpu


def installed(tree: Path, work: Path, label: str, *, pure: bool = False) -> Path:
    """The wheel of the checkout `tree` (tools/build-wheel: compiled where it can be, as a user's `pip install`
    builds it; `pure`: CARLOS_COMPILE=0) installed without its dependencies into a folder of its own; returns
    the folder."""
    dist, site = work / f"dist-{label}", work / f"site-{label}"
    wheel = subprocess.run(
        [str(tree / "tools" / "build-wheel"), str(dist)],
        env={**os.environ, "PYTHON": sys.executable, **({"CARLOS_COMPILE": "0"} if pure else {})},
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()[-1]
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site), wheel],
        capture_output=True,
        check=True,
    )
    return site


def site_env(site: Path) -> dict[str, str]:
    """The environment that makes `carlos` (and this script's child) run the installation in `site`: first on
    the path, ahead of this virtualenv's editable install of the checkout."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def build_of(env: dict[str, str]) -> str:
    """`carlos --version`'s build: compiled or pure Python."""
    done = subprocess.run([str(CARLOS), "--version"], env=env, capture_output=True, text=True, check=True)
    return done.stdout.strip().rsplit(", ", 1)[-1].rstrip(")")


def esmini_command(binary: Path, scenario: Path) -> list[str]:
    return [str(binary), "--headless", "--fixed_timestep", "0.05", "--disable_log", "--disable_stdout",
            "--osc", str(scenario)]  # fmt: skip


def sweep_matrix(size: int) -> dict[str, list[float]]:
    ego = [round(18.0 + 0.5 * i, 2) for i in range(10)]
    gap = [round(8.0 + 1.0 * i, 2) for i in range(10)]
    adversary = [round(32.0 + 1.0 * i, 2) for i in range(max(1, size // 100))]
    return {"EgoSpeed": ego, "CutInGap": gap, "AdversarySpeed": adversary}


def esmini_variants(directory: Path, matrix: dict[str, list[float]]) -> list[Path]:
    """One copy of the example per run of the matrix, next to a link to its maps (relative paths resolve)."""
    scenarios = directory / "scenarios"
    scenarios.mkdir()
    (directory / "maps").symlink_to(EXAMPLE.parent.parent / "maps")
    text = EXAMPLE.read_text()
    out = []
    keys = list(matrix)
    for i, values in enumerate(itertools.product(*(matrix[k] for k in keys))):
        variant = text
        for key, value in zip(keys, values, strict=True):
            variant = re.sub(
                rf'(<ParameterDeclaration name="{key}" parameterType="double" value=")[^"]*"',
                rf'\g<1>{value}"',
                variant,
            )
        path = scenarios / f"run{i}.xosc"
        path.write_text(variant)
        out.append(path)
    return out


def pipeline_vs_engine(scenario: Path, work: Path) -> tuple[float, float, float, float]:
    """(simulated s of one pass, pipeline sim-s/wall-s, bare engine sim-s/wall-s, bare engine on a road
    parsed once sim-s/wall-s), warm, in this process. The bare engine parses its road each pass, as a
    program would that runs one scenario; the pipeline keeps a worker's parsed roads (`OpenDrive.shared`)."""
    from simcore.manifest import load_manifest
    from simcore.pipeline import simulate
    from simcore.plan import Plan
    from simcore.scenario.engine import ScenarioEngine
    from simcore.scenario.xosc import load_scenario
    from simcore.world.opendrive import OpenDrive

    loaded = load_manifest(manifest(work, "inproc", scenario))
    run = loaded[0] if isinstance(loaded, tuple) else loaded
    point = Plan(run.spec)[0]

    out = work / "pipeline-out"  # one folder for every pass: without recording a run writes nothing there
    out.mkdir(exist_ok=True)

    def pipeline() -> float:
        return simulate(run, point, scenario, out).sim_seconds

    def engine(road_once: bool = False) -> float:
        loaded_scenario = load_scenario(scenario)
        road_file = loaded_scenario.road_file
        road = None
        if road_file is not None:
            road = OpenDrive.shared(road_file) if road_once else OpenDrive.from_file(road_file)
        eng = ScenarioEngine(loaded_scenario, road=road, sumo=None, step_seconds=0.05)
        while not eng.ended and eng.step_index < 1200:
            eng.advance()
        return eng.time

    jobs: list[Callable[[], float]] = [pipeline, engine, lambda: engine(road_once=True)]
    for job in jobs:
        job()  # warm-up
    # rounds of PASSES passes of each, the order reversed every other round (a drift of the host's speed
    # weighs on all alike); each rate from the median round (a round a busy host slowed counts as one)
    seconds: list[list[float]] = [[] for _ in jobs]
    sim = 0.0
    for k in range(PASS_ROUNDS):
        order = list(enumerate(jobs))
        for i, job in order if k % 2 == 0 else reversed(order):
            started = time.perf_counter()
            sim = sum(job() for _ in range(PASSES))
            seconds[i].append(time.perf_counter() - started)
    rates = [sim / statistics.median(each) for each in seconds]
    return sim / PASSES, rates[0], rates[1], rates[2]


def _median(pairs: list[tuple[float, float]]) -> tuple[float, float]:
    return statistics.median(p[0] for p in pairs), statistics.median(p[1] for p in pairs)


def main() -> None:
    binary = esmini_binary()
    cut_in = CORPUS / "resources" / "xosc" / "cut-in.xosc"
    if not cut_in.is_file():
        raise SystemExit(f"corpus cut-in not found at {cut_in} (set CARLOS_ESMINI_CORPUS)")
    trees = {
        "after": ROOT,
        **({"before": BEFORE} if BEFORE is not None else {}),
        **({"pure": ROOT} if PURE else {}),
    }
    figures: dict[str, float | int | str | list[float] | None] = {"sweep_runs": SWEEP}
    with tempfile.TemporaryDirectory(prefix="carlos-bench-") as name:
        work = Path(name)
        single = manifest(work, "single", cut_in, recording=True)  # the defaults: recording and report on
        envs = {
            label: site_env(installed(tree, work, label, pure=label == "pure"))
            for label, tree in trees.items()
        }
        for label, env in envs.items():
            figures[f"build_{label}"] = build_of(env)
        for env in envs.values():  # warm-up: bytecode cache, road network cache
            timed([str(CARLOS), "run", str(single), "--fresh"], work, env)
            for made in ("results/single/report.html", "results/single/0/recording.mcap"):
                if not (work / made).is_file():
                    raise SystemExit(f"the single run did not write {made}: not the default pipeline")
        singles: dict[str, list[tuple[float, float]]] = {label: [] for label in [*trees, "esmini"]}
        for _ in range(REPEAT):
            for label, env in envs.items():
                singles[label].append(
                    measured(lambda env=env: timed([str(CARLOS), "run", str(single), "--fresh"], work, env))
                )
            if binary is not None:
                singles["esmini"].append(measured(lambda: timed(esmini_command(binary, cut_in), work)))
        single_wall: dict[str, float] = {}
        for label in [*trees, "esmini"]:
            if singles[label]:
                single_wall[label], cpu = _median(singles[label])
                figures[f"single_{label}_s"] = round(single_wall[label], 3)
                figures[f"single_{label}_cpu_s"] = round(cpu, 3)
        if "esmini" in single_wall:
            for label in trees:
                figures[f"single_{label}_over_esmini"] = round(single_wall[label] / single_wall["esmini"], 2)
        matrix = sweep_matrix(SWEEP)
        sweep = manifest(work, "sweep", EXAMPLE, matrix)
        runs = len(list(itertools.product(*matrix.values())))
        figures["sweep_runs"] = runs
        variants: list[Path] = []
        esmini_dir = work / "esmini"
        if binary is not None:
            esmini_dir.mkdir()
            variants = esmini_variants(esmini_dir, matrix)

        def esmini_sweep() -> None:
            assert binary is not None
            with ThreadPoolExecutor(max_workers=2) as pool:
                list(pool.map(lambda p: timed(esmini_command(binary, p), esmini_dir), variants))

        rounds = itertools.count()

        def carlos_sweep(env: dict[str, str]) -> None:
            # each round into a folder of its own, none deleted until the end: `--fresh` over the previous
            # round's results would replace its 2,000 files, and on a file system without a journal (ext4
            # without one skips inodes freed in the last minutes when it allocates one) every file the round
            # creates would then pay a scan past the ones freed before it
            out = (work / f"sweep-{next(rounds)}").as_uri()
            timed([str(CARLOS), "run", str(sweep), "--fresh", "--parallel", "2", "-o", out], work, env)

        for label, env in envs.items():
            # rounds of carlos, esmini, esmini, carlos (ABBA): a drift of the host's speed during the
            # rounds weighs on both sides alike; the figures are the means of the rounds
            sides: dict[str, list[tuple[float, float]]] = {"carlos": [], "esmini": []}
            for _ in range(SWEEP_ROUNDS):
                order = ["carlos", "esmini", "esmini", "carlos"] if binary is not None else ["carlos"]
                for side in order:
                    if side == "carlos":
                        sides[side].append(measured(lambda env=env: carlos_sweep(env)))
                    else:
                        sides[side].append(measured(esmini_sweep))
            figures[f"sweep_{label}_each_s"] = [round(w, 2) for w, _ in sides["carlos"]]
            wall, cpu = (statistics.fmean(v) for v in zip(*sides["carlos"], strict=True))
            figures[f"sweep_{label}_s"] = round(wall, 2)
            figures[f"sweep_{label}_cpu_s"] = round(cpu, 2)
            figures[f"sweep_{label}_runs_per_s"] = round(runs / wall, 2)
            if sides["esmini"]:
                e_wall, e_cpu = (statistics.fmean(v) for v in zip(*sides["esmini"], strict=True))
                figures[f"sweep_esmini_next_to_{label}_s"] = round(e_wall, 2)
                figures[f"sweep_esmini_next_to_{label}_cpu_s"] = round(e_cpu, 2)
                figures[f"sweep_{label}_throughput_over_esmini"] = round(e_wall / wall, 2)
        child = subprocess.run(
            [sys.executable, __file__, "--pipeline-vs-engine", str(cut_in), str(work)],
            env=envs["after"],
            capture_output=True,
            text=True,
            check=True,
        )
        sim, pipeline_rate, engine_rate, engine_road_once_rate = json.loads(child.stdout.splitlines()[-1])
        figures["pipeline_sim_s_per_wall_s"] = round(pipeline_rate, 1)
        figures["engine_sim_s_per_wall_s"] = round(engine_rate, 1)
        figures["engine_road_once_sim_s_per_wall_s"] = round(engine_road_once_rate, 1)
        figures["pipeline_over_engine"] = round(pipeline_rate / engine_rate, 3)
        figures["pipeline_over_engine_road_once"] = round(pipeline_rate / engine_road_once_rate, 3)
        shutil.rmtree(work / "results", ignore_errors=True)

    def row(what: str, *cells: object) -> None:
        print(f"{what:44}" + "".join(f" {cell!s:>16}" for cell in cells))

    def pair(key: str) -> str:
        wall, cpu = figures.get(f"{key}_s"), figures.get(f"{key}_cpu_s")
        return "—" if wall is None else f"{wall} ({cpu} cpu)"

    labels = list(trees)
    row(
        "measure", *[f"carlos {label}" for label in labels], "esmini", *[f"ratio {label}" for label in labels]
    )
    row("installed build (carlos --version)", *[figures[f"build_{label}"] for label in labels])
    row(
        "single run, fresh process (s)",
        *[pair(f"single_{label}") for label in labels],
        pair("single_esmini"),
        *[figures.get(f"single_{label}_over_esmini", "—") for label in labels],
    )
    row(
        f"{runs}-run sweep, 2 at a time (s; ratio=throughput)",
        *[pair(f"sweep_{label}") for label in labels],
        pair(f"sweep_esmini_next_to_{labels[0]}"),
        *[figures.get(f"sweep_{label}_throughput_over_esmini", "—") for label in labels],
    )
    row(
        f"sim-s per wall-s, cut-in {sim:.0f} s (pipeline/engine)",
        figures["pipeline_sim_s_per_wall_s"],
        *([""] * (len(labels) - 1)),
        figures["engine_sim_s_per_wall_s"],
        figures["pipeline_over_engine"],
    )
    row(
        "  the same, engine on a road parsed once",
        figures["pipeline_sim_s_per_wall_s"],
        *([""] * (len(labels) - 1)),
        figures["engine_road_once_sim_s_per_wall_s"],
        figures["pipeline_over_engine_road_once"],
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    if sys.argv[1:2] == ["--pipeline-vs-engine"]:  # (c), in a child running the installed build
        # the installed build only: not this checkout, nor this folder (its simcore.py is another bench)
        sys.path[:] = [p for p in sys.path if p and Path(p).resolve() not in (ROOT, ROOT / "bench")]
        print(json.dumps(pipeline_vs_engine(Path(sys.argv[2]), Path(sys.argv[3]))))
    else:
        main()
