"""The process's libsumo simulation, kept warm between runs on the same network and step, whatever their seeds.

libsumo holds one simulation per process. Starting one costs a run ~2.5 ms of CPU (libsumo registers its ~1,000
options, seeds its random generators and reads the network) and closing it ~0.4 ms, while a worker's runs of a
sweep share network and step. So a run's end parks the simulation instead of closing it, and the next run's
start resets it:

1. at the end: its vehicles are removed and one empty step is made (loading the state right after a run leaves
   every later vehicle standing still in SUMO 1.28, presumably because their lanes are still marked active;
   after the removal and a step they move: tests/test_sumo_world.py);
2. at the next start: the state saved right after the first start is loaded, its random generators written as
   seeding them with the new run's seed leaves them: time 0, no vehicles, no routes, only SUMO's vehicle types;
3. the simulation must then be empty at time 0, or it is closed and SUMO started afresh.

The random generators. A start seeds each of SUMO's named generators (`default`, the one vehicles draw their
speed factors from, `routeHandler`, `insertionControl`, `device`, ...) with `--seed`; nothing is drawn before
the state is saved, and nothing else at the start depends on the seed. SUMO saves a generator as the count of
numbers drawn since it was seeded and, loading, draws that many more from wherever the generator stands: a
count does not rewind it. So every named generator is written out in full instead (`std::mt19937` seeded with
the run's seed), for whichever seed the run has; the next run of the same seed loads only `default` in full, as
a run draws from no other named generator (a generator missing from a state is left as it stands). A
generator SUMO itself writes in full (it does once a state was loaded in the process) must be exactly that, or
the simulation is never parked; and the first start checks the loaded state: three vehicles' speed factors drawn after loading it must be those drawn right after the
start, or the simulation is never parked. The per-lane generators are left as they stand: SUMO draws from them
for every vehicle's dawdling every step, which CARLOS's vehicles do with imperfection 0 (simcore/world/sumo.py
`add_vehicle`): the draws are multiplied by zero and change nothing.

A run started with the key of the parked simulation (its arguments other than the seed, and the network
file's content) gets it as a fresh start with its seed would have made it (the same trajectories and speed
factors to the last bit: tests/test_sumo_world.py); any other key, or any error, closes it and starts afresh.
What a run changes in SUMO is only vehicles, their types and routes (simcore/world/sumo.py).
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
#: the named generators of a saved state: `<rngState name="count" ...>` (a count, or a count of at least
#: FULL_STATE_COUNT followed by the generator's full state)
_RNG_STATE = re.compile(r"<rngState\b([^>]*?)(/?>)")
_GENERATOR = re.compile(r'(\s)([\w.]+)="([^"]*)"')


class _Parked:
    """The simulation waiting for the next run: its key (None: nothing parked), the process that started it (a
    forked child never uses its parent's), its saved state at time 0, and the keys whose state failed its
    check."""

    def __init__(self) -> None:
        self.key: Hashable | None = None
        self.pid = 0
        self.folder: Path | None = None
        #: the state at time 0 of this process's simulation, saved and checked (its generators to be written
        #: for a run's seed); None: nothing saved
        self.template: str | None = None
        #: the snapshot file's seed, and whether it holds every generator
        self.written: tuple[int, bool] | None = None
        self.loaded_seed: int | None = None  # the seed every generator was last loaded for
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
                sumo.simulation.close()
        shutil.rmtree(folder, ignore_errors=True)


def mt19937_seeded(seed: int) -> str:
    """`std::mt19937` seeded with `seed` as libstdc++ writes it out: its 624 state words, then its position."""
    words = [seed & 0xFFFFFFFF]
    for i in range(1, 624):
        previous = words[-1]
        words.append((1812433253 * (previous ^ (previous >> 30)) + i) & 0xFFFFFFFF)
    return " ".join(map(str, words)) + " 624"


def start_template(state: str, seed: int) -> str | None:
    """A state SUMO saved right after a start with `seed`, as the template for any seed (`for_seed`): without
    the parts loading does nothing with. None when a named generator is written in full with another state
    than `std::mt19937` seeded with `seed`. (A count-only generator is as the start seeded it: nothing is drawn
    before the state is saved. Its count need not be 0: seeding does not reset it, and a process counts on
    from its earlier simulations.)"""
    match = _RNG_STATE.search(state)
    if match is None:
        return None
    fresh = mt19937_seeded(seed)
    for _, _, value in _GENERATOR.findall(match.group(1)):
        count, _, words = value.partition(" ")
        if not count.isdigit() or (int(count) >= FULL_STATE_COUNT) != bool(words):
            return None
        if words and words != fresh:
            return None
    return without_inert_parts(state)


def for_seed(template: str, seed: int, only: Iterable[str] | None = None) -> str:
    """The state `template` (`start_template`) with every named generator (or those named in `only`: loading
    leaves a generator not in the state as it stands) written in full as seeded with `seed` (its count kept,
    counted from FULL_STATE_COUNT)."""
    seeded = mt19937_seeded(seed)
    match = _RNG_STATE.search(template)
    assert match is not None  # start_template made sure
    kept = None if only is None else set(only)

    def written(generator: re.Match[str]) -> str:
        if kept is not None and generator.group(2) not in kept:
            return ""
        count = int(generator.group(3).partition(" ")[0])
        count += FULL_STATE_COUNT if count < FULL_STATE_COUNT else 0
        return f'{generator.group(1)}{generator.group(2)}="{count} {seeded}"'

    attributes = _GENERATOR.sub(written, match.group(1))
    return f"{template[: match.start(1)]}{attributes}{template[match.end(1) :]}"


def without_inert_parts(state: str) -> str:
    """A saved SUMO state without what loading it does nothing with (`_INERT`)."""
    return _INERT.sub("", state)


def start(sumo: Any, args: list[str], seed: int, key: Hashable | None) -> bool:
    """A simulation as `sumo.simulation.start(args)` with `--seed seed` makes it. With a `key` (what identifies the
    arguments and the files they name, the seed aside): the parked one, reset for `seed`, when it was parked
    with an equal key (True), else a fresh start, prepared for parking when its saved state passes its check
    (False). Without: a fresh start, closed by `close`. A parked simulation not reused is closed first. Errors
    are libsumo's."""
    parked, _PARKED.key = _PARKED.key, None
    if key is not None and parked == key and _load(sumo, seed):
        return True
    if parked is not None:
        with contextlib.suppress(Exception):
            sumo.simulation.close()
    _PARKED.template = None
    command = [*args, "--seed", str(seed), *SAVE_RNG]
    sumo.simulation.start(command)
    if key is not None and key not in _PARKED.refused:
        try:
            saved = _save_and_check(sumo, seed)
        except Exception:  # any failure only means: not parked
            saved = False
        if not saved:  # the check drew random numbers: this run gets a fresh start of its own
            _PARKED.template = None
            _PARKED.refused.add(key)
            with contextlib.suppress(Exception):
                sumo.simulation.close()
            sumo.simulation.start(command)
    return False


def _save_and_check(sumo: Any, seed: int) -> bool:
    """The fresh simulation's state saved as the template for every seed, and loaded again for `seed`; True
    when vehicles then draw the speed factors they draw right after the start."""
    path = _PARKED.snapshot(sumo)
    sumo.simulation.saveState(str(path))
    template = start_template(path.read_text(encoding="utf-8"), seed)
    if template is None:
        return False
    _PARKED.template, _PARKED.written, _PARKED.loaded_seed = template, None, None
    _PARKED.types = sumo.vehicletype.getIDCount()
    edge = next(edge for edge in sumo.edge.getIDList() if not edge.startswith(":"))
    fresh = _speed_factors(sumo, edge)
    if not (_clear(sumo, PROBES) and _load(sumo, seed)) or _speed_factors(sumo, edge) != fresh:
        return False
    return _clear(sumo, PROBES) and _load(sumo, seed)


def _speed_factors(sumo: Any, edge: str) -> tuple[float, ...]:
    """The speed factors SUMO draws for PROBES added (not yet inserted) on `edge`."""
    sumo.route.add(PROBES[0], [edge])
    for name in PROBES:
        sumo.vehicle.add(name, PROBES[0], depart="now")
    return tuple(float(sumo.vehicle.getSpeedFactor(name)) for name in PROBES)


def close(sumo: Any, vehicles: Iterable[str], key: Hashable | None) -> None:
    """End a run whose vehicles were `vehicles`: with its start's `key`, park the simulation for the next run
    (see the module's doc); else, or when its vehicles cannot be removed, close it."""
    if key is not None and _clear(sumo, vehicles):
        _PARKED.key = key
        return
    with contextlib.suppress(Exception):  # already closed or never started: nothing to release
        sumo.simulation.close()


def _clear(sumo: Any, vehicles: Iterable[str]) -> bool:
    """A run's vehicles (and any other) removed and one empty step made; False when that cannot be made sure,
    or nothing is saved to load afterwards."""
    if _PARKED.template is None or _PARKED.pid != os.getpid():
        return False
    try:
        for name in dict.fromkeys((*vehicles, *sumo.vehicle.getIDList())):
            with contextlib.suppress(sumo.TraCIException):  # already left the network
                sumo.vehicle.remove(name)
        sumo.simulation.step()
        return True
    except Exception:  # any failure only means: not parked
        return False


def _load(sumo: Any, seed: int) -> bool:
    """The simulation back at its saved start, its generators seeded with `seed`, empty; False when that cannot
    be made sure."""
    if _PARKED.template is None or _PARKED.pid != os.getpid():
        return False
    try:
        path = _PARKED.snapshot(sumo)
        # every generator for a new seed; then only `default`: a run draws from no other named generator
        # (tests/test_sumo_world.py), so they still hold this seed's start, and loading leaves them (half the
        # cost of a load: each generator written in full is 624 numbers to parse)
        every = _PARKED.loaded_seed != seed
        if _PARKED.written != (seed, every):
            _PARKED.written = None
            state = for_seed(_PARKED.template, seed, None if every else ("default",))
            path.write_text(state, encoding="utf-8")
            _PARKED.written = (seed, every)
        _PARKED.loaded_seed = None  # until the load is through: after a failed one, every generator again
        sumo.simulation.loadState(str(path))
        _PARKED.loaded_seed = seed
        return (
            sumo.simulation.getTime() == 0.0
            and sumo.vehicle.getIDCount() == 0
            and sumo.simulation.getMinExpectedNumber() == 0
            and sumo.route.getIDCount() == 0
            and sumo.vehicletype.getIDCount() == _PARKED.types
        )
    except Exception:  # any failure only means: not parked
        return False
