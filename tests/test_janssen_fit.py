"""Band-true Janssen fit, pressure statistics and the resolution of derived numbers (issue 18,
items 1, 4 and 5), on constructed data with known answers. Pure Python: no engine."""
from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import quad
from scipy.signal import lfilter

from postprocess.dump_results import (MIN_STEADY_SAMPLES, band_extents, steady_resolution,
                                      surface_rate_resolution)
from postprocess.first_results import BAND_STATISTICS, band_statistics, batch_means_stderr, pressure_window
from postprocess.discharge import FlowRate
from postprocess.flow_rate import surface_flow_rate
from postprocess.janssen import (band_hydrostatic_pressure, band_janssen_pressure, fit_janssen_bands,
                                 janssen_depth_integral)
from postprocess.report import janssen_lines, post_process, report_text

RHO, G = 1500.0, 9.81


def janssen_at(depth, rho_b, g, D, mu, K):
    """Janssen's p(d), written out here independently of postprocess.janssen (0 above the surface)."""
    return rho_b * g * D / (4 * mu) * (1 - math.exp(-4 * mu * K * depth / D)) if depth > 0 else 0.0


def band_by_quadrature(z0, z1, h, rho_b, g, D, mu, K):
    """What a sensor z0..z1 reads: its force over its whole area = the mean of p(h - z) over the
    band's height, zero above the surface h; integrated numerically over z."""
    return quad(lambda z: janssen_at(h - z, rho_b, g, D, mu, K), z0, z1, points=[h] if z0 < h < z1 else None,
                epsabs=1e-13, epsrel=1e-13)[0] / (z1 - z0)


# ---------------------------------------------------------------- the band average

@pytest.mark.parametrize("mu, K", [(0.3, 0.5), (0.57, 0.54), (1.5, 2.0), (1e-5, 0.6)])
def test_band_average_matches_quadrature_below_across_and_above_the_surface(mu, K):
    """Bands wholly below the surface, cut by it (only the loaded part integrates, over the
    whole band's height) and wholly above it (0), against numerical quadrature of p(h - z)."""
    D, h = 0.03, 0.17
    z0 = np.array([0.0, 0.05, 0.10, 0.15, 0.20, 0.169])
    z1 = np.array([0.05, 0.10, 0.15, 0.20, 0.25, 0.1705])
    got = band_janssen_pressure(z0, z1, h, RHO, G, D, mu, K)
    want = [band_by_quadrature(a, b, h, RHO, G, D, mu, K) for a, b in zip(z0, z1)]
    assert got[4] == 0.0
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_band_cut_by_the_surface_by_hand():
    """Band 0.15-0.20 m, surface at h = 0.17 m: depths 0..0.02 m load it, over a 0.05 m band.
    Hydrostatic (K = 0.5): K rho g (0.02^2 / 2) / 0.05 = 0.5 x 1500 x 9.81 x 0.004 = 29.43 Pa;
    the point-at-centre model would put the band at depth -0.005 m (above the surface: 0 Pa).
    Janssen with mu = 0.3, K = 0.5, D = 0.03 m: L = D / (4 mu K) = 0.05 m, x = 0.02 / 0.05 = 0.4,
    integral = rho g D / (4 mu) L (x - 1 + e^-x) = 367.875 x 0.05 x 0.070320 = 1.29346 Pa m,
    over 0.05 m: 25.869 Pa."""
    assert band_hydrostatic_pressure(0.15, 0.20, 0.17, RHO, G, 0.5) == pytest.approx(29.43, rel=1e-12)
    assert RHO * G * 0.03 / 1.2 == pytest.approx(367.875)
    assert 0.4 - 1 + math.exp(-0.4) == pytest.approx(0.0703200460, rel=1e-9)
    assert band_janssen_pressure(0.15, 0.20, 0.17, RHO, G, 0.03, 0.3, 0.5) == pytest.approx(
        367.875 * 0.05 * 0.0703200460 / 0.05, rel=1e-9)
    # the depth integral's hydrostatic limit: mu -> 0 is K rho g (b^2 - a^2) / 2, without cancellation
    assert janssen_depth_integral(0.01, 0.1, RHO, G, 0.03, 1e-9, 0.6) == pytest.approx(
        0.6 * RHO * G * (0.1 ** 2 - 0.01 ** 2) / 2, rel=1e-7)


# ---------------------------------------------------------------- the fit

def column(h=0.155, D=0.03, mu=0.3, K=0.5, n=16, dz=0.01):
    """16 bands of 1 cm from the floor (z = 0), the surface at 15.5 cm cutting band 15 (15-16 cm)
    in half. D = 3 cm, mu 0.3, K 0.5: L = 5 cm, the bed is 3.1 decay lengths deep."""
    z0 = np.arange(n) * dz
    return z0, z0 + dz, h, D, band_janssen_pressure(z0, z0 + dz, h, RHO, G, D, mu, K)


def test_band_fit_recovers_k_and_mu_within_their_intervals():
    """Exact band data: K 0.5 and mu_eff 0.3 to 1e-6; mobilisation 0.3 / 0.5 = 0.6. With
    additive noise of 1 % of the largest band pressure, 60 realisations: each 95 % interval
    holds the truth in at least 52 of 60 (binomial mean 57, sd 1.7; measured over seeds
    1-3 x 300 realisations: 94-97 % for both)."""
    z0, z1, h, D, p = column()
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, mu_w=0.5, g=G, floor=0.0)
    assert fit.K == pytest.approx(0.5, rel=1e-6) and fit.mu_eff == pytest.approx(0.3, rel=1e-6)
    assert fit.mobilisation == pytest.approx(0.6, rel=1e-6) and fit.r2 == pytest.approx(1.0, abs=1e-12)
    assert fit.resolved and fit.flags == [] and fit.reason == ""
    assert fit.n_bands_used == 15 and fit.bands_used == list(range(1, 16))      # corner band 0 excluded
    assert [e["band"] for e in fit.bands_excluded] == [0]
    assert fit.length == pytest.approx(0.05) and fit.asymptote == pytest.approx(RHO * G * D / 1.2)
    rng = np.random.default_rng(11)
    hits = {"K": 0, "mu_eff": 0, "mobilisation": 0}
    for _ in range(60):
        f = fit_janssen_bands(z0, z1, p + 0.01 * p.max() * rng.standard_normal(len(p)), h, RHO, D, 0.5, G, floor=0.0)
        for name, true in (("K", 0.5), ("mu_eff", 0.3), ("mobilisation", 0.6)):
            lo, hi = getattr(f, f"{name}_ci")
            hits[name] += lo <= true <= hi
        assert f.mobilisation_ci == pytest.approx([c / 0.5 for c in f.mu_eff_ci])
    assert min(hits.values()) >= 52, hits
    # the interval is t(0.975, n - 2) standard errors: 13 degrees of freedom, t = 2.1604
    assert (f.K_ci[1] - f.K) / f.K_stderr == pytest.approx(2.160369, rel=1e-5)


def test_corner_band_is_excluded_when_asked():
    """The floor's corner band reads 60 % of Janssen (corner stresses are not Janssen's): excluded
    (the default), the fit is exact; included, it biases K by 14 % and mu_eff by 13 % (measured
    0.572 and 0.338) and spoils the fit (r2 0.90)."""
    z0, z1, h, D, p = column()
    p = p.copy()
    p[0] *= 0.6
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0)
    assert fit.exclude_corner and 0 not in fit.bands_used
    assert fit.K == pytest.approx(0.5, rel=1e-6) and fit.mu_eff == pytest.approx(0.3, rel=1e-6)
    biased = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0, exclude_corner=False)
    assert 0 in biased.bands_used and biased.n_bands_used == 16
    assert biased.K > 0.55 and biased.mu_eff > 0.33 and biased.r2 < 0.95, biased
    # no band on the floor (a plain wall below the sensors): nothing is excluded as a corner
    lifted = fit_janssen_bands(z0 + 0.02, z1 + 0.02, band_janssen_pressure(z0 + 0.02, z1 + 0.02, h, RHO, G, D, 0.3, 0.5),
                               h, RHO, D, 0.5, G, floor=0.0)
    assert all(not e["reason"].startswith("corner") for e in lifted.bands_excluded)


def test_quick_demo_profile_is_flagged_not_called_saturated():
    """Issue 18's quick demo (D = 3 cm, 6 bands of 5 cm, surface at 17 cm): its old point fit said
    K = 1.323, mu_w = 0.096. Band pressures rebuilt from that fit at the band centres (bands 0-2),
    band 3 cut by the surface, bands 4-5 above it:
    * corner excluded, 3 loaded bands (1, 2, 3) remain and the fit's K (about 1.39) lies outside
      0.2-1.0: flagged, not resolved;
    * with the surface at 14 cm only 2 loaded bands remain: flagged as too few, no interval."""
    D, h = 0.03, 0.17
    z0 = np.arange(6) * 0.05
    z1 = z0 + 0.05
    p = np.array([janssen_at(h - z - 0.025, RHO, G, D, 0.096, 1.323) for z in z0])
    p[3] = band_janssen_pressure(z0[3], z1[3], h, RHO, G, D, 0.096, 1.323)
    p[4:] = 0.05
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0, bands=np.arange(6))
    assert fit.bands_used == [1, 2, 3] and not fit.resolved
    assert any("outside the physical range 0.2-1" in f for f in fit.flags), fit.flags
    assert "saturated" not in " ".join(fit.flags)
    shallow = fit_janssen_bands(z0, z1, p, 0.14, RHO, D, 0.5, G, floor=0.0)
    assert shallow.n_bands_used == 2 and not shallow.resolved
    assert any(f.startswith("only 2 loaded band(s) used, fewer than 3 (the corner band is excluded)")
               for f in shallow.flags), shallow.flags
    assert all(math.isnan(c) for c in shallow.K_ci)
    # one band: nothing to fit, said so without raising
    one = fit_janssen_bands(z0, z1, p, 0.06, RHO, D, 0.5, G, floor=0.0)
    assert one.n_bands_used == 1 and math.isnan(one.K) and not one.resolved


@pytest.mark.parametrize("mu, K, flag", [(0.3, 1.5, "K = 1.5 (95 % CI 1.5-1.5) is outside the physical range"),
                                         (0.3, 0.15, "K = 0.15 (95 % CI 0.15-0.15) is outside the physical range"),
                                         (0.8, 0.5, "mobilisation mu_eff / mu_w = 1.6")])
def test_implausible_fits_are_flagged(mu, K, flag):
    """Well-resolved profiles (exact data, 15 bands) whose parameters no poured bed has: K
    outside 0.2-1.0, or mu_eff = 0.8 on a wall of mu_w = 0.5 (mobilisation 1.6 > 1)."""
    z0, z1, h, D, p = column(mu=mu, K=K)
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0)
    assert fit.K == pytest.approx(K, rel=1e-5) and fit.mu_eff == pytest.approx(mu, rel=1e-5)
    assert not fit.resolved and len(fit.flags) == 1 and fit.flags[0].startswith(flag), fit.flags
    assert fit.reason == fit.flags[0]


def test_a_k_at_the_top_of_the_range_within_its_interval_is_not_called_implausible():
    """K is implausible only when its whole 95 % interval lies outside 0.2-1.0 (as the mobilisation
    is above 1 only beyond its interval): a bed with K = 1.04 and scattered bands (+/- 4 %) fits to an
    interval that reaches below 1, and is resolved; the same bed with K = 1.6 is flagged."""
    rng = np.random.default_rng(7)
    for K, implausible in ((1.04, False), (1.6, True)):
        z0, z1, h, D, p = column(mu=0.3, K=K)
        noisy = p * (1.0 + 0.04 * rng.standard_normal(len(p)))
        fit = fit_janssen_bands(z0, z1, noisy, h, RHO, D, 0.5, G, floor=0.0)
        flagged = any("outside the physical range" in f for f in fit.flags)
        assert flagged == implausible, (K, fit.K, fit.K_ci, fit.flags)
        if not implausible:
            assert fit.K_ci[0] < 1.0 < fit.K_ci[1] and fit.resolved, (fit.K, fit.K_ci, fit.flags)


def test_hydrostatic_profile_fits_k_and_says_mu_is_not_measurable():
    """p = 0.6 rho g d (no wall friction mobilised), band-averaged: the hydrostatic comparison gives
    K = 0.6 exactly with r2 1; the Janssen fit's mu_eff falls to 0 and is flagged as not measurable."""
    z0, z1, h, D, _ = column()
    p = band_hydrostatic_pressure(z0, z1, h, RHO, G, 0.6)
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0)
    assert fit.hydrostatic_K == pytest.approx(0.6, rel=1e-12) and fit.hydrostatic_r2 == pytest.approx(1.0)
    assert fit.K == pytest.approx(0.6, rel=1e-4) and fit.mu_eff < 1e-4
    assert not fit.resolved and any("no wall friction is measurable" in f for f in fit.flags), fit.flags
    # a Janssen profile is not hydrostatic: its hydrostatic r2 is worse than Janssen's
    z0, z1, h, D, p = column()
    fit = fit_janssen_bands(z0, z1, p, h, RHO, D, 0.5, G, floor=0.0)
    assert fit.hydrostatic_r2 < 0.9 < fit.r2


def test_summary_fit_reads_band_extents_friction_and_floor_from_the_plan():
    """dump_results.janssen_static: band heights from the plan's walls (4 sectors per band), mu_w
    from its particle-wall pair, D = 2 R, the floor at the hopper's top (a 2 cm hopper: band 0
    stands on it and is excluded); the summary entry is the fit's fields."""
    from postprocess.dump_results import janssen_static
    hh, D, h = 0.02, 0.03, 0.02 + 0.255
    walls = [SimpleNamespace(role="band", band=b, sector=s, z0=hh + 0.05 * b, z1=hh + 0.05 * (b + 1))
             for b in range(6) for s in range(4)] + [SimpleNamespace(role="bottom", band=None, z0=None, z1=None)]
    plan = SimpleNamespace(walls=walls, gravity=G, pairs={"particle_wall": SimpleNamespace(friction=0.6)},
                           geometry=SimpleNamespace(kind="hopper", radius=D / 2, hopper_height=hh))
    z0 = hh + 0.05 * np.arange(6)
    table = pd.DataFrame({"band": np.arange(6), "z_mid": z0 + 0.025,
                          "static_pressure": band_janssen_pressure(z0, z0 + 0.05, h, RHO, G, D, 0.3, 0.5)})
    j = janssen_static(plan, table, h, RHO)
    assert j["K"] == pytest.approx(0.5, rel=1e-6) and j["mu_eff"] == pytest.approx(0.3, rel=1e-6)
    assert j["mu_w"] == 0.6 and j["mobilisation"] == pytest.approx(0.5, rel=1e-6) and j["diameter"] == D
    assert j["bands_used"] == [1, 2, 3, 4, 5] and j["bands_excluded"][0]["band"] == 0 and j["exclude_corner"]
    assert j["resolved"] and "saturated" not in j
    empty = janssen_static(plan, table.iloc[:0], h, RHO)
    assert not empty["resolved"] and "no wall-pressure sensors" in empty["reason"]


def test_band_extents_from_plan_walls_and_bad_input():
    walls = [SimpleNamespace(role="band", band=b, sector=s, z0=0.01 * b, z1=0.01 * (b + 1))
             for b in range(3) for s in range(4)] + [SimpleNamespace(role="wall", band=None, z0=0.03, z1=0.3)]
    assert band_extents(walls) == {0: (0.0, 0.01), 1: (0.01, 0.02), 2: (0.02, 0.03)}
    with pytest.raises(ValueError, match="z1 > z0"):
        fit_janssen_bands([0.1], [0.1], [1.0], 0.2, RHO, 0.03, 0.5)
    with pytest.raises(ValueError, match="one entry per band"):
        fit_janssen_bands([0.0, 0.1], [0.1, 0.2], [1.0], 0.2, RHO, 0.03, 0.5)


# ---------------------------------------------------------------- pressure statistics

def test_batch_means_standard_error_by_hand():
    """40 samples -> 10 batches of 4; 12 samples -> 5 batches of 2, the first 2 samples dropped;
    9 samples -> none. Batch means 0, 1, ..., 9: SE = sd(0..9) / sqrt(10) = 3.02765 / 3.16228."""
    x = np.repeat(np.arange(10.0), 4) + np.tile([-1.0, 1.0, -1.0, 1.0], 10)
    se, b = batch_means_stderr(x)
    assert b == 10 and se == pytest.approx(math.sqrt(sum((k - 4.5) ** 2 for k in range(10)) / 9) / math.sqrt(10))
    se, b = batch_means_stderr(np.concatenate([[100.0, -100.0], np.repeat([1.0, 2.0, 3.0, 4.0, 5.0], 2)]))
    assert b == 5 and se == pytest.approx(math.sqrt(2.5) / math.sqrt(5))
    assert batch_means_stderr(np.ones(9)) == (pytest.approx(float("nan"), nan_ok=True), 0)


def test_batch_means_standard_error_of_an_ar1_series():
    """AR(1) x_t = 0.8 x_(t-1) + e_t (e ~ N(0, 1), stationary start), n = 2000, 400 series. The
    exact variance of the mean: sigma^2 / n (1 + 2 sum_k (1 - k/n) 0.8^k), sigma^2 = 1 / (1 - 0.64):
    SE = 0.111679. The batch-means SE (10 batches of 200) gives it, RMS over the series, within
    10 % (measured over seeds 1-4: 0.96-1.02); the naive sd / sqrt(n) is sqrt(0.2 / 1.8) = 0.333
    of it (measured 0.332-0.333)."""
    phi, n = 0.8, 2000
    rng = np.random.default_rng(3)
    e = rng.standard_normal((400, n))
    x0 = rng.standard_normal(400) / math.sqrt(1 - phi ** 2)
    x = lfilter([1.0], [1.0, -phi], e, axis=1, zi=(phi * x0)[:, None])[0]
    k = np.arange(1, n)
    true = math.sqrt(1 / (1 - phi ** 2) / n * (1 + 2 * np.sum((1 - k / n) * phi ** k)))
    assert true == pytest.approx(0.111679, rel=1e-5)
    se = np.array([batch_means_stderr(row)[0] for row in x])
    assert 0.9 < math.sqrt(np.mean(se ** 2)) / true < 1.1
    naive = x.std(axis=1, ddof=1) / math.sqrt(n)
    assert np.mean(naive) / true == pytest.approx(math.sqrt(0.2 / 1.8), rel=0.05)


def test_band_statistics_of_a_synthetic_series():
    """Two bands, steps 0..59. Static window: steps 0-19 (20 samples: 5 batches of 4); dynamic
    window: steps 30-50 (21 samples), band 0 reading 1, 2, ..., 21 Pa there: mean 11, sd
    sqrt(2 (1 + 4 + ... + 100) / 20) = sqrt(38.5), 95th percentile at position 0.95 x 20 = 19:
    20 Pa, max 21 Pa. Band 1 reads 2 x band 0 + 5."""
    steps = np.arange(60)
    base = np.where(steps < 20, 100.0 + (steps // 4), np.where((steps >= 30) & (steps <= 50), steps - 29.0, 0.0))
    bands = pd.DataFrame({"step": np.tile(steps, 2), "band": np.repeat([0, 1], 60),
                          "pressure": np.concatenate([base, 2 * base + 5])}).sample(frac=1.0, random_state=1)
    static = bands.step < 20
    dynamic = (bands.step >= 30) & (bands.step <= 50)
    # the static window's sector means: band 0's four sectors 98, 100, 102, 104 (sd sqrt(20/3), SE / 2)
    sector_means = pd.Series([98.0, 100.0, 102.0, 104.0, 7.0], index=pd.MultiIndex.from_tuples(
        [(0, 0), (0, 1), (0, 2), (0, 3), (1, 0)], names=["band", "sector"]))
    t = band_statistics(bands, dynamic, static, sector_means)
    assert list(t.columns) == BAND_STATISTICS and list(t.index) == [0, 1]
    b0 = t.loc[0]
    assert b0.dynamic_samples == 21 and b0.dynamic_mean_pressure == pytest.approx(11.0)
    assert b0.dynamic_std_pressure == pytest.approx(math.sqrt(38.5))
    assert b0.dynamic_p95_pressure == pytest.approx(20.0) and b0.dynamic_max_pressure == 21.0
    # static: batch means 100, 101, ..., 104 (sorted by step whatever the row order): SE sd/sqrt(5)
    assert b0.static_samples == 20 and b0.static_batches == 5
    assert b0.static_pressure_batch_stderr == pytest.approx(math.sqrt(2.5) / math.sqrt(5))
    assert b0.static_sectors == 4 and b0.static_pressure_sector_stderr == pytest.approx(math.sqrt(20 / 3) / 2)
    assert b0.static_pressure_stderr == pytest.approx(math.hypot(math.sqrt(0.5), math.sqrt(20 / 3) / 2))
    b1 = t.loc[1]
    assert b1.dynamic_mean_pressure == pytest.approx(27.0) and b1.dynamic_p95_pressure == pytest.approx(45.0)
    assert b1.dynamic_std_pressure == pytest.approx(2 * math.sqrt(38.5))
    assert b1.static_pressure_batch_stderr == pytest.approx(2 * math.sqrt(2.5) / math.sqrt(5))
    # one sector shows no spread around the wall: no headline error rather than one too small
    assert b1.static_sectors == 1 and math.isnan(b1.static_pressure_stderr)
    # no dynamic window: counts 0, statistics NaN
    none = band_statistics(bands, False, static)
    assert (none.dynamic_samples == 0).all() and none.dynamic_mean_pressure.isna().all()


def test_pressure_window_prefers_a_resolved_steady_window():
    rate = SimpleNamespace(t_start=1.0, t_end=2.0)
    steady = {"t_start": 1.2, "t_end": 1.8, **steady_resolution(40)}
    assert pressure_window(steady, rate) == {"source": "steady window detected", "t_start": 1.2, "t_end": 1.8}
    short = {"t_start": 1.2, "t_end": 1.3, **steady_resolution(MIN_STEADY_SAMPLES - 1)}
    assert not short["resolved"] and "holds 9 samples (needs 10)" in short["reason"]
    assert pressure_window(short, rate)["source"] == "flow-rate fit window"
    assert pressure_window(None, SimpleNamespace(t_start=float("nan"), t_end=float("nan"))) is None


# ---------------------------------------------------------------- Wr resolved or not

def test_wr_is_not_resolved_when_the_surface_moved_less_than_three_grain_diameters():
    """Quick-demo-like silo (R = 15 mm, rho_b 1500, d = 3 mm), 0.8 s of discharge: a surface
    falling 1 grain diameter (3.75 mm/s) is not resolved; 4 diameters (15 mm/s) is. The height
    series carries 0.1 mm noise; the descent is the fitted speed x the window."""
    d, area = 0.003, math.pi * 0.015 ** 2
    t = np.linspace(1.0, 1.8, 41)
    noise = 1e-4 * np.random.default_rng(5).standard_normal(len(t))
    slow = surface_flow_rate(t, 0.17 - 0.00375 * (t - 1.0) + noise, area, RHO)
    r = surface_rate_resolution(slow, area, RHO, d)
    assert not r["resolved"] and r["surface_descent_grain_diameters"] == pytest.approx(1.0, abs=0.1)
    assert "grain diameters over t = 1-1.8 s; Wr needs at least 3 (9 mm)" in r["reason"], r["reason"]
    fast = surface_flow_rate(t, 0.17 - 0.015 * (t - 1.0) + noise, area, RHO)
    r = surface_rate_resolution(fast, area, RHO, d)
    assert r["resolved"] and r["reason"] == "" and r["surface_descent_m"] == pytest.approx(0.012, rel=0.02)
    r = surface_rate_resolution(FlowRate(float("nan"), float("nan"), float("nan"), float("nan"), 2), area, RHO, d)
    assert not r["resolved"] and "only 2 free-surface sample(s)" in r["reason"]


# ---------------------------------------------------------------- the report

def test_report_says_not_resolved_with_the_reason_and_never_saturated():
    D, h = 0.03, 0.14
    z0 = np.arange(6) * 0.05
    p = band_janssen_pressure(z0, z0 + 0.05, h, RHO, G, D, 0.1, 1.3)
    j = asdict(fit_janssen_bands(z0, z0 + 0.05, p, h, RHO, D, 0.5, G, floor=0.0))
    wr = {**asdict(FlowRate(0.004, 1e-4, 1.0, 1.8, 41)),
          **surface_rate_resolution(FlowRate(0.004, 1e-4, 1.0, 1.8, 41), math.pi * 0.015 ** 2, RHO, 0.003)}
    summary = {"particles_inserted": 5000, "initial_mass_kg": 0.07, "settled_ke_pe": 1e-6, "time_open_s": 0.5,
               "force_balance": None, "discharged_mass_kg": 0.02, "mass_in_silo_end_kg": 0.05,
               "flow_rate": {"rate": 0.02, "stderr": 1e-4, "t_start": 0.7, "t_end": 1.5, "r2": 0.999},
               "steady_window_detected": {"t_start": 0.7, "t_end": 0.72, "median_rate": 0.02, "n_samples": 5,
                                          **steady_resolution(5)},
               "frame_analyses": {"bulk_solid_fraction": 0.6, "cross_section_solid_fraction": 0.58,
                                  "bulk_density_kg_m3": 1500.0, "settled_surface_height_m": h,
                                  "flow_rate_surface": wr, "flow_rate_surface_over_outlet": 0.2,
                                  "janssen_static": j},
               "bands": [], "pressure_statistics": None}
    text = report_text(summary, SimpleNamespace(folder=Path("runs/quick")))
    assert "saturated" not in text
    assert "free-surface flow rate Wr: not resolved: the free surface descended" in text
    assert "steady discharge detected (the window of the dynamic pressures): t = 0.7-0.72 s: not resolved: the " \
        "steady window holds 5" in text
    assert "Janssen fit of the settled profile (band-averaged below the free surface, 2 band(s) 1-2; corner band " \
           "excluded): not resolved: only 2 loaded band(s) used" in text, text
    z0 = np.arange(16) * 0.01
    good = asdict(fit_janssen_bands(z0, z0 + 0.01, band_janssen_pressure(z0, z0 + 0.01, 0.155, RHO, G, D, 0.3, 0.5),
                                    0.155, RHO, D, 0.5, G, floor=0.0))
    line = janssen_lines(good)[0]
    assert "K = 0.500 [0.5, 0.5], mu_eff = 0.300 [0.3, 0.3], mobilisation mu_eff / mu_w = 0.60 [0.60, 0.60] " \
           "of mu_w = 0.5" in line, line
    assert janssen_lines({"error": "no wall-pressure sensors"}) == [
        "- Janssen fit of the settled profile: not fitted: no wall-pressure sensors"]


# ---------------------------------------------------------------- analyse() end to end, no engine

class FakeRun:
    """What ``first_results.analyse`` reads of a run folder (``RunOutputs``), built in memory: a
    slab-like silo of 4 bands x 2 sensor sides (1 cm each, from the floor at z = 0), sampled every
    1 ms (dt 1e-5 s, 100 steps); static stage from t = 0.1 s, outlet open at 0.2 s, run to 1.2 s;
    mass leaves at 20 g/s from t = 0.25 s. Band k reads 1000 - 100 k Pa (+ 5 Pa noise) while
    static (to the opening step, inclusive) and 1.1 x that + 30 sin(2 pi 7 t) Pa after. No dumps:
    no frame analyses."""

    def __init__(self, tmp_path):
        from siloflow.plan import Wall
        rng = np.random.default_rng(2)
        self.folder = tmp_path / "run"
        self.run = SimpleNamespace(results=self.folder / "results", dump_files=lambda kind: None)
        self.folder.mkdir()
        self.dt, self.sample_steps = 1e-5, 100
        self.stage_steps = {"static": 10000, "open": 20000, "discharge": 20000}
        self.walls = [Wall(name=f"band{k:02d}_s{s:02d}", role="band", file="x.stl", area=1e-4, n_triangles=2,
                           band=k, sector=s, z0=0.01 * k, z1=0.01 * (k + 1), normal=(-1.0 if s == 0 else 1.0, 0.0),
                           projected_area=1e-4) for k in range(4) for s in range(2)]
        steps = np.arange(0, 120001, 100)
        t = steps * self.dt
        cols = {"step": steps}
        for w in self.walls:
            base = 1000.0 - 100.0 * w.band
            p = np.where(steps <= 20000, base + 5.0 * rng.standard_normal(len(t)), 1.1 * base + 30 * np.sin(2 * np.pi * 7 * t))
            sign = w.normal[0]
            cols[f"{w.name}_fx"], cols[f"{w.name}_fy"], cols[f"{w.name}_fz"] = sign * p * 1e-4, 0 * t, -0.01 + 0 * t
        self.forces = pd.DataFrame(cols)
        self.has_bands = True
        out = np.clip(0.02 * (t - 0.25), 0, None)
        self.flow = pd.DataFrame({"step": steps, "discharged_mass": out, "mass_silo": 0.07 - out,
                                  "mass_total": 0.07 - out, "atoms": np.full(len(t), 5000)})
        grain = SimpleNamespace(kind="sphere", radius=0.0011, density=2500.0, number_fraction=1.0,
                                mass=0.07 / 5000)          # the 70 g bed below, as planned
        self.plan = SimpleNamespace(gravity=G, outputs=SimpleNamespace(results=None), design=None,
                                    fill=SimpleNamespace(bed_height_estimate=0.2, packing_fraction=0.6, count=5000),
                                    grains=[grain], species=[grain], expected_mass=5000 * grain.mass,
                                    pairs={"particle_particle": SimpleNamespace(friction=0.5),
                                           "particle_wall": SimpleNamespace(friction=0.5)},
                                    geometry=SimpleNamespace(kind="planar", thickness=0.01, outlet_radius=0.006),
                                    # a slab: EN 1991-4 not computed; Beverloo's slot law
                                    engine=SimpleNamespace(name="liggghts", ranks=1))
        self.record = SimpleNamespace(engine="liggghts", inserted=5000, fill_losses=0, settled_ke_pe=1e-6, wall_time=1.0,
                                      discharge_stop=None, fill_cache=None, warnings=[], guard=None,
                                      guard_peaks={"max_speed": 1.2, "max_overlap": 1.5e-5})

    def stage_time(self, stage):
        return self.stage_steps[stage] * self.dt


def test_analyse_writes_the_pressure_statistics_and_resolution(tmp_path, monkeypatch):
    """The pressure statistics go into summary['bands'], bands.csv and the report; the steady
    window carries n_samples and resolved. Over the steady window the dynamic pressure is
    1.1 p_k + 30 sin(2 pi 7 t): mean about 1.1 p_k, sd about 30 / sqrt 2 = 21.2 Pa, max up to
    1.1 p_k + 30; the static mean's batch-means SE about (5 / sqrt 2) / sqrt(99) = 0.36 Pa (99
    samples of white noise, the mean of two sides)."""
    import postprocess.first_results as fr
    run = FakeRun(tmp_path)
    monkeypatch.setattr(fr, "RunOutputs", lambda folder: run)
    summary = post_process(run.folder)
    steady = summary["steady_window_detected"]
    assert steady["resolved"] and steady["n_samples"] >= 10
    stats = summary["pressure_statistics"]
    assert stats["dynamic_window"]["source"] == "steady window detected" and stats["dynamic_window"]["resolved"]
    table = pd.read_csv(run.run.results / "bands.csv")
    assert list(table.columns[:6]) == ["band", "z_mid", "static_pressure", "static_shear", "max_dynamic_pressure",
                                       "discharge_factor"]
    assert list(table.columns[6:]) == BAND_STATISTICS
    for _, b in table.iterrows():
        base = 1000.0 - 100.0 * b.band
        assert b.dynamic_mean_pressure == pytest.approx(1.1 * base, abs=3.0)
        assert b.dynamic_std_pressure == pytest.approx(30 / math.sqrt(2), rel=0.05)
        assert 1.1 * base + 25 < b.dynamic_max_pressure <= 1.1 * base + 30 + 1e-9
        assert b.dynamic_p95_pressure < b.dynamic_max_pressure
        assert b.static_batches == 10 and 0.2 < b.static_pressure_stderr < 1.0
    assert summary["bands"][0]["dynamic_samples"] == stats["dynamic_window"]["n_samples"]
    report = (run.run.results / "report.md").read_text()
    assert "| band | z (m) | static p | dynamic mean +/- sd | p95 | max (window) | max dynamic | C_h |" in report
    assert "Dynamic: over the steady window detected" in report
