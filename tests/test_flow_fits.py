"""The one straight-line fit (postprocess.discharge.straight_line_fit) behind the outlet flow
rate (steady_flow_rate, kg/s) and the free-surface rate (linear_rate / surface_flow_rate),
checked against references that share none of its code: exact rational arithmetic, the
textbook closed form, np.polyfit(cov=True), np.linalg.lstsq and scipy.stats.linregress."""
from __future__ import annotations

import math
from dataclasses import astuple
from fractions import Fraction

import numpy as np
import pytest

from postprocess.discharge import FlowRate, LineFit, steady_flow_rate, straight_line_fit
from postprocess.flow_rate import linear_rate, surface_flow_rate

REL = 1e-12


def noisy_line(seed: int, n: int | None = None, noise: float | None = None):
    """Samples of a random line over a random window of time (s), with Gaussian noise of
    ``noise`` times the signal's size (random between 1e-3 and 1 when not given)."""
    rng = np.random.default_rng(seed)
    n = n or int(rng.integers(5, 300))
    t = np.sort(rng.uniform(0, 20) + rng.uniform(0.5, 20) * rng.random(n))
    v = rng.normal(0, 5) * t + rng.normal(0, 3)
    scale = noise if noise is not None else 10 ** rng.uniform(-3, 0)
    return t, v + rng.normal(0, scale * np.abs(v).max(), n)


def exact_fit(t, v):
    """Slope, stderr, intercept and r2 in exact rational arithmetic on the float samples."""
    T, V = [Fraction(x) for x in t], [Fraction(x) for x in v]
    n = len(T)
    tb, vb = sum(T) / n, sum(V) / n
    stt = sum((x - tb) ** 2 for x in T)
    slope = sum((x - tb) * (y - vb) for x, y in zip(T, V)) / stt
    ss_res = sum((y - vb - slope * (x - tb)) ** 2 for x, y in zip(T, V))
    ss_tot = sum((y - vb) ** 2 for y in V)
    return (float(slope), math.sqrt(ss_res / (n - 2) / stt), float(vb - slope * tb),
            float(1 - ss_res / ss_tot))


@pytest.mark.parametrize("seed", range(20))
def test_fit_matches_exact_arithmetic(seed):
    t, v = noisy_line(seed, n=40)
    fit = straight_line_fit(t, v)
    slope, stderr, intercept, r2 = exact_fit(t, v)
    assert fit.slope == pytest.approx(slope, rel=REL)
    assert fit.stderr == pytest.approx(stderr, rel=REL)
    assert fit.intercept == pytest.approx(intercept, rel=REL, abs=REL * np.abs(v).max())
    assert fit.r2 == pytest.approx(r2, rel=REL, abs=REL)
    assert (fit.t_start, fit.t_end, fit.n_samples) == (t[0], t[-1], 40)


@pytest.mark.parametrize("seed", range(20))
def test_fit_matches_closed_form(seed):
    """slope = cov(t, v) / var(t); stderr = sqrt(ss_res / (n - 2) / sum((t - tbar)^2))."""
    t, v = noisy_line(seed, noise=0.3)
    n = len(t)
    slope = np.cov(t, v)[0, 1] / np.var(t, ddof=1)
    intercept = v.mean() - slope * t.mean()
    ss_res = ((v - intercept - slope * t) ** 2).sum()
    stderr = math.sqrt(ss_res / (n - 2) / ((t - t.mean()) ** 2).sum())
    fit = straight_line_fit(t, v)
    assert fit.slope == pytest.approx(slope, rel=REL)
    assert fit.stderr == pytest.approx(stderr, rel=REL)
    assert fit.intercept == pytest.approx(intercept, rel=REL, abs=REL * np.abs(v).max())
    assert fit.r2 == pytest.approx(1 - ss_res / ((v - v.mean()) ** 2).sum(), rel=REL)


@pytest.mark.parametrize("seed", range(20))
def test_fit_matches_the_two_fits_it_replaced(seed):
    """The former linear_rate (np.polyfit, cov=True) and steady_flow_rate (np.linalg.lstsq).

    numpy >= 1.16 scales polyfit's covariance by ss_res / (n - deg - 1) = ss_res / (n - 2), the
    same n - 2 degrees of freedom (earlier numpy used n - deg - 3); a small n tells them apart."""
    t, v = noisy_line(seed, n=6 if seed % 2 else None)
    fit = straight_line_fit(t, v)
    (p_slope, p_icpt), cov = np.polyfit(t, v, 1, cov=True)
    assert fit.slope == pytest.approx(p_slope, rel=REL)
    assert fit.stderr == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-10)   # polyfit's own rounding
    A = np.column_stack([t, np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(A, v, rcond=None)
    ss_res = ((v - A @ coef) ** 2).sum()
    assert fit.slope == pytest.approx(coef[0], rel=REL)
    assert fit.stderr == pytest.approx(math.sqrt(ss_res / (len(t) - 2) / ((t - t.mean()) ** 2).sum()), rel=REL)
    assert fit.r2 == pytest.approx(1 - ss_res / ((v - v.mean()) ** 2).sum(), rel=REL)


@pytest.mark.parametrize("seed", range(20))
def test_fit_matches_scipy_linregress(seed):
    stats = pytest.importorskip("scipy.stats")
    t, v = noisy_line(seed, noise=0.3)
    ref = stats.linregress(t, v)
    fit = straight_line_fit(t, v)
    assert fit.slope == pytest.approx(ref.slope, rel=REL)
    assert fit.intercept == pytest.approx(ref.intercept, rel=REL, abs=REL * np.abs(v).max())
    assert fit.stderr == pytest.approx(ref.stderr, rel=REL)
    assert fit.r2 == pytest.approx(ref.rvalue ** 2, rel=REL, abs=REL)


def test_fit_far_from_time_zero_stays_accurate():
    """A short window late in a run (t ~ 1e3 s, 0.1 s wide): the fit is about the mean time."""
    rng = np.random.default_rng(7)
    t = 1000.0 + np.linspace(0, 0.1, 50)
    v = 0.04 * t + rng.normal(0, 1e-6, t.size)
    fit = straight_line_fit(t, v)
    slope, stderr, _, _ = exact_fit(t, v)
    assert fit.slope == pytest.approx(slope, rel=1e-12) and fit.stderr == pytest.approx(stderr, rel=1e-9)


def test_fit_degenerate_inputs():
    nan_fit = straight_line_fit([0.0, 1.0], [0.0, 1.0])
    assert math.isnan(nan_fit.slope) and math.isnan(nan_fit.stderr) and nan_fit.n_samples == 2
    assert (nan_fit.t_start, nan_fit.t_end) == (0.0, 1.0)
    empty = straight_line_fit([], [])
    assert empty.n_samples == 0 and all(math.isnan(x) for x in astuple(empty)[:6])
    same_time = straight_line_fit(np.ones(6), np.arange(6.0))
    assert math.isnan(same_time.slope) and math.isnan(same_time.stderr)
    flat = straight_line_fit(np.arange(6.0), np.full(6, 2.5))
    assert flat.slope == 0.0 and flat.stderr == 0.0 and flat.intercept == 2.5 and math.isnan(flat.r2)
    exact = straight_line_fit(np.arange(10.0), 3.0 - 0.5 * np.arange(10.0))
    assert exact.slope == pytest.approx(-0.5, rel=1e-15) and exact.stderr < 1e-15 and exact.r2 == pytest.approx(1.0)
    with_nan = straight_line_fit(np.arange(6.0), [0, 1, np.nan, 3, 4, 5])
    assert math.isnan(with_nan.slope) and math.isnan(with_nan.stderr)
    with pytest.raises(ValueError, match="same length"):
        straight_line_fit(np.arange(5.0), np.arange(6.0))


# ----------------------------------------------------------------- the callers


def test_steady_flow_rate_is_the_line_fit_of_its_window():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 6, 601)
    t_open, M0 = 1.0, 2.0
    mass = np.clip(0.3 * (t - t_open), 0, M0) + rng.normal(0, 1e-4, t.size)   # kg
    rate = steady_flow_rate(t, mass, t_open, mass_in_silo=M0 - mass, initial_mass=M0)
    keep = (t >= t_open + 0.2) & (M0 - mass >= 0.2 * M0)
    fit = straight_line_fit(t[keep], mass[keep])
    assert isinstance(rate, FlowRate) and isinstance(fit, LineFit)
    assert (rate.rate, rate.fit_stderr, rate.t_start, rate.t_end, rate.n_samples, rate.r2) == \
        (fit.slope, fit.stderr, fit.t_start, fit.t_end, fit.n_samples, fit.r2)
    assert rate.batches == 10 and rate.stderr > 0
    assert rate.rate == pytest.approx(0.3, abs=4 * rate.stderr)


def test_steady_flow_rate_needs_five_samples():
    t = np.linspace(0, 1, 11)
    few = steady_flow_rate(t, 2 * t, t_open=0.6, skip=0.0)             # 0.6 ... 1.0: 5 samples
    assert few.n_samples == 5 and few.rate == pytest.approx(2.0)
    four = steady_flow_rate(t, 2 * t, t_open=0.65, skip=0.0)           # 0.7 ... 1.0: 4 samples
    assert math.isnan(four.rate) and math.isnan(four.stderr) and math.isnan(four.r2)
    assert (four.t_start, four.t_end, four.n_samples) == (0.65, 1.0, 4)
    none = steady_flow_rate([], [], t_open=2.0)
    assert math.isnan(none.rate) and (none.t_start, none.t_end, none.n_samples) == (2.0, 2.0, 0)


def test_linear_rate_and_surface_rate_are_the_line_fit():
    t, h = noisy_line(11, n=50)
    fit = straight_line_fit(t, h)
    lr = linear_rate(t, h)
    assert isinstance(lr, FlowRate)
    assert astuple(lr) == (fit.slope, fit.stderr, fit.t_start, fit.t_end, fit.n_samples, None, None, None)
    assert list(lr.record()) == ["rate", "stderr", "t_start", "t_end", "n_samples"]   # summary.json's keys
    wr = surface_flow_rate(t, h, area=0.02, bulk_density=1500.0)               # kg/s
    assert wr.rate == pytest.approx(-fit.slope * 30.0, rel=1e-15) and wr.stderr == pytest.approx(fit.stderr * 30.0, rel=1e-15)


def test_linear_rate_needs_three_samples():
    two = linear_rate([0.0, 1.0], [0.0, 1.0])
    assert all(math.isnan(x) for x in astuple(two)[:4]) and two.n_samples == 2
    three = linear_rate([0.0, 1.0, 2.0], [0.0, 1.1, 1.9])
    assert three.rate == pytest.approx(0.95) and three.stderr > 0 and three.n_samples == 3


def test_the_batch_means_error_of_a_flow_rate_stands_for_the_spread_of_realizations():
    """A discharge whose rate fluctuates slowly (AR(1), phi 0.95 per sample): over 300 realizations the
    spread of the fitted rate is what the batch-means error says (within 35 %), while the straight
    line's stderr, which takes the samples as independent, is several times too small (issue 16)."""
    rng = np.random.default_rng(11)
    n, dt, phi = 600, 0.005, 0.95
    t = np.arange(n) * dt
    rates, batch, line = [], [], []
    for _ in range(300):
        e = np.zeros(n)
        noise = rng.normal(0, 0.05, n)
        for k in range(1, n):
            e[k] = phi * e[k - 1] + noise[k]
        mass = np.concatenate([[0.0], np.cumsum((0.3 + e[1:]) * dt)])
        fr = steady_flow_rate(t, mass, t_open=0.0, skip=0.0)
        rates.append(fr.rate)
        batch.append(fr.stderr)                 # the headline error: batch means
        line.append(fr.fit_stderr)
    spread = np.std(rates, ddof=1)
    assert np.mean(batch) == pytest.approx(spread, rel=0.35)
    assert np.mean(line) < 0.3 * spread


def test_a_report_gives_one_flow_rate_with_its_batch_error_in_a_readable_unit():
    """Issue 35: the headline error is the batch-means one, printed to two figures in a unit of the
    rate's size; a detected window whose median rate differs from Wf by more than 2 errors says why,
    one within them gives no second rate."""
    from postprocess.report import flow_rate_line, steady_window_line
    fr = {"rate": 29.04471, "stderr": 0.52, "fit_stderr": 0.04, "batches": 10, "t_start": 1.0, "t_end": 3.0,
          "n_samples": 400, "r2": 0.999}
    line = flow_rate_line(fr)
    assert "Wf = 29.04 +/- 0.52 kg/s" in line and "batch means of 10 batches" in line and "29044" not in line
    small = {**fr, "rate": 0.03615, "stderr": 0.00113, "fit_stderr": 0.00009}
    assert "Wf = 36.1 +/- 1.1 g/s" in flow_rate_line(small)
    assert "not resolved" in flow_rate_line({**small, "stderr": float("nan"), "batches": 0})
    steady = {"t_start": 0.76, "t_end": 1.43, "n_samples": 130, "median_rate": 0.03832, "resolved": True}
    assert "+2.0 standard errors" not in steady_window_line(steady, small)
    drift = steady_window_line(steady, {**small, "stderr": 0.0005})
    assert "differs from Wf by +4.3 standard errors" in drift and "median rate" not in steady_window_line(
        {**steady, "median_rate": 0.0362}, small)


# ------------------------------------------------------------------ a discharge that clogged
def _discharge(t_stop: float, duration: float = 1.0, rate: float = 0.02, initial: float = 0.05, n: int = 201):
    """A discharge at ``rate`` kg/s from ``initial`` kg that stops at ``t_stop`` s (or empties)."""
    t = np.linspace(0.0, duration, n)
    out = np.minimum(rate * np.minimum(t, t_stop), initial)
    return t, out, initial - out


def test_a_discharge_that_stopped_with_grains_left_clogged():
    from postprocess.discharge import clog
    t, out, left = _discharge(t_stop=0.3)
    c = clog(t, out, left, initial_mass=0.05)
    assert c is not None and c["t_last_outflow_s"] == pytest.approx(0.3, abs=0.006)
    assert c["discharged_mass_kg"] == pytest.approx(0.006)
    # one that flows to the end, one that emptied and one that stopped inside the last 40 % did not
    assert clog(*_discharge(t_stop=2.0), initial_mass=0.05) is None
    assert clog(*_discharge(t_stop=2.0, rate=0.1), initial_mass=0.05) is None        # empty at 0.5 s
    assert clog(*_discharge(t_stop=0.7), initial_mass=0.05) is None
    assert clog(*_discharge(t_stop=0.55), initial_mass=0.05) is not None
    # a flat bottom's dead zone (under a fifth of the bed) left when the flow stopped: emptied
    t, out, left = _discharge(t_stop=0.3)
    assert clog(t, out, left, initial_mass=5 * left[-1] + 1e-6) is None
    # a bed that clogged at once: nothing ever left
    assert clog(*_discharge(t_stop=0.0), initial_mass=0.05)["t_last_outflow_s"] == 0.0


def test_a_clogged_run_says_so_instead_of_a_steady_rate():
    from postprocess.report import flow_rate_line
    fr = {"rate": 2.7e-5, "stderr": 2.1e-5, "t_start": 0.9, "t_end": 1.9, "n_samples": 200, "r2": 0.3,
          "batches": 10, "fit_stderr": 1e-7}
    line = flow_rate_line(fr, {"t_last_outflow_s": 0.05, "discharged_mass_kg": 5e-4, "window": 0.4})
    assert "CLOGGED" in line and "steady flow rate" not in line and "0.05 s" in line
    assert "steady flow rate" in flow_rate_line(fr, None)
