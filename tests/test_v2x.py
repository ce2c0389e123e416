"""V2X: CAM/CPM/DENM generation rules, WGS84 conversion, the channel model."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from simcore.v2x.channel import BUSY, DELIVERED, TOO_WEAK, Channel, ChannelParameters
from simcore.v2x.triggers import (
    CAUSE_DANGEROUS_SITUATION,
    CAUSE_STATIONARY_VEHICLE,
    CamTriggers,
    CpmObjectTriggers,
    HazardTriggers,
)

# --- CAM generation rules ---------------------------------------------------------------------------------


def _cam_times(xy, heading, speed, dt=0.05, seconds=3.0):
    """Times of the CAMs of one station whose kinematics are functions of t, and the LF-container times."""
    triggers = CamTriggers(1)
    sent, low = [], []
    for k in range(round(seconds / dt) + 1):
        t = k * dt
        decision = triggers.step(t, np.array([xy(t)]), np.array([heading(t)]), np.array([speed(t)]))
        if decision.send[0]:
            sent.append(round(t, 3))
        if decision.low_frequency[0]:
            low.append(round(t, 3))
    return sent, low


def test_cam_standing_still_goes_out_every_second_with_a_low_frequency_container():
    sent, low = _cam_times(lambda t: (0.0, 0.0), lambda t: 0.0, lambda t: 0.0)
    assert sent == [0.0, 1.0, 2.0, 3.0]
    assert low == sent  # every CAM is ≥ 500 ms after the last low-frequency container


def test_cam_position_change_over_4_m_triggers_at_most_every_100_ms():
    # 50 m/s: 4 m in 80 ms, so every check after 100 ms qualifies
    sent, _ = _cam_times(lambda t: (50.0 * t, 0.0), lambda t: 0.0, lambda t: 50.0, seconds=1.0)
    assert sent == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]


def test_cam_position_below_4_m_does_not_trigger():
    # 3.5 m/s: 4 m after 1.14 s, so the 1 s ceiling comes first
    sent, _ = _cam_times(lambda t: (3.5 * t, 0.0), lambda t: 0.0, lambda t: 3.5, seconds=2.0)
    assert sent == [0.0, 1.0, 2.0]


def test_cam_heading_change_over_4_degrees_triggers():
    # turning 10°/s: 4° exceeded after 0.45 s (0.40 s gives exactly 4°, not more)
    rate = math.radians(10.0)
    sent, _ = _cam_times(lambda t: (0.0, 0.0), lambda t: rate * t, lambda t: 0.0, seconds=1.0)
    assert sent[:2] == [0.0, 0.45]


def test_cam_speed_change_over_half_a_metre_per_second_triggers():
    # accelerating 2 m/s² from 0 (position change stays < 4 m over the first second)
    sent, _ = _cam_times(lambda t: (t * t, 0.0), lambda t: 0.0, lambda t: 2.0 * t, seconds=0.6)
    assert sent == [0.0, 0.3, 0.6]  # 0.25 s gives exactly 0.5 m/s: not more


def test_cam_dynamic_interval_is_kept_for_three_cams_then_the_ceiling_returns():
    # a 5 m jump at 0.2 s, then standing still: T_GenCam = 0.2 s for three CAMs, then 1 s again
    sent, low = _cam_times(
        lambda t: (5.0 if t >= 0.2 else 0.0, 0.0), lambda t: 0.0, lambda t: 0.0, seconds=2.0
    )
    assert sent == [0.0, 0.2, 0.4, 0.6, 0.8, 1.8]
    assert low == [0.0, 0.6, 1.8]  # ≥ 500 ms between low-frequency containers


def test_cam_rules_are_per_station():
    triggers = CamTriggers(2)
    xy = np.zeros((2, 2))
    assert triggers.step(0.0, xy, np.zeros(2), np.zeros(2)).send.tolist() == [True, True]
    moved = np.array([[5.0, 0.0], [0.0, 0.0]])
    assert triggers.step(0.1, moved, np.zeros(2), np.zeros(2)).send.tolist() == [True, False]


# --- CPM object inclusion and DENM hazards ---------------------------------------------------------------


def test_cpm_includes_new_moved_and_stale_objects_only():
    triggers = CpmObjectTriggers()
    ids = ["a", "b"]
    xy = np.array([[0.0, 0.0], [10.0, 0.0]])
    v = np.array([1.0, 0.0])
    h = np.zeros(2)
    moved = xy + np.array([[4.5, 0.0], [1.0, 0.0]])
    turned = h + np.array([0.0, 0.1])
    assert triggers.select(0.0, ids, xy, v, h).tolist() == [True, True]
    assert triggers.select(0.1, ids, moved, v, h).tolist() == [True, False]
    assert triggers.select(0.5, ids, moved, v, turned).tolist() == [
        False,
        True,
    ]
    assert triggers.select(1.1, ids, moved, v, turned).tolist() == [
        True,
        False,
    ]
    assert triggers.select(1.2, ["c"], xy[:1], v[:1], h[:1]).tolist() == [True]


def test_denm_on_hard_braking_repeats_while_it_lasts_and_names_its_onset():
    triggers = HazardTriggers(2, hard_braking=4.0, repetition=0.1)
    speed = np.array([10.0, 10.0])
    assert triggers.step(0.0, speed, np.array([0.0, -1.0])) == []
    first = triggers.step(0.05, speed, np.array([-6.0, -1.0]))
    assert [(h.station, h.cause, h.new, h.detection_time) for h in first] == [
        (0, CAUSE_DANGEROUS_SITUATION, True, 0.05)
    ]
    assert triggers.step(0.1, speed, np.array([-6.0, -1.0])) == []  # repetition interval 100 ms
    again = triggers.step(0.15, speed, np.array([-6.0, -1.0]))
    assert [(h.new, h.detection_time) for h in again] == [(False, 0.05)]
    assert triggers.step(0.2, speed, np.array([0.0, -1.0])) == []


def test_denm_stationary_vehicle_after_having_moved():
    triggers = HazardTriggers(2, stationary_seconds=2.0, repetition=1.0)
    events = []
    for k in range(61):
        t = k * 0.1
        speed = np.array([5.0 if t < 1.0 else 0.0, 0.0])  # station 1 never moved: a parked car, no hazard
        events += [(round(t, 1), h.station, h.cause) for h in triggers.step(t, speed, np.zeros(2))]
    assert events == [
        (3.0, 0, CAUSE_STATIONARY_VEHICLE),
        (4.0, 0, CAUSE_STATIONARY_VEHICLE),
        (5.0, 0, CAUSE_STATIONARY_VEHICLE),
        (6.0, 0, CAUSE_STATIONARY_VEHICLE),
    ]


# --- channel model ---------------------------------------------------------------------------------------


def test_free_space_reference_and_range():
    p = ChannelParameters(frequency_hz=5.9e9, reference_distance=1.0, path_loss_exponent=2.0)
    assert p.reference_loss_db() == pytest.approx(47.86, abs=0.01)  # 20·log10(4π·5.9e9/c)
    assert p.mean_path_loss_db(np.array([10.0]))[0] == pytest.approx(47.86 + 20.0, abs=0.01)
    assert float(p.mean_rx_power_dbm(np.array([p.range_m()]))[0]) == pytest.approx(p.sensitivity_dbm)


def test_delivery_without_randomness_is_a_range_cut():
    p = ChannelParameters(path_loss_exponent=2.7)
    reach = p.range_m()
    channel = Channel(p, seed=1)
    tx = np.array([[0.0, 0.0, 1.5]])
    rx = np.array([[reach - 1.0, 0.0, 1.5], [reach + 1.0, 0.0, 1.5]])
    assert channel.transmit(0, 0.1, tx, rx).lost.tolist() == [[DELIVERED, TOO_WEAK]]


def test_delivery_ratio_by_distance_matches_the_shadowing_model():
    p = ChannelParameters(path_loss_exponent=2.7, shadowing_sigma_db=6.0, jitter=0.0)
    channel = Channel(p, seed=7)
    distances = np.array([100.0, 300.0, 500.0, 700.0, 900.0])
    rx = np.stack([distances, np.zeros(5), np.zeros(5)], axis=1)
    tx = np.zeros((1, 3))
    delivered = np.zeros(5)
    draws = 4000
    for step in range(draws):
        delivered += channel.transmit(step, 0.1, tx, rx).delivered[0]
    expected = p.delivery_probability(distances)
    assert np.abs(delivered / draws - expected).max() < 0.03  # 4000 draws: σ ≤ 0.008
    assert expected[0] > 0.9 and expected[-1] < 0.3  # the test spans the interesting part of the curve


def test_channel_is_deterministic_for_a_seed():
    p = ChannelParameters(shadowing_sigma_db=4.0, fading_m=1.0, jitter=0.01)
    pts = np.random.default_rng(0).uniform(0, 800, size=(20, 3))
    a = Channel(p, seed=3).transmit(5, 0.1, pts, pts)
    b = Channel(p, seed=3).transmit(5, 0.1, pts, pts)
    c = Channel(p, seed=4).transmit(5, 0.1, pts, pts)
    assert np.array_equal(a.lost, b.lost) and np.array_equal(a.delay, b.delay)
    assert not np.array_equal(a.rx_power_dbm, c.rx_power_dbm)


def test_blocked_line_of_sight_costs_the_nlos_loss():
    p = ChannelParameters(nlos_loss_db=30.0)
    tx = np.zeros((1, 3))
    rx = np.array([[100.0, 0.0, 0.0], [0.0, 100.0, 0.0]])
    clear = Channel(p, seed=0).transmit(0, 0.1, tx, rx)
    blocked = Channel(p, seed=0, los=lambda rows, cols: rx[cols, 1] < 50.0).transmit(
        0, 0.1, tx, rx
    )  # the +y link is blocked
    assert blocked.rx_power_dbm[0, 0] == pytest.approx(clear.rx_power_dbm[0, 0])
    assert blocked.rx_power_dbm[0, 1] == pytest.approx(clear.rx_power_dbm[0, 1] - 30.0)


def test_channel_busy_limit_keeps_the_strongest_messages():
    p = ChannelParameters(max_messages_per_second=20.0)  # 2 per 0.1 s step
    tx = np.array([[10.0, 0, 0], [20.0, 0, 0], [30.0, 0, 0], [40.0, 0, 0]])
    rx = np.zeros((1, 3))
    lost = Channel(p, seed=0).transmit(0, 0.1, tx, rx).lost[:, 0].tolist()
    assert lost == [DELIVERED, DELIVERED, BUSY, BUSY]


def test_a_station_does_not_receive_itself():
    pts = np.zeros((2, 3))
    pts[1, 0] = 10.0
    lost = Channel(ChannelParameters(), seed=0).transmit(0, 0.1, pts, pts, same=np.eye(2, dtype=bool)).lost
    assert lost.tolist() == [[-1, DELIVERED], [DELIVERED, -1]]


def test_within_criterion_names_the_banded_delivery_ratio():
    from pydantic import TypeAdapter

    from simcore.evaluation.criteria import ranges_of
    from simcore.spec import Criterion
    from simcore.v2x.metrics import V2XMetrics

    adapter: TypeAdapter[Any] = TypeAdapter(Criterion)
    criterion = adapter.validate_python("v2x.packetDeliveryRatio >= 0.9 within 300 m")
    assert criterion.metric == "v2x.packetDeliveryRatio.0-300m"
    assert ranges_of([criterion.metric, "detection.recall.0-50m"], "v2x.packetDeliveryRatio") == [300.0]
    metrics = V2XMetrics([300.0])
    metrics.links(np.array([50.0, 150.0, 250.0, 350.0]), np.array([True, True, False, False]))
    out = metrics.result()
    assert out["v2x.packetDeliveryRatio.0-300m"] == pytest.approx(2 / 3)
    assert out["v2x.packetDeliveryRatio.300-400m"] == 0.0
    assert out["v2x.packetDeliveryRatio"] == 0.5
    with pytest.raises(ValueError, match="applies to detection"):
        adapter.validate_python("minDistance >= 2 within 50 m")
