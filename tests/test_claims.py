"""Verdict functions of the papers' claims (postprocess.claims, issue 38): each is fed numbers
that must hold, fail and stay unresolved, and the statistics behind them are checked against
closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from postprocess.claims import (
    FAILS,
    HOLDS,
    NOT_RESOLVED,
    Estimate,
    collapse,
    follows,
    greater,
    monotonic,
    power_law_exponent,
    ratio_about,
    within,
)


def test_estimate_intervals_are_student_and_normal():
    e = Estimate(10.0, 1.0, 4)
    lo, hi = e.interval()
    assert hi - 10 == pytest.approx(stats.t.ppf(0.975, 4)) and 10 - lo == pytest.approx(2.776445, rel=1e-6)
    assert Estimate(10.0, 1.0).interval()[1] == pytest.approx(11.959964, rel=1e-7)
    s = Estimate.of_samples([1.0, 2.0, 3.0, 4.0])
    assert (s.value, s.stderr, s.dof) == pytest.approx((2.5, np.std([1, 2, 3, 4], ddof=1) / 2, 3))
    with pytest.raises(ValueError):
        Estimate.of_samples([1.0])
    with pytest.raises(ValueError):
        Estimate(float("nan"), 1.0)


def test_differences_and_ratios_propagate_errors():
    a, b = Estimate(10.0, 3.0, 4), Estimate(4.0, 4.0, 9)
    d = a.minus(b)
    assert (d.value, d.stderr) == pytest.approx((6.0, 5.0))
    # Welch-Satterthwaite: (9 + 16)^2 / (81/4 + 256/9)
    assert d.dof == pytest.approx(625 / (81 / 4 + 256 / 9))
    r = Estimate(6.0, 0.3).over(Estimate(3.0, 0.3))
    assert r.value == 2.0 and r.stderr == pytest.approx(2.0 * math.hypot(0.05, 0.1))


@pytest.mark.parametrize("estimate, verdict", [
    (Estimate(40.0, 0.2), HOLDS),          # 39.6-40.4 inside 39-41
    (Estimate(44.0, 0.5), FAILS),          # 43-45 outside
    (Estimate(40.8, 0.5), NOT_RESOLVED),   # 39.8-41.8 straddles 41
])
def test_within(estimate, verdict):
    assert within(estimate, 40.0, 1.0) == verdict
    assert within(estimate, 40.0, 0.025, relative=True) == verdict


@pytest.mark.parametrize("a, b, verdict", [
    (Estimate(31.4, 0.3), Estimate(29.1, 0.3), HOLDS),
    (Estimate(29.0, 0.3), Estimate(31.0, 0.3), FAILS),
    (Estimate(29.5, 1.0), Estimate(29.1, 1.0), NOT_RESOLVED),
])
def test_greater(a, b, verdict):
    assert greater(a, b) == verdict


@pytest.mark.parametrize("contacts, verdict", [
    (Estimate(61403.0, 300.0), HOLDS),     # 1.96 x 31279: about twice
    (Estimate(40000.0, 300.0), FAILS),     # 1.28 x
    (Estimate(50000.0, 8000.0), NOT_RESOLVED),
])
def test_ratio_about(contacts, verdict):
    assert ratio_about(contacts, Estimate(31279.0, 200.0), 2.0, 0.25) == verdict


def test_monotonic():
    down = [Estimate(v, 0.1) for v in (10.0, 8.0, 6.0, 4.0)]
    assert monotonic(down, increasing=False) == HOLDS
    assert monotonic(down[::-1], increasing=True) == HOLDS
    assert monotonic(down, increasing=True) == FAILS
    bump = [Estimate(v, 0.1) for v in (10.0, 8.0, 9.0, 4.0)]       # a resolved step up: fails
    assert monotonic(bump, increasing=False) == FAILS
    noisy = [Estimate(v, 1.0) for v in (10.0, 9.8, 9.9, 9.6)]      # within its noise: not resolved
    assert monotonic(noisy, increasing=False) == NOT_RESOLVED


def test_follows_the_outlet_profile():
    r = np.linspace(0.0, 0.9, 7)
    model = np.sqrt(1 - r ** 2)
    assert follows([Estimate(m + 0.005, 0.005) for m in model], model, 0.05) == HOLDS
    assert follows([Estimate(m if k != 3 else m + 0.2, 0.005) for k, m in enumerate(model)], model, 0.05) == FAILS
    assert follows([Estimate(m, 0.05) for m in model], model, 0.05) == NOT_RESOLVED


def test_collapse():
    x = np.linspace(0, 1, 5)
    base = 1 - x ** 2
    same = [[Estimate(v + dv, 0.005) for v in base] for dv in (0.0, 0.01, -0.01)]
    assert collapse(same, 0.05) == HOLDS
    apart = [[Estimate(v * s, 0.005) for v in base] for s in (1.0, 1.3)]
    assert collapse(apart, 0.05) == FAILS
    wide = [[Estimate(v + dv, 0.05) for v in base] for dv in (0.0, 0.02)]
    assert collapse(wide, 0.05) == NOT_RESOLVED


def test_power_law_exponent():
    R = np.array([8.0, 10.0, 12.0, 16.0])
    exact = [Estimate(2.0 * r ** 0.5, 0.01 * 2.0 * r ** 0.5) for r in R]
    b = power_law_exponent(R, exact)
    assert b.value == pytest.approx(0.5, abs=1e-12) and math.isinf(b.dof)
    assert within(b, 0.5, 0.1) == HOLDS and within(b, 1.0, 0.1) == FAILS
    # points scattered beyond their errors: the Birge ratio widens the error, with n - 2 dof
    scattered = [Estimate(2.0 * r ** 0.5 * f, 0.001 * 2.0 * r ** 0.5) for r, f in zip(R, (1.05, 0.95, 1.05, 0.95))]
    s = power_law_exponent(R, scattered)
    unscaled = 0.001 / math.sqrt(np.sum((np.log(R) - np.log(R).mean()) ** 2))    # what the errors alone give
    assert s.dof == 2 and s.stderr > 10 * unscaled and within(s, 0.5, 0.1) != FAILS


def test_all_of_bonferroni_and_pooled_mean():
    from postprocess.claims import all_of, bonferroni, pooled_mean

    assert all_of([HOLDS, HOLDS]) == HOLDS
    assert all_of([HOLDS, NOT_RESOLVED]) == NOT_RESOLVED
    assert all_of([NOT_RESOLVED, FAILS, HOLDS]) == FAILS
    with pytest.raises(ValueError):
        all_of([])
    with pytest.raises(ValueError):
        all_of(["maybe"])
    assert bonferroni(1) == pytest.approx(0.95) and bonferroni(5) == pytest.approx(0.99)
    # three apertures each at 0.60 +/- 0.003: the pooled mean holds 0.60 +/- 0.02; at 0.65 it fails;
    # with errors of 0.03 it is not resolved
    p = pooled_mean([Estimate(0.59, 0.003, 4), Estimate(0.60, 0.003, 4), Estimate(0.61, 0.003, 4)])
    assert p.value == pytest.approx(0.60) and p.stderr == pytest.approx(0.003 / math.sqrt(3))
    assert p.dof == pytest.approx(12.0)
    assert within(p, 0.60, 0.02) == HOLDS
    assert within(pooled_mean([Estimate(0.65, 0.003, 4)] * 3), 0.60, 0.02) == FAILS
    assert within(pooled_mean([Estimate(0.61, 0.03, 4)] * 3), 0.60, 0.02) == NOT_RESOLVED
