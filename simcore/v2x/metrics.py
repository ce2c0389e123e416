"""The `v2x.*` metrics of one run, accumulated from link outcomes, receptions and the ego's view.

- `v2x.packetDeliveryRatio`: delivered / sent over every link (sender → other station); per distance band
  `.0-100m`, `.100-200m`, … and for the ranges criteria name (`… within 300 m`: `.0-300m`).
- `v2x.ageOfInformation.mean` / `.max`: per (receiver, sender) pair, from the first reception on, the age of
  the newest message received (now − its generation time), sampled every step; `v2x.ageOfInformation.<sender>`
  is the mean over the sender's receivers.
- `v2x.cpmObjectCoverage`: of the object-steps the ego's own sensors miss (not in line of sight within
  `egoSensorRange`; objects within twice that range), the share the ego knows from a CPM received in the last
  second; `v2x.cpmObjectsFromV2xOnly`: how many objects it knew that way at least once.
- `v2x.hazardToFirstDenm`: the longest time from a hazard's detection (another station's hard braking,
  stationary vehicle) to the ego's first DENM about it; `v2x.hazards`, `v2x.hazardsMissed` (never reached it).
- `v2x.messages.cam|cpm|denm`: messages sent.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable

import numpy as np

BAND = 100.0
MAX_BANDED = 1000.0
#: A CPM object is known for this long after its CPM arrived (s).
CPM_FRESH = 1.0


def _edge(value: float) -> str:
    return f"{value:g}"


class V2XMetrics:
    def __init__(self, ranges: Iterable[float] = ()) -> None:
        self.ranges = sorted(set(ranges))
        self.distances: list[np.ndarray] = []
        self.outcomes: list[np.ndarray] = []
        self.sent: dict[str, int] = defaultdict(int)
        self.names: list[str] = []
        self.newest = np.zeros((0, 0))  # (receiver, sender) → generation time of the newest message received
        self.aoi_sum = np.zeros(0)
        self.aoi_count = np.zeros(0, dtype=np.int64)
        self.aoi_max = 0.0
        self.unseen_steps = 0
        self.covered_steps = 0
        self.covered_objects: set[str] = set()
        self.hazards: dict[tuple[str, int, float], float | None] = {}

    # --- inputs -----------------------------------------------------------------------------------------
    def links(self, distance: np.ndarray, delivered: np.ndarray) -> None:
        """Every link attempt of one step (flat arrays)."""
        self.distances.append(np.asarray(distance, dtype=np.float64).ravel())
        self.outcomes.append(np.asarray(delivered, dtype=bool).ravel())

    def message_sent(self, kind: str) -> None:
        self.sent[kind] += 1

    def stations(self, names: list[str]) -> None:
        """The stations, in the order `received` indexes them."""
        n = len(names)
        self.names = list(names)
        self.newest = np.full((n, n), -np.inf)
        self.aoi_sum = np.zeros(n)
        self.aoi_count = np.zeros(n, dtype=np.int64)

    def received(self, receiver: int, sender: int, generated: float) -> None:
        if generated > self.newest[receiver, sender]:
            self.newest[receiver, sender] = generated

    def received_many(self, receivers: np.ndarray, senders: np.ndarray, generated: float) -> None:
        """`received` for many copies generated at the same time."""
        self.newest[receivers, senders] = np.maximum(self.newest[receivers, senders], generated)

    def sample_age(self, time: float) -> None:
        known = np.isfinite(self.newest)
        if not known.any():
            return
        age = np.where(known, np.maximum(time - self.newest, 0.0), 0.0)
        self.aoi_sum += age.sum(axis=0)
        self.aoi_count += known.sum(axis=0)
        self.aoi_max = max(self.aoi_max, float(age.max()))

    def ego_view(self, unseen: Iterable[str], known_from_cpm: Iterable[str]) -> None:
        """One step of the ego: the objects its sensors miss, and those of them it knows from CPMs."""
        unseen = set(unseen)
        covered = unseen & set(known_from_cpm)
        self.unseen_steps += len(unseen)
        self.covered_steps += len(covered)
        self.covered_objects |= covered

    def hazard(self, key: tuple[str, int, float]) -> None:
        """A hazard (station, cause, detection time) another station detected."""
        self.hazards.setdefault(key, None)

    def ego_denm(self, key: tuple[str, int, float], time: float) -> None:
        if key in self.hazards and self.hazards[key] is None:
            self.hazards[key] = time

    # --- result -----------------------------------------------------------------------------------------
    def result(self) -> dict[str, float]:
        out: dict[str, float] = {
            f"v2x.messages.{kind}": float(self.sent.get(kind, 0)) for kind in ("cam", "cpm", "denm")
        }
        if self.distances:
            d = np.concatenate(self.distances)
            ok = np.concatenate(self.outcomes)
            if len(d):
                out["v2x.packetDeliveryRatio"] = float(ok.mean())
                lo = 0.0
                while lo < min(MAX_BANDED, float(d.max()) + 1e-9):
                    hi = lo + BAND
                    band = (d >= lo) & (d < hi)
                    if band.any():
                        out[f"v2x.packetDeliveryRatio.{_edge(lo)}-{_edge(hi)}m"] = float(ok[band].mean())
                    lo = hi
                for reach in self.ranges:
                    within = d < reach
                    if within.any():
                        out[f"v2x.packetDeliveryRatio.0-{_edge(reach)}m"] = float(ok[within].mean())
        total = int(self.aoi_count.sum())
        if total:
            out["v2x.ageOfInformation.mean"] = float(self.aoi_sum.sum()) / total
            out["v2x.ageOfInformation.max"] = self.aoi_max
            for sender, count in enumerate(self.aoi_count):
                if count:
                    out[f"v2x.ageOfInformation.{self.names[sender]}"] = float(self.aoi_sum[sender]) / int(
                        count
                    )
        if self.unseen_steps:
            out["v2x.cpmObjectCoverage"] = self.covered_steps / self.unseen_steps
        out["v2x.cpmObjectsFromV2xOnly"] = float(len(self.covered_objects))
        out["v2x.hazards"] = float(len(self.hazards))
        warned = [first - key[2] for key, first in self.hazards.items() if first is not None]
        out["v2x.hazardsMissed"] = float(len(self.hazards) - len(warned))
        if warned:
            out["v2x.hazardToFirstDenm"] = max(warned)
        return out
