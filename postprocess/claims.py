"""Verdicts on a paper's claims, computed from measured numbers and their uncertainties (issue 38).

A claim's verdict is never typed: it comes from an :class:`Estimate` (a value, its standard error
and the degrees of freedom of that error) by one of the functions below, at a stated confidence:

- ``"holds"``: the claim is true over the whole confidence interval;
- ``"fails"``: it is false over the whole interval;
- ``"not resolved"``: the interval holds values for which it is true and values for which it is false.

The functions take numbers, not run folders, so that the report layer can call them on whatever a
run measured and tests can feed them numbers that must hold, fail and stay unresolved. Claims
checked at several points at once (a monotonic profile, a collapse of curves) use Bonferroni's
correction, so that the whole claim, not each point, is held to the confidence.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Literal, Sequence

import numpy as np
from scipy import stats

HOLDS, FAILS, NOT_RESOLVED = "holds", "fails", "not resolved"
#: the verdict of a report row that shows a figure or a number the paper states no test for
SHOWN = "shown"
Verdict = Literal["holds", "fails", "not resolved"]
#: the confidence of every verdict unless told otherwise
CONFIDENCE = 0.95


@dataclass(frozen=True)
class Estimate:
    """A measured number: ``value``, its standard error ``stderr`` (same unit) and the degrees of
    freedom of that error (``inf``: known, or from a large sample; n - 1 for the mean of n seeds)."""

    value: float
    stderr: float = 0.0
    dof: float = math.inf

    def __post_init__(self):
        if not (math.isfinite(self.value) and math.isfinite(self.stderr)) or self.stderr < 0 or not self.dof > 0:
            raise ValueError(f"an estimate needs a finite value and a finite stderr >= 0, dof > 0: {self}")

    @classmethod
    def of_samples(cls, samples: Iterable[float]) -> "Estimate":
        """The mean of independent samples (seeds), its standard error sd / sqrt(n), dof n - 1."""
        x = np.asarray(list(samples), dtype=float)
        if x.size < 2 or not np.isfinite(x).all():
            raise ValueError(f"the mean's error needs at least 2 finite samples, not {x.tolist()}")
        return cls(float(x.mean()), float(x.std(ddof=1) / math.sqrt(x.size)), float(x.size - 1))

    def interval(self, confidence: float = CONFIDENCE) -> tuple[float, float]:
        """The two-sided ``confidence`` interval (Student's t with ``dof``; normal when infinite)."""
        q = 0.5 + confidence / 2
        half = (stats.norm.ppf(q) if math.isinf(self.dof) else stats.t.ppf(q, self.dof)) * self.stderr
        return self.value - half, self.value + half

    def minus(self, other: "Estimate") -> "Estimate":
        """self - other, independent: errors in quadrature, Welch-Satterthwaite's dof."""
        return Estimate(self.value - other.value, math.hypot(self.stderr, other.stderr),
                        _welch_dof([(self.stderr, self.dof), (other.stderr, other.dof)]))

    def over(self, other: "Estimate") -> "Estimate":
        """self / other, independent (delta method: relative errors in quadrature)."""
        if other.value == 0:
            raise ValueError("ratio to an estimate of zero")
        parts = [(self.stderr / abs(other.value), self.dof),
                 (abs(self.value) * other.stderr / other.value ** 2, other.dof)]
        return Estimate(self.value / other.value, math.hypot(parts[0][0], parts[1][0]), _welch_dof(parts))


    def scaled(self, factor: float) -> "Estimate":
        """factor x self (an exact factor: a unit or a scale)."""
        return Estimate(factor * self.value, abs(factor) * self.stderr, self.dof)


def weighted_sum(estimates: Sequence[Estimate], weights: Sequence[float], constant: float = 0.0) -> Estimate:
    """constant + sum w_k x_k of independent estimates: errors in quadrature, Welch-Satterthwaite's dof."""
    if len(estimates) != len(weights) or not estimates:
        raise ValueError("one weight per estimate, at least one")
    parts = [(abs(w) * e.stderr, e.dof) for e, w in zip(estimates, weights)]
    return Estimate(constant + sum(w * e.value for e, w in zip(estimates, weights)),
                    math.sqrt(sum(s ** 2 for s, _ in parts)), _welch_dof(parts))


def _welch_dof(parts: Sequence[tuple[float, float]]) -> float:
    """Welch-Satterthwaite degrees of freedom of a sum of independent errors ``(stderr, dof)``."""
    num = sum(s ** 2 for s, _ in parts) ** 2
    den = sum(s ** 4 / d for s, d in parts if s > 0 and math.isfinite(d))
    if num == 0:
        return math.inf
    return num / den if den > 0 else math.inf


def _side(lo: float, hi: float, ok_lo: float, ok_hi: float) -> Verdict:
    """Holds when [lo, hi] lies inside [ok_lo, ok_hi], fails when it misses it, else not resolved."""
    if ok_lo <= lo and hi <= ok_hi:
        return HOLDS
    if hi < ok_lo or lo > ok_hi:
        return FAILS
    return NOT_RESOLVED


def within(estimate: Estimate, target: float, tolerance: float, relative: bool = False,
           confidence: float = CONFIDENCE) -> Verdict:
    """Claim "the value is ``target`` within ``tolerance``" (absolute, or a fraction of |target| when
    ``relative``)."""
    tol = tolerance * abs(target) if relative else tolerance
    if tol < 0:
        raise ValueError("a tolerance is >= 0")
    lo, hi = estimate.interval(confidence)
    return _side(lo, hi, target - tol, target + tol)


def greater(a: Estimate, b: Estimate, confidence: float = CONFIDENCE) -> Verdict:
    """Claim "a > b" (independent estimates): on the interval of a - b."""
    lo, hi = a.minus(b).interval(confidence)
    return HOLDS if lo > 0 else FAILS if hi < 0 else NOT_RESOLVED


def ratio_about(a: Estimate, b: Estimate, target: float, tolerance: float,
                confidence: float = CONFIDENCE) -> Verdict:
    """Claim "a / b is about ``target``" (e.g. twice the contacts: target 2), within a relative
    ``tolerance`` of the target."""
    return within(a.over(b), target, tolerance, relative=True, confidence=confidence)


def monotonic(values: Sequence[Estimate], increasing: bool, confidence: float = CONFIDENCE) -> Verdict:
    """Claim "the profile changes monotonically" in the given direction along ``values`` (ordered in
    the position): holds when the change from first to last is resolved in that direction and no
    step is resolved against it; fails when the overall change or a step is resolved against it;
    else not resolved. The steps and the overall change are tested at Bonferroni's level."""
    if len(values) < 2:
        raise ValueError("a profile needs at least two points")
    sign = 1.0 if increasing else -1.0
    tests = [values[k + 1].minus(values[k]) for k in range(len(values) - 1)] + [values[-1].minus(values[0])]
    level = 1 - (1 - confidence) / len(tests)
    # in the claimed direction: a change d becomes sign * d, claimed > 0
    intervals = [sorted((sign * lo, sign * hi)) for lo, hi in (t.interval(level) for t in tests)]
    if any(hi < 0 for _, hi in intervals):
        return FAILS
    return HOLDS if intervals[-1][0] > 0 else NOT_RESOLVED


def follows(curve: Sequence[Estimate], model: Sequence[float], tolerance: float,
            confidence: float = CONFIDENCE) -> Verdict:
    """Claim "the measured curve follows the model" point by point (e.g. v_z(r)/v_z(0) against
    sqrt(1 - (r/R)^2)): every point within ``tolerance`` (absolute) of the model holds; any point
    resolved outside fails (Bonferroni over the points)."""
    if len(curve) != len(model) or not curve:
        raise ValueError("one model value per measured point")
    level = 1 - (1 - confidence) / len(curve)
    return _combine([within(p, m, tolerance, confidence=level) for p, m in zip(curve, model)])


def collapse(curves: Sequence[Sequence[Estimate]], tolerance: float, confidence: float = CONFIDENCE) -> Verdict:
    """Claim "the curves collapse" (the same dimensionless profile measured for several apertures on
    one grid of x): every pair of curves agrees within ``tolerance`` (absolute) at every point
    (Bonferroni over pairs and points)."""
    if len(curves) < 2 or len({len(c) for c in curves}) != 1:
        raise ValueError("at least two curves on one grid")
    pairs = [(i, j) for i in range(len(curves)) for j in range(i + 1, len(curves))]
    level = 1 - (1 - confidence) / (len(pairs) * len(curves[0]))
    return _combine([within(curves[i][k].minus(curves[j][k]), 0.0, tolerance, confidence=level)
                     for i, j in pairs for k in range(len(curves[0]))])


def _combine(verdicts: Sequence[Verdict]) -> Verdict:
    """A claim made of parts: fails if any part fails, holds if all hold, else not resolved."""
    if FAILS in verdicts:
        return FAILS
    return HOLDS if all(v == HOLDS for v in verdicts) else NOT_RESOLVED


def all_of(verdicts: Sequence[Verdict]) -> Verdict:
    """A claim made of parts (the same claim at several apertures, say): fails if any part
    fails, holds if every part holds, else not resolved. The parts should be computed at
    Bonferroni's level, ``bonferroni(n)``, so that the whole claim keeps the confidence."""
    verdicts = list(verdicts)
    if not verdicts or any(v not in (HOLDS, FAILS, NOT_RESOLVED) for v in verdicts):
        raise ValueError(f"verdicts to combine: {verdicts}")
    return _combine(verdicts)


def bonferroni(parts: int, confidence: float = CONFIDENCE) -> float:
    """The confidence of each of ``parts`` tests whose joint claim is held to ``confidence``."""
    if parts < 1:
        raise ValueError("at least one part")
    return 1 - (1 - confidence) / parts


def pooled_mean(estimates: Sequence[Estimate]) -> Estimate:
    """The plain mean of independent estimates (e.g. one per aperture): errors in quadrature
    over n, Welch-Satterthwaite's dof."""
    if not estimates:
        raise ValueError("nothing to pool")
    n = len(estimates)
    parts = [(e.stderr / n, e.dof) for e in estimates]
    return Estimate(sum(e.value for e in estimates) / n, math.sqrt(sum(s * s for s, _ in parts)),
                    _welch_dof(parts))


@dataclass(frozen=True)
class ClaimRow:
    """One row of a claims report (papers A and B): the claim, the paper's statement or number,
    ours and its uncertainty (as a reader reads them), the computed verdict (:data:`HOLDS`,
    :data:`FAILS`, :data:`NOT_RESOLVED`, or ``"shown"`` for a figure-only row that states no
    testable number) and a note (how it was measured, the tolerance, the test)."""

    claim: str
    paper: str
    ours: str
    uncertainty: str
    verdict: str
    note: str = ""


def power_law_exponent(x: Sequence[float], y: Sequence[Estimate]) -> Estimate:
    """The exponent b of y = a x^b (e.g. v_z(0) against R, claimed 1/2), by weighted least squares
    on log y against log x, each point weighted by its relative error's inverse square. Its standard
    error is the one the points' errors give, scaled up by the Birge ratio sqrt(chi^2 / (n - 2))
    when the points scatter more than their errors say (then with n - 2 dof)."""
    lx = np.log(np.asarray(x, float))
    ly = np.log([p.value for p in y])
    sl = np.array([p.stderr / abs(p.value) for p in y])
    if lx.size < 2 or lx.size != ly.size or np.any(sl <= 0):
        raise ValueError("an exponent needs two or more points, each with an error")
    w = 1 / sl ** 2
    xm, ym = np.sum(w * lx) / np.sum(w), np.sum(w * ly) / np.sum(w)
    sxx = np.sum(w * (lx - xm) ** 2)
    b = np.sum(w * (lx - xm) * (ly - ym)) / sxx
    se, dof = 1 / math.sqrt(sxx), math.inf
    if lx.size > 2:
        birge2 = float(np.sum(w * (ly - ym - b * (lx - xm)) ** 2)) / (lx.size - 2)
        if birge2 > 1:
            se, dof = se * math.sqrt(birge2), float(lx.size - 2)
    return Estimate(float(b), float(se), dof)
