"""The process's libsumo simulation, kept warm between runs on the same network, step and seed.

libsumo holds one simulation per process. Starting one costs a run ~2.5 ms of CPU (libsumo registers its ~1,000
options, seeds its random generators and reads the network) and closing it ~0.4 ms, while a worker's runs of a
sweep mostly share network, step and seed. So a run's end parks the simulation instead of closing it:

1. its vehicles are removed and one empty step is made (loading the state right after a run leaves every
   later vehicle standing still in SUMO 1.28, presumably because their lanes are still marked active; after
   the removal and a step they move: tests/test_sumo_world.py);
2. the state saved right after the start is loaded again: time 0, no vehicles, no routes, only SUMO's vehicle
   types, and the random generator vehicles draw their speed factors from (`default`) as the start seeded it;
3. the simulation must then be empty at time 0, or it is closed.

The random generators. SUMO saves a generator as the count of numbers drawn since it was seeded and, loading,
draws that many more from wherever the generator stands: a count does not rewind it. So the saved state's
`default` generator is written out in full instead (`std::mt19937` seeded with the run's seed, as the start
leaves it), and checked once per start: three vehicles' speed factors drawn after loading it must be those drawn
right after the start, or the simulation is never parked. The per-lane generators are left as they stand: SUMO
draws from them for every vehicle's dawdling every step, which CARLOS's vehicles do with imperfection 0
(simcore/world/sumo.py `add_vehicle`): the draws are multiplied by zero and change nothing.

The next run started with the same key gets the simulation as a fresh start would have made it (the same
trajectories and speed factors to the last bit: tests/test_sumo_world.py); any other key, or any error, closes
it and starts afresh. What a run changes in SUMO is only vehicles, their types and routes (simcore/world/sumo.py).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re
import shutil
from collections.abc import Hashable, Iterable
from pathlib import Path
from typing import Any

from simcore.lifetime import make_scratch_root

#: the libsumo option that makes a saved state hold the random generators' states
SAVE_RNG = ("--save-state.rng", "true")
#: SUMO's SAVE_ONLY_COUNT: a generator's saved count this large is followed by its full state, which loading
#: then takes as it is
FULL_STATE_COUNT = 1_000_000
#: vehicles drawing speed factors to check a saved state (`_save_and_check`)
PROBES = tuple(f"carlos.probe.{i}" for i in range(3))
#: what loading a saved state does nothing with: the comment naming the options it was saved with, and a lane's
#: generator with nothing drawn (loading `state="0"` draws nothing); ~23% of a load's cost on a small network
_INERT = re.compile(r'<!--.*?-->\s*|\s*<rngLane index="\d+" state="0"/>', re.DOTALL)
_DEFAULT_GENERATOR = re.compile(r'<rngState\b[^>]*?\bdefault="(\d+)( [\d ]+)?"')


class _Parked:
    """The simulation waiting for the next run: its key (None: nothing parked), the process that started it (a
    forked child never uses its parent's), its state at time 0, and the keys whose state failed its check."""

    def __init__(self) -> None:
        self.key: Hashable | None = None
        self.pid = 0
        self.folder: Path | None = None
        self.saved = False  # the state at time 0 of this process's simulation is saved and checked
        self.types = 0  # the vehicle types right after the start (SUMO's defaults)
        self.refused: set[Hashable] = set()

    def snapshot(self, sumo: Any) -> Path:
        if self.folder is None or self.pid != os.getpid():
            # a scratch folder of this process: when a kill leaves it behind (no atexit), the next process to make
            # one, or the next `carlos run`, removes it (simcore/lifetime.py)
            self.folder = make_scratch_root(label="sumo-")
            self.pid = os.getpid()
            self.refused = set()
            atexit.register(_at_exit, sumo, self.folder, self.pid)
        return self.folder / "start.xml"


_PARKED = _Parked()


def _at_exit(sumo: Any, folder: Path, pid: int) -> None:
    """A parked simulation closed and its saved state removed when the process that made them ends."""
    if os.getpid() == pid:
        if _PARKED.key is not None:
            with contextlib.suppress(Exception):
                sumo.close()
        shutil.rmtree(folder, ignore_errors=True)


def mt19937_seeded(seed: int) -> str:
    """`std::mt19937` seeded with `seed` as libstdc++ writes it out: its 624 state words, then its position."""
    words = [seed & 0xFFFFFFFF]
    for i in range(1, 624):
        previous = words[-1]
        words.append((1812433253 * (previous ^ (previous >> 30)) + i) & 0xFFFFFFFF)
    return " ".join(map(str, words)) + " 624"


def with_default_generator_seeded(state: str, seed: int) -> str | None:
    """A saved SUMO state whose `default` generator is written in full: as SUMO wrote it when it did (its count
    reached FULL_STATE_COUNT: the generator lives as long as the process, and a state loaded before set its
    count), else as freshly seeded with `seed` (the count plus FULL_STATE_COUNT). None without that generator."""
    match = _DEFAULT_GENERATOR.search(state)
    if match is None:
        return None
    if match.group(2) is not None:
        return state
    count = FULL_STATE_COUNT + int(match.group(1))
    return f"{state[: match.start(1)]}{count} {mt19937_seeded(seed)}{state[match.end(1) :]}"


def without_inert_parts(state: str) -> str:
    """A saved SUMO state without what loading it does nothing with (`_INERT`)."""
    return _INERT.sub("", state)


def start(sumo: Any, args: list[str], seed: int, key: Hashable | None) -> bool:
    """A simulation as `sumo.start(args)` (with `--seed seed`) makes it. With a `key` (what identifies the
    arguments and the files they name): the parked one when it was started with an equal key (True), else a
    fresh start, prepared for parking when its saved state passes its check (False). Without: a fresh start,
    closed by `close`. A parked simulation not reused is closed first. Errors are libsumo's."""
    parked, _PARKED.key = _PARKED.key, None
    if key is not None and parked == key and _PARKED.pid == os.getpid():
        return True
    if parked is not None:
        with contextlib.suppress(Exception):
            sumo.close()
    _PARKED.saved = False
    sumo.start([*args, *SAVE_RNG])
    if key is not None and key not in _PARKED.refused:
        try:
            _PARKED.saved = _save_and_check(sumo, seed)
        except Exception:  # any failure only means: not parked
            _PARKED.saved = False
        if not _PARKED.saved:  # the check drew random numbers: this run gets a fresh start of its own
            _PARKED.refused.add(key)
            with contextlib.suppress(Exception):
                sumo.close()
            sumo.start([*args, *SAVE_RNG])
    return False


def _save_and_check(sumo: Any, seed: int) -> bool:
    """The fresh simulation's state saved (its default generator in full) and loaded again; True when vehicles
    then draw the speed factors they draw right after the start."""
    path = _PARKED.snapshot(sumo)
    sumo.simulation.saveState(str(path))
    state = with_default_generator_seeded(path.read_text(encoding="utf-8"), seed)
    if state is None:
        return False
    path.write_text(without_inert_parts(state), encoding="utf-8")
    _PARKED.types = sumo.vehicletype.getIDCount()
    edge = next(edge for edge in sumo.edge.getIDList() if not edge.startswith(":"))
    fresh = _speed_factors(sumo, edge)
    _PARKED.saved = True
    if not _reset(sumo, PROBES) or _speed_factors(sumo, edge) != fresh:
        return False
    return _reset(sumo, PROBES)


def _speed_factors(sumo: Any, edge: str) -> tuple[float, ...]:
    """The speed factors SUMO draws for PROBES added (not yet inserted) on `edge`."""
    sumo.route.add(PROBES[0], [edge])
    for name in PROBES:
        sumo.vehicle.add(name, PROBES[0], depart="now")
    return tuple(float(sumo.vehicle.getSpeedFactor(name)) for name in PROBES)


def close(sumo: Any, vehicles: Iterable[str], key: Hashable | None) -> None:
    """End a run whose vehicles were `vehicles`: with its start's `key`, park the simulation for the next run
    (see the module's doc); else, or when it cannot be reset, close it."""
    if key is not None and _reset(sumo, vehicles):
        _PARKED.key = key
        return
    with contextlib.suppress(Exception):  # already closed or never started: nothing to release
        sumo.close()


def _reset(sumo: Any, vehicles: Iterable[str]) -> bool:
    """The simulation back at its saved start, empty; False when that cannot be made sure."""
    if not _PARKED.saved or _PARKED.pid != os.getpid():
        return False
    try:
        for name in dict.fromkeys((*vehicles, *sumo.vehicle.getIDList())):
            with contextlib.suppress(sumo.TraCIException):  # already left the network
                sumo.vehicle.remove(name)
        sumo.simulationStep()
        sumo.simulation.loadState(str(_PARKED.snapshot(sumo)))
        return (
            sumo.simulation.getTime() == 0.0
            and sumo.vehicle.getIDCount() == 0
            and sumo.simulation.getMinExpectedNumber() == 0
            and sumo.route.getIDCount() == 0
            and sumo.vehicletype.getIDCount() == _PARKED.types
        )
    except Exception:  # any failure only means: not parked
        return False
