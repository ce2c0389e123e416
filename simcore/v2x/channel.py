"""Radio channel: which receivers get which messages, how late, and why the others did not.

Per link (sender s, receiver r at distance d, m):

    received power  P_rx = P_tx + G_tx + G_rx − PL(d) − X_shadow − X_fading − L_nlos
    path loss       PL(d) = FSPL(d0) + 10·n·log10(max(d, d0) / d0),   FSPL(d0) = 20·log10(4π·d0·f / c)

with the path-loss exponent n, the free-space reference distance d0 and the carrier frequency f; the
shadowing X_shadow ~ N(0, σ²) dB; the fading is Nakagami-m small-scale fading (m = 1: Rayleigh) of the
power, X_fading = −10·log10(g), g ~ Gamma(m, 1/m); L_nlos (dB) is added when the line of sight is blocked
(`los` callback, e.g. rays against the scene's road mesh and entity boxes). A message arrives when
P_rx ≥ the receiver's sensitivity, after `latency` + U(0, `jitter`) seconds. Channel busy: a receiver takes
at most `max_messages_per_second`·step messages per step (the strongest first); the rest are lost as `busy`.

Random draws come from a generator seeded by (seed, step), so a run is reproducible for its seed and a
step's outcome does not depend on how many draws earlier steps made.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

SPEED_OF_LIGHT = 299_792_458.0

#: Why a message did not arrive (`Delivery.lost`).
DELIVERED, TOO_WEAK, BUSY = 0, 1, 2


@dataclass(frozen=True)
class ChannelParameters:
    """ITS-G5 / C-V2X sidelink defaults: 5.9 GHz, 23 dBm, −90 dBm sensitivity, urban exponent 2.7."""

    frequency_hz: float = 5.9e9
    tx_power_dbm: float = 23.0
    tx_gain_db: float = 0.0
    rx_gain_db: float = 0.0
    sensitivity_dbm: float = -90.0
    path_loss_exponent: float = 2.7
    reference_distance: float = 1.0
    shadowing_sigma_db: float = 0.0
    fading_m: float | None = None  # Nakagami m; None: no fading
    nlos_loss_db: float = 20.0
    latency: float = 0.002
    jitter: float = 0.001
    max_messages_per_second: float | None = None

    def reference_loss_db(self) -> float:
        d0 = self.reference_distance
        return 20.0 * math.log10(4.0 * math.pi * d0 * self.frequency_hz / SPEED_OF_LIGHT)

    def mean_path_loss_db(self, distance: np.ndarray) -> np.ndarray:
        d0 = self.reference_distance
        ratio = np.maximum(np.asarray(distance, dtype=np.float64), d0) / d0
        return self.reference_loss_db() + 10.0 * self.path_loss_exponent * np.log10(ratio)

    def mean_rx_power_dbm(self, distance: np.ndarray) -> np.ndarray:
        return self.tx_power_dbm + self.tx_gain_db + self.rx_gain_db - self.mean_path_loss_db(distance)

    def delivery_probability(self, distance: np.ndarray) -> np.ndarray:
        """P(delivered) at `distance` with shadowing only (no fading, line of sight, channel not busy)."""
        margin = self.mean_rx_power_dbm(distance) - self.sensitivity_dbm
        if self.shadowing_sigma_db <= 0:
            return (margin >= 0).astype(np.float64)
        from scipy.special import ndtr

        return np.asarray(ndtr(margin / self.shadowing_sigma_db), dtype=np.float64)

    def range_m(self) -> float:
        """The distance at which the mean received power meets the sensitivity."""
        budget = self.tx_power_dbm + self.tx_gain_db + self.rx_gain_db - self.sensitivity_dbm
        excess = budget - self.reference_loss_db()
        return self.reference_distance * 10.0 ** (excess / (10.0 * self.path_loss_exponent))


#: los(rows (K,), cols (K,)) → True where the straight line from sender `tx[rows[k]]` to receiver
#: `rx[cols[k]]` is clear.
LineOfSight = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Delivery:
    """The outcome of one step's transmissions: for every (sender, receiver) pair, `lost` is DELIVERED,
    TOO_WEAK or BUSY (−1 on the diagonal: nobody receives its own message), `rx_power_dbm` and `delay` (s),
    and `distance` (m)."""

    lost: np.ndarray
    rx_power_dbm: np.ndarray
    delay: np.ndarray
    distance: np.ndarray

    @property
    def delivered(self) -> np.ndarray:
        return self.lost == DELIVERED


class Channel:
    def __init__(self, parameters: ChannelParameters, seed: int, los: LineOfSight | None = None) -> None:
        self.parameters = parameters
        self.seed = seed
        self.los = los

    def transmit(
        self, step: int, step_seconds: float, tx: np.ndarray, rx: np.ndarray, same: np.ndarray | None = None
    ) -> Delivery:
        """Deliver one message from each of the S senders at `tx` (S, 3) to each of the R receivers at
        `rx` (R, 3). `same` (S, R), when given, marks pairs that are one station (not a link)."""
        p = self.parameters
        rng = np.random.default_rng([self.seed, step])
        tx = np.asarray(tx, dtype=np.float64).reshape(-1, 3)
        rx = np.asarray(rx, dtype=np.float64).reshape(-1, 3)
        s, r = len(tx), len(rx)
        distance = np.sqrt(((tx[:, None, :] - rx[None, :, :]) ** 2).sum(axis=2))
        power = p.mean_rx_power_dbm(distance)
        if p.shadowing_sigma_db > 0:
            power = power - rng.normal(0.0, p.shadowing_sigma_db, size=(s, r))
        if p.fading_m is not None:
            gain = rng.gamma(p.fading_m, 1.0 / p.fading_m, size=(s, r))
            power = power + 10.0 * np.log10(np.maximum(gain, 1e-30))
        link = np.ones((s, r), dtype=bool) if same is None else ~same
        if self.los is not None and s and r:
            candidates = np.argwhere(link & (power >= p.sensitivity_dbm))
            if len(candidates):
                clear = self.los(candidates[:, 0], candidates[:, 1])
                blocked = candidates[~np.asarray(clear, dtype=bool)]
                power[blocked[:, 0], blocked[:, 1]] -= p.nlos_loss_db
        lost = np.where(power >= p.sensitivity_dbm, DELIVERED, TOO_WEAK)
        if p.max_messages_per_second is not None:
            capacity = math.floor(p.max_messages_per_second * step_seconds + 1e-9)
            arriving = (lost == DELIVERED) & link
            over = arriving.sum(axis=0) > capacity
            for j in np.flatnonzero(over):
                order = np.argsort(-np.where(arriving[:, j], power[:, j], -np.inf), kind="stable")
                lost[order[capacity:][arriving[order[capacity:], j]], j] = BUSY
        lost = np.where(link, lost, -1)
        delay = p.latency + (rng.uniform(0.0, p.jitter, size=(s, r)) if p.jitter > 0 else np.zeros((s, r)))
        return Delivery(lost=lost, rx_power_dbm=power, delay=delay, distance=distance)
