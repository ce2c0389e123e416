"""When a station sends: the generation rules of CAMs (ETSI EN 302 637-2 V1.4.1, 6.1.3), of the objects in
CPMs (ETSI TS 103 324 V2.1.1, 6.1.2.3) and of DENMs for hazards (hard braking, stationary vehicle).

Every rule set is a pure, vectorised state machine over N stations (or objects): `step(t, …)` takes the
current kinematics of all of them as arrays and returns boolean masks, so 100 stations cost one numpy pass.

CAM (vehicle ITS-S), checked every T_CheckCamGen (each simulation step, ≤ T_GenCamMin):
1. dynamics: at least T_GenCamDcc (= T_GenCamMin = 100 ms, no DCC) since the last CAM and the heading
   changed by more than 4°, the position by more than 4 m or the speed by more than 0.5 m/s since then;
   the interval of such a CAM becomes T_GenCam for the next N_GenCam = 3 CAMs;
2. time: T_GenCam (default T_GenCamMax = 1 s) since the last CAM.
The first CAM goes out at the first check. The low-frequency container is included in the first CAM and in
a CAM when at least 500 ms passed since the last one that carried it. Time comparisons allow a microsecond of
floating-point slack (steps of 0.05 s add up to 0.9999999 s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

T_GEN_CAM_MIN = 0.1
T_GEN_CAM_MAX = 1.0
N_GEN_CAM = 3
CAM_HEADING_DELTA = math.radians(4.0)
CAM_POSITION_DELTA = 4.0
CAM_SPEED_DELTA = 0.5
LOW_FREQUENCY_INTERVAL = 0.5
_SLACK = 1e-6


def heading_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| wrapped to [0, π], elementwise."""
    d = np.abs(np.asarray(a) - np.asarray(b)) % (2 * math.pi)
    return np.minimum(d, 2 * math.pi - d)


def _angle_difference(a: float, b: float) -> float:
    d = abs(a - b) % (2 * math.pi)
    return min(d, 2 * math.pi - d)


@dataclass(frozen=True)
class CamDecision:
    """Which stations send a CAM this check, and which of those CAMs carry the low-frequency container."""

    send: np.ndarray
    low_frequency: np.ndarray


class CamTriggers:
    """CAM generation state of `n` stations."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.last_time = np.full(n, -np.inf)
        self.last_xy = np.zeros((n, 2))
        self.last_heading = np.zeros(n)
        self.last_speed = np.zeros(n)
        self.last_low_frequency = np.full(n, -np.inf)
        self.t_gen_cam = np.full(n, T_GEN_CAM_MAX)
        self.kept = np.zeros(n, dtype=np.int64)  # CAMs left at the dynamic T_GenCam

    def step(self, t: float, xy: np.ndarray, heading: np.ndarray, speed: np.ndarray) -> CamDecision:
        elapsed = t - self.last_time
        first = ~np.isfinite(self.last_time)
        moved = np.hypot(*(xy - self.last_xy).T) > CAM_POSITION_DELTA
        turned = heading_difference(heading, self.last_heading) > CAM_HEADING_DELTA
        sped = np.abs(speed - self.last_speed) > CAM_SPEED_DELTA
        dynamic = (elapsed >= T_GEN_CAM_MIN - _SLACK) & (moved | turned | sped) & ~first
        timed = elapsed >= self.t_gen_cam - _SLACK
        send = first | dynamic | timed
        low = send & (t - self.last_low_frequency >= LOW_FREQUENCY_INTERVAL - _SLACK)
        # T_GenCam: a dynamics-triggered CAM sets it to its interval for the next N_GenCam CAMs
        timed_only = send & ~dynamic & ~first
        self.kept = np.where(timed_only, np.maximum(self.kept - 1, 0), self.kept)
        self.t_gen_cam = np.where(timed_only & (self.kept == 0), T_GEN_CAM_MAX, self.t_gen_cam)
        self.t_gen_cam = np.where(dynamic, np.clip(elapsed, T_GEN_CAM_MIN, T_GEN_CAM_MAX), self.t_gen_cam)
        self.kept = np.where(dynamic, N_GEN_CAM, self.kept)
        self.last_time = np.where(send, t, self.last_time)
        self.last_xy = np.where(send[:, None], xy, self.last_xy)
        self.last_heading = np.where(send, heading, self.last_heading)
        self.last_speed = np.where(send, speed, self.last_speed)
        self.last_low_frequency = np.where(low, t, self.last_low_frequency)
        return CamDecision(send=send, low_frequency=low)


# --- CPM object inclusion (TS 103 324, 6.1.2.3) ----------------------------------------------------------

#: An object is included again once it moved this far, changed speed or heading this much, or after T_GenCpmMax.
CPM_POSITION_DELTA = 4.0
CPM_SPEED_DELTA = 0.5
CPM_HEADING_DELTA = math.radians(4.0)
T_GEN_CPM_MIN = 0.1
T_GEN_CPM_MAX = 1.0


class CpmObjectTriggers:
    """Which perceived objects of one sender go into its next CPM: new objects, objects that moved > 4 m,
    changed speed > 0.5 m/s or heading > 4° since they were last included, and objects last included
    T_GenCpmMax (1 s) ago or more. Objects are keyed by their id (a string)."""

    def __init__(self) -> None:
        self._last: dict[str, tuple[float, float, float, float, float]] = {}  # t, x, y, speed, heading

    def select(
        self, t: float, ids: list[str], xy: np.ndarray, speed: np.ndarray, heading: np.ndarray
    ) -> np.ndarray:
        out = np.zeros(len(ids), dtype=bool)
        for i, key in enumerate(ids):
            last = self._last.get(key)
            if last is None:
                include = True
            else:
                lt, lx, ly, ls, lh = last
                include = (
                    t - lt >= T_GEN_CPM_MAX - _SLACK
                    or math.hypot(xy[i, 0] - lx, xy[i, 1] - ly) > CPM_POSITION_DELTA
                    or abs(float(speed[i]) - ls) > CPM_SPEED_DELTA
                    or _angle_difference(float(heading[i]), lh) > CPM_HEADING_DELTA
                )
            if include:
                out[i] = True
                self._last[key] = (t, float(xy[i, 0]), float(xy[i, 1]), float(speed[i]), float(heading[i]))
        return out


# --- DENM hazards ---------------------------------------------------------------------------------------

#: ETSI cause codes (ETSI TS 102 894-2 / EN 302 637-3).
CAUSE_DANGEROUS_SITUATION = 99
SUB_CAUSE_EMERGENCY_ELECTRONIC_BRAKE = 1
CAUSE_STATIONARY_VEHICLE = 94
SUB_CAUSE_UNAVAILABLE = 0


@dataclass(frozen=True)
class Hazard:
    """A detected event of one station: its cause, when it started and whether it is new this step."""

    station: int
    cause: int
    sub_cause: int
    detection_time: float
    new: bool


class HazardTriggers:
    """Hazards of `n` stations: hard braking (deceleration above `hard_braking` m/s²) and a stationary vehicle
    (speed below `stationary_speed` m/s for `stationary_seconds` after having moved). While a hazard lasts its
    DENM is repeated every `repetition` seconds; `step` returns the hazards whose DENM is due now."""

    def __init__(
        self,
        n: int,
        *,
        hard_braking: float = 4.0,
        stationary_speed: float = 0.1,
        stationary_seconds: float = 2.0,
        repetition: float = 0.1,
    ) -> None:
        self.n = n
        self.hard_braking = hard_braking
        self.stationary_speed = stationary_speed
        self.stationary_seconds = stationary_seconds
        self.repetition = repetition
        self.moved = np.zeros(n, dtype=bool)
        self.still_since = np.full(n, np.nan)
        self.onset: dict[tuple[int, int], float] = {}
        self.last_sent: dict[tuple[int, int], float] = {}

    def _active(self, t: float, speed: np.ndarray, acceleration: np.ndarray) -> dict[int, set[int]]:
        moving = np.abs(speed) >= self.stationary_speed
        self.moved |= moving
        self.still_since = np.where(moving, np.nan, np.where(np.isnan(self.still_since), t, self.still_since))
        stationary = self.moved & ~moving & (t - self.still_since >= self.stationary_seconds - _SLACK)
        braking = (acceleration <= -self.hard_braking) & moving
        active: dict[int, set[int]] = {}
        for i in np.flatnonzero(stationary):
            active.setdefault(int(i), set()).add(CAUSE_STATIONARY_VEHICLE)
        for i in np.flatnonzero(braking):
            active.setdefault(int(i), set()).add(CAUSE_DANGEROUS_SITUATION)
        return active

    def step(self, t: float, speed: np.ndarray, acceleration: np.ndarray) -> list[Hazard]:
        active = self._active(t, speed, acceleration)
        current = {(i, cause) for i, causes in active.items() for cause in causes}
        for key in list(self.onset):
            if key not in current:
                del self.onset[key]
                self.last_sent.pop(key, None)
        out = []
        for key in sorted(current):
            new = key not in self.onset
            if new:
                self.onset[key] = t
            last = self.last_sent.get(key)
            if last is not None and t - last < self.repetition - _SLACK:
                continue
            self.last_sent[key] = t
            station, cause = key
            sub = (
                SUB_CAUSE_EMERGENCY_ELECTRONIC_BRAKE
                if cause == CAUSE_DANGEROUS_SITUATION
                else SUB_CAUSE_UNAVAILABLE
            )
            out.append(Hazard(station, cause, sub, self.onset[key], new))
        return out
