"""The in-flight airspeed-scale and wind-error estimate, on synthetic fixes (no sockets)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gcs.coordination.speedbias import BiasConfig, SpeedBiasEstimator
from planner.wind import Wind, groundspeed_m_s


def _fly(
    est: SpeedBiasEstimator,
    headings_rad: list[float],
    *,
    scale: float,
    true_wind: Wind,
    reported_wind: Wind,
    tas_m_s: float = 22.0,
    noise_m_s: float = 0.0,
    t0_s: float = 0.0,
    seed: int = 0,
) -> float:
    rng = np.random.default_rng(seed)
    t = t0_s
    for h in headings_rad:
        ve = scale * tas_m_s * math.sin(h) + true_wind.to_east_m_s + noise_m_s * rng.normal()
        vn = scale * tas_m_s * math.cos(h) + true_wind.to_north_m_s + noise_m_s * rng.normal()
        est.update(
            t, ve_m_s=ve, vn_m_s=vn, heading_rad=h, predicted_tas_m_s=tas_m_s, wind=reported_wind
        )
        t += 0.5
    return t


def test_learns_a_five_percent_fast_airframe_and_a_wind_error_over_a_turning_route() -> None:
    est = SpeedBiasEstimator()
    reported = Wind.from_speed_from(5.0, 270.0)
    true = Wind(reported.to_east_m_s + 1.2, reported.to_north_m_s - 0.5)
    headings = [math.radians(90.0 + 200.0 * math.sin(k / 60.0)) for k in range(600)]
    _fly(est, headings, scale=1.05, true_wind=true, reported_wind=reported, noise_m_s=0.3)
    assert est.scale == pytest.approx(1.05, abs=0.005)
    assert est.wind_error.to_east_m_s == pytest.approx(1.2, abs=0.15)
    assert est.wind_error.to_north_m_s == pytest.approx(-0.5, abs=0.15)


@pytest.mark.parametrize("scale", [0.95, 1.0, 1.05])
def test_on_one_straight_leg_the_groundspeed_of_that_leg_is_predicted_right(scale: float) -> None:
    """A straight leg cannot tell the scale from the wind along it; what it flies is right."""
    est = SpeedBiasEstimator()
    reported = Wind.from_speed_from(5.0, 270.0)
    true = Wind(reported.to_east_m_s + 0.8, reported.to_north_m_s + 0.3)
    track = math.radians(30.0)
    # Crab into the wind so that the ground track is `track`.
    air = 22.0 * scale
    cross = true.to_east_m_s * math.cos(track) - true.to_north_m_s * math.sin(track)
    heading = track - math.asin(cross / air)
    _fly(est, [heading] * 400, scale=scale, true_wind=true, reported_wind=reported)
    flown = groundspeed_m_s(air, track, true)
    predicted = groundspeed_m_s(22.0 * est.scale, track, est.corrected(reported))
    assert predicted == pytest.approx(flown, rel=2e-3)


def test_a_final_approach_sinking_to_its_goal_is_learnt_with_the_flight_path_angle() -> None:
    """A straight descent at 1.4 m/s (a route sinking to a goal below it) into a wind the
    autopilot over-reads by 1.2 m/s: the groundspeed of that descent is predicted right. With
    such fixes left out, the wind error stayed and the vehicle arrived about 0.9 s early."""
    est = SpeedBiasEstimator()
    true = Wind.from_speed_from(4.3, 180.0)
    reported = Wind.from_speed_from(5.5, 180.0)
    tas, sink = 26.0, -1.4
    horizontal = math.sqrt(tas**2 - sink**2)
    track = math.radians(190.0)
    cross = true.to_east_m_s * math.cos(track) - true.to_north_m_s * math.sin(track)
    heading = track - math.asin(cross / horizontal)
    for k in range(240):
        ve = horizontal * math.sin(heading) + true.to_east_m_s
        vn = horizontal * math.cos(heading) + true.to_north_m_s
        assert est.update(
            0.5 * k,
            ve_m_s=ve,
            vn_m_s=vn,
            heading_rad=heading,
            predicted_tas_m_s=tas,
            wind=reported,
            climb_m_s=sink,
        )
    flown = groundspeed_m_s(horizontal, track, true)
    predicted = groundspeed_m_s(horizontal * est.scale, track, est.corrected(reported))
    assert predicted == pytest.approx(flown, rel=2e-3)


def test_old_evidence_fades_when_the_bias_changes() -> None:
    est = SpeedBiasEstimator()
    still = Wind()
    headings = [math.radians(3.0 * k) for k in range(600)]
    t = _fly(est, headings, scale=1.05, true_wind=still, reported_wind=still)
    assert est.scale == pytest.approx(1.05, abs=0.003)
    _fly(est, headings * 2, scale=0.97, true_wind=still, reported_wind=still, t0_s=t)
    assert est.scale == pytest.approx(0.97, abs=0.005)


def test_fixes_while_climbing_steeply_or_settling_are_not_used() -> None:
    est = SpeedBiasEstimator()
    still = Wind()
    kw = {"ve_m_s": 0.0, "vn_m_s": 30.0, "heading_rad": 0.0, "predicted_tas_m_s": 20.0}
    assert not est.update(0.0, wind=still, climb_m_s=5.0, **kw)
    assert not est.update(0.5, wind=still, airspeed_m_s=17.0, commanded_m_s=20.0, **kw)
    assert not est.update(1.0, wind=still, **{**kw, "predicted_tas_m_s": math.nan})
    assert (est.used, est.skipped, est.scale) == (0, 3, 1.0)


def test_the_scale_is_bounded() -> None:
    est = SpeedBiasEstimator()
    still = Wind()
    headings = [math.radians(5.0 * k) for k in range(300)]
    _fly(est, headings, scale=1.6, true_wind=still, reported_wind=still)
    assert est.scale == pytest.approx(est.config.scale_bounds[1])


def test_with_the_scale_at_its_bound_the_wind_error_is_fitted_for_that_scale() -> None:
    """A 25 % fast airframe: the scale stops at its bound (1.15), and the wind error is the
    decayed least-squares fit, with its prior, for that scale (solved here by numpy): what
    the predictions are made with. Fitted for the scale beyond the bound instead, the wind
    error carried the part of the airspeed the bound cut off, the wrong way round."""
    est = SpeedBiasEstimator()
    cfg = est.config
    reported = Wind.from_speed_from(3.0, 120.0)
    rows_e, rows_n, times, tas = [], [], [], 22.0
    for k in range(200):
        t, h = 0.5 * k, math.radians(3.0 * k)
        ve = 1.25 * tas * math.sin(h) + reported.to_east_m_s + 1.0
        vn = 1.25 * tas * math.cos(h) + reported.to_north_m_s - 0.5
        assert est.update(
            t, ve_m_s=ve, vn_m_s=vn, heading_rad=h, predicted_tas_m_s=tas, wind=reported
        )
        rows_e.append((tas * math.sin(h), ve - reported.to_east_m_s))
        rows_n.append((tas * math.cos(h), vn - reported.to_north_m_s))
        times.append(t)
    k_bound = cfg.scale_bounds[1]
    assert est.scale == pytest.approx(k_bound)
    w = np.exp(-(times[-1] - np.array(times)) / cfg.time_constant_s)
    # For a fixed scale each component's fit is the weighted mean of what the scale leaves,
    # pulled towards 0 by the prior's weight.
    fit = [
        float(
            (w * (np.array([r for _, r in rows]) - k_bound * np.array([x for x, _ in rows]))).sum()
        )
        / float(w.sum() + cfg.prior_fixes)
        for rows in (rows_e, rows_n)
    ]
    assert (est.wind_error.to_east_m_s, est.wind_error.to_north_m_s) == pytest.approx(
        tuple(fit), abs=1e-9
    )


def test_the_estimate_is_the_decayed_least_squares_fit_with_its_prior() -> None:
    """The estimator's closed form against the same problem solved here by numpy: each fix's
    two rows weighted by exp(-age / time constant), the prior as that many fixes' worth of
    ``k = 1, dw = 0`` at the last predicted airspeed."""
    est = SpeedBiasEstimator()
    cfg = est.config
    rng = np.random.default_rng(5)
    rows, resid, times = [], [], []
    reported = Wind.from_speed_from(4.0, 200.0)
    tas = 0.0
    for k in range(60):
        t, h, tas = 0.5 * k, float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(18, 26))
        # 7% fast, the wind off by (1.5, -2) m/s, and noise: within the bounds, not clipped.
        ve = 1.07 * tas * math.sin(h) + reported.to_east_m_s + 1.5 + float(rng.normal(0, 1))
        vn = 1.07 * tas * math.cos(h) + reported.to_north_m_s - 2.0 + float(rng.normal(0, 1))
        assert est.update(
            t, ve_m_s=ve, vn_m_s=vn, heading_rad=h, predicted_tas_m_s=tas, wind=reported
        )
        rows += [[tas * math.sin(h), 1.0, 0.0], [tas * math.cos(h), 0.0, 1.0]]
        resid += [ve - reported.to_east_m_s, vn - reported.to_north_m_s]
        times += [t, t]
    w = np.exp(-(times[-1] - np.array(times)) / cfg.time_constant_s)
    a, r = np.array(rows), np.array(resid)
    prior = np.diag([cfg.prior_fixes * tas * tas, cfg.prior_fixes, cfg.prior_fixes])
    theta = np.linalg.solve(a.T @ (w[:, None] * a) + prior, a.T @ (w * r) + prior @ [1, 0, 0])
    lo, hi = cfg.scale_bounds
    assert lo < theta[0] < hi and math.hypot(theta[1], theta[2]) < cfg.max_wind_error_m_s
    assert est.scale == pytest.approx(theta[0], abs=1e-9)
    assert (est.wind_error.to_east_m_s, est.wind_error.to_north_m_s) == pytest.approx(
        (theta[1], theta[2]), abs=1e-9
    )


def test_a_gap_in_the_fixes_keeps_what_was_learnt() -> None:
    """A 5 % fast airframe learnt over five minutes, then 250 s with no fix (a restart of the
    coordinator): the first fix after it finds the estimate where it was, not pulled back to
    the prior (aged by the whole gap, the evidence fell to 1.5 % of its weight, and one noisy
    fix with the prior set the scale); a gap ages it by at most ``max_gap_s``."""
    still = Wind()
    headings = [math.radians(3.0 * k) for k in range(600)]

    def after_a_gap(est: SpeedBiasEstimator) -> tuple[float, float]:
        """The scale learnt, and the scale after one fix 250 s later, 1 m/s slow along its
        heading (noise)."""
        t = _fly(est, headings, scale=1.05, true_wind=still, reported_wind=still)
        learnt, h, tas = est.scale, 0.3, 22.0
        slow = 1.05 * tas - 1.0
        est.update(
            t + 250.0,
            ve_m_s=slow * math.sin(h),
            vn_m_s=slow * math.cos(h),
            heading_rad=h,
            predicted_tas_m_s=tas,
            wind=still,
        )
        return learnt, est.scale

    learnt, after = after_a_gap(SpeedBiasEstimator())
    assert learnt == pytest.approx(1.05, abs=0.003)
    assert after == pytest.approx(learnt, abs=0.002)
    # The same fix after a gap aged in full (a time constant of 60 s) moved it by over 1 %.
    aged = SpeedBiasEstimator(dataclasses.replace(BiasConfig(), max_gap_s=math.inf))
    learnt, after = after_a_gap(aged)
    assert abs(after - learnt) > 0.01
