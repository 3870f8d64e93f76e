"""Statistics of an accuracy-vs-speed benchmark of DEM settings ("candidates") against a reference.

Each candidate is run with several seeds. ``compare`` turns the table of finished runs (columns
``candidate``, ``seed``, ``wall_s`` in s, one float column per quantity in its SI unit, NaN for not
measured) into relative errors with confidence intervals and speed-ups; ``recommend`` picks the
fastest candidate whose 95 % error bound is inside the tolerances; ``pareto_figure`` draws them.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats


def _sample(x) -> np.ndarray:
    """The finite values of ``x`` as a float array (NaN = not measured, dropped)."""
    x = np.asarray(x, dtype=float).ravel()
    return x[~np.isnan(x)]


def _moments(x: np.ndarray) -> tuple[int, float, float]:
    """(n, mean, sample standard deviation); NaN where undefined."""
    n = len(x)
    return n, float(x.mean()) if n else math.nan, float(x.std(ddof=1)) if n > 1 else math.nan


def _t_half(parts, confidence: float) -> float:
    """Half-width of the t interval of a sum of variance components ``[(var, dof), ...]``, with
    the Welch-Satterthwaite degrees of freedom of that sum."""
    var = sum(v for v, _ in parts)
    if var == 0.0:
        return 0.0
    dof = var ** 2 / sum(v ** 2 / d for v, d in parts if v > 0)
    return float(stats.t.ppf(0.5 + confidence / 2, dof)) * math.sqrt(var)


def _with_interval(out: dict, rel: float, half: float) -> dict:
    """``out`` with the interval ``rel +/- half`` (relative): ``ci_lo, ci_hi``, ``bound`` (the larger
    end's magnitude), ``resolved`` (the interval excludes 0) and the ``verdict`` text."""
    lo, hi = rel - half, rel + half
    resolved = bool(lo > 0 or hi < 0)
    verdict = f"{rel:+.1%} [{lo:+.1%}, {hi:+.1%}]" if resolved else "not resolved"
    return dict(out, ci_lo=lo, ci_hi=hi, bound=max(abs(lo), abs(hi)), resolved=resolved, verdict=verdict)


def difference(ref, cand, confidence: float = 0.95) -> dict:
    """Relative difference of the means, ``cand_mean / ref_mean - 1``, with a Welch t interval:
    delta method for the ratio, ``se = sqrt(se_c**2/m_r**2 + m_c**2 se_r**2/m_r**4)``, and the
    Welch-Satterthwaite dof of these two terms (Welch's dof when the means are equal). NaNs dropped.

    Parameters
    ----------
    ref, cand : array_like
        One value per run of the reference and of the candidate (any unit, the same for both).

    Returns
    -------
    dict
        ``n_ref, n_cand, ref_mean, cand_mean, ref_sd, cand_sd`` (input unit); ``rel_error, ci_lo,
        ci_hi`` (relative, 0.1 = +10 %); ``bound = max(|ci_lo|, |ci_hi|)`` (inf when undefined);
        ``resolved`` (the interval excludes 0); ``verdict`` (str).
    """
    n_r, m_r, s_r = _moments(_sample(ref))
    n_c, m_c, s_c = _moments(_sample(cand))
    out = dict(n_ref=n_r, n_cand=n_c, ref_mean=m_r, cand_mean=m_c, ref_sd=s_r, cand_sd=s_c,
               rel_error=math.nan, ci_lo=math.nan, ci_hi=math.nan, bound=math.inf, resolved=False)
    if m_r == 0.0:
        return dict(out, verdict="reference mean is zero")
    out["rel_error"] = rel = m_c / m_r - 1.0 if n_r and n_c else math.nan
    if n_r < 2 or n_c < 2:
        return dict(out, verdict="not resolved (n < 2)")
    half = _t_half([(s_c ** 2 / n_c / m_r ** 2, n_c - 1),
                    (m_c ** 2 * s_r ** 2 / n_r / m_r ** 4, n_r - 1)], confidence)
    return _with_interval(out, rel, half)


#: a quantity of a candidate pairs with the reference's by seed (common random numbers) when at least
#: this many of the candidate's values of it have a reference value of the same seed ...
MIN_PAIRS = 3
#: ... and they are at least this share of the candidate's values of it (the others are left out of
#: the paired difference: a reference run that failed costs its seed's pair, not the pairing)
MIN_PAIRED_SHARE = 0.8


def paired_difference(ref, cand, confidence: float = 0.95) -> dict:
    """Relative difference of the means, ``cand_mean / ref_mean - 1``, of runs paired by seed (the
    same seed feeds both runs the same random insertion stream: common random numbers, so what the
    fill's randomness does to both cancels in part). Ratio estimator R = mean(c) / mean(r) with the
    residuals e = c - R r: ``se = sd(e) / (sqrt(n) mean(r))``, t interval with n - 1 dof. Valid
    whatever the correlation of the pairs; narrower than Welch's when they are positively correlated.

    Parameters
    ----------
    ref, cand : array_like
        One value per seed, aligned (ref[i] and cand[i] of the same seed); a pair with a NaN is dropped.

    Returns
    -------
    dict
        As :func:`difference`, with ``n_ref = n_cand`` = the pairs and ``pair_corr`` (the pairs'
        correlation, NaN when undefined).
    """
    r, c = np.asarray(ref, dtype=float).ravel(), np.asarray(cand, dtype=float).ravel()
    if r.shape != c.shape:
        raise ValueError(f"paired samples differ in length ({r.size} and {c.size})")
    keep = ~(np.isnan(r) | np.isnan(c))
    r, c = r[keep], c[keep]
    n, m_r, s_r = _moments(r)
    _, m_c, s_c = _moments(c)
    corr = float(np.corrcoef(r, c)[0, 1]) if n > 2 and s_r > 0 and s_c > 0 else math.nan
    out = dict(n_ref=n, n_cand=n, ref_mean=m_r, cand_mean=m_c, ref_sd=s_r, cand_sd=s_c, pair_corr=corr,
               rel_error=math.nan, ci_lo=math.nan, ci_hi=math.nan, bound=math.inf, resolved=False)
    if n and m_r == 0.0:
        return dict(out, verdict="reference mean is zero")
    out["rel_error"] = rel = m_c / m_r - 1.0 if n else math.nan
    if n < 2:
        return dict(out, verdict="not resolved (n < 2)")
    ratio = m_c / m_r
    se = float(np.std(c - ratio * r, ddof=1)) / math.sqrt(n) / abs(m_r)
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * se
    return _with_interval(out, rel, half)


def speedup(ref_wall, cand_wall, confidence: float = 0.95) -> dict:
    """Speed-up ``mean(ref_wall) / mean(cand_wall)`` with an interval on the log scale:
    ``se_log = sqrt((se_r/m_r)**2 + (se_c/m_c)**2)``, t quantile with the Welch dof. A side with one
    run borrows the relative spread of the other; with one run on both sides the interval is NaN.

    Parameters
    ----------
    ref_wall, cand_wall : array_like
        Engine wall times of the reference and of the candidate runs (s); NaNs are dropped.

    Returns
    -------
    dict
        ``speedup, lo, hi`` (dimensionless; > 1: the candidate is faster).
    """
    n_r, m_r, s_r = _moments(_sample(ref_wall))
    n_c, m_c, s_c = _moments(_sample(cand_wall))
    ratio = m_r / m_c if n_r and n_c and m_c > 0 else math.nan
    if math.isnan(ratio) or (n_r < 2 and n_c < 2):
        return dict(speedup=ratio, lo=math.nan, hi=math.nan)
    cv_r, cv_c = (s_r / m_r if n_r > 1 else s_c / m_c), (s_c / m_c if n_c > 1 else s_r / m_r)
    dof_r, dof_c = (n_r - 1 if n_r > 1 else n_c - 1), (n_c - 1 if n_c > 1 else n_r - 1)
    half = _t_half([(cv_r ** 2 / n_r, dof_r), (cv_c ** 2 / n_c, dof_c)], confidence)
    return dict(speedup=ratio, lo=ratio * math.exp(-half), hi=ratio * math.exp(half))


#: ``timing_machine`` of runs that recorded no machine (taken as one, when no recorded machine ran both)
UNRECORDED = "unrecorded"


def _pairs(ref: pd.DataFrame, cand: pd.DataFrame, design: tuple = ()) -> list:
    """The seeds by which a candidate's runs can pair with the reference's: those both sides ran
    (seeds unique on both sides), when the ``design`` columns that decide what a seed makes of its
    random stream (ranks, engine, grain size) hold the same values on both sides (missing ones
    ignored); else [] (no pairing). Decided from the seeds and the design, before any value is
    looked at; :func:`compare` then pairs a quantity on them when enough of its values pair."""
    if "seed" not in cand.columns or "seed" not in ref.columns:
        return []
    rs, cs = ref["seed"], cand["seed"]
    if not (rs.is_unique and cs.is_unique):
        return []
    for col in design:
        if col in ref.columns and col in cand.columns:
            if set(ref[col].dropna().astype(str)) != set(cand[col].dropna().astype(str)):
                return []
    known = set(rs)
    return [s for s in cs if s in known]


def _timing_machine(ref: pd.DataFrame, cand: pd.DataFrame):
    """The machine whose runs time a candidate against the reference: of the recorded machines with
    runs of both, the one with the most candidate runs (speed-ups are ratios measured on one
    machine); runs that recorded none count as one machine (``UNRECORDED``) only when no recorded
    machine ran both. Returns (machine, reference walls, candidate walls); without a ``machine``
    column every run is on one machine (""); (None, empty, empty) when no machine ran both."""
    if "machine" not in cand.columns or "machine" not in ref.columns:
        return "", ref["wall_s"], cand["wall_s"]
    rm, cm = ref["machine"].fillna(UNRECORDED).astype(str), cand["machine"].fillna(UNRECORDED).astype(str)
    shared = [m for m in cm.value_counts().index if (rm == m).any()]
    shared.sort(key=lambda m: m == UNRECORDED)          # stable: recorded machines first, by count
    if not shared:
        return None, ref["wall_s"].iloc[:0], cand["wall_s"].iloc[:0]
    m = shared[0]
    return m, ref["wall_s"][rm == m], cand["wall_s"][cm == m]


def compare(runs: pd.DataFrame, reference: str, quantities: list[str], confidence: float = 0.95,
            design: tuple = ()) -> pd.DataFrame:
    """One row per (candidate, quantity): the difference from the reference and the speed-up.

    The difference is :func:`paired_difference` on the seeds both sides ran (:func:`_pairs` with the
    ``design`` columns) when the quantity's finite pairs are at least ``MIN_PAIRS`` and
    ``MIN_PAIRED_SHARE`` of the candidate's finite values of it (decided from which values exist,
    not what they are) (``method`` "paired"), else Welch's :func:`difference` ("welch"). The
    speed-up compares engine wall times on one machine (:func:`_timing_machine`, column
    ``timing_machine``; NaN when no machine ran both).

    Parameters
    ----------
    runs : pandas.DataFrame
        One row per run: ``candidate``, ``seed``, ``wall_s`` (s), the quantities (SI; NaN = not
        measured); optional ``machine`` (where it ran), ``timed`` (bool; False: the run is not a
        whole one, its wall time is left out of the speed-up and ``wall_mean_s``) and the ``design``
        columns.
    reference : str
        The candidate compared with; its own rows have rel_error 0, bound 0, speed-up 1 and
        verdict "the reference". ValueError if it has no runs.
    quantities : list of str
        Columns of ``runs`` to compare.

    Returns
    -------
    pandas.DataFrame
        Columns ``candidate, quantity``, the keys of ``difference``, ``method``, ``pair_corr``,
        ``speedup, speedup_lo, speedup_hi`` (dimensionless), ``timing_machine``, ``timed_runs``
        (reference/candidate) and ``wall_mean_s`` (s, all the candidate's timed runs); the reference first.
    """
    missing = [c for c in ["candidate", "wall_s", *quantities] if c not in runs.columns]
    if missing:
        raise ValueError(f"runs has no column(s) {missing}")
    # the runs that time a candidate: whole ones (a fill-only run times nothing)
    if "timed" in runs.columns and runs["timed"].dtype != bool:
        raise ValueError("runs' column 'timed' must be boolean (True: a whole run, timed)")
    timing = runs[runs["timed"]] if "timed" in runs.columns else runs
    groups = dict(list(runs.groupby("candidate", sort=False)))
    timed = {name: timing[timing["candidate"] == name] for name in groups}
    if reference not in groups:
        raise ValueError(f"the reference {reference!r} has no runs")
    ref = groups[reference]
    rows = []
    for name in [reference, *(c for c in groups if c != reference)]:
        grp = groups[name]
        machine, ref_wall, cand_wall = _timing_machine(timed[reference], timed[name])
        sp = (dict(speedup=1.0, lo=1.0, hi=1.0) if name == reference
              else speedup(ref_wall, cand_wall, confidence) if machine is not None
              else dict(speedup=math.nan, lo=math.nan, hi=math.nan))
        seeds = _pairs(ref, grp, design) if name != reference else []
        if seeds:
            ref_at, cand_at = ref.set_index("seed").loc[seeds], grp.set_index("seed").loc[seeds]
        for q in quantities:
            r, c = (ref_at[q].to_numpy(dtype=float), cand_at[q].to_numpy(dtype=float)) if seeds else (None, None)
            pairs = int(np.sum(~(np.isnan(r) | np.isnan(c)))) if seeds else 0
            if pairs >= max(MIN_PAIRS, MIN_PAIRED_SHARE * int(grp[q].notna().sum())):
                d = dict(paired_difference(r, c, confidence), method="paired")
            else:
                d = dict(difference(ref[q], grp[q], confidence), method="welch", pair_corr=math.nan)
            if name == reference:
                d.update(method="")
                if d["n_ref"] > 0 and d["ref_mean"] != 0:
                    d.update(rel_error=0.0, ci_lo=0.0, ci_hi=0.0, bound=0.0, resolved=False, verdict="the reference")
            rows.append(dict(candidate=name, quantity=q, **d, speedup=sp["speedup"], speedup_lo=sp["lo"],
                             speedup_hi=sp["hi"], timing_machine=machine,
                             timed_runs=f"{ref_wall.notna().sum()}/{cand_wall.notna().sum()}",
                             wall_mean_s=float(timed[name]["wall_s"].mean())))
    return pd.DataFrame(rows)


#: the largest ensemble :func:`fills_needed` looks at (fills a side)
MAX_FILLS = 100_000


def fills_needed(row, tolerance: float, confidence: float = 0.95) -> float:
    """Fills a side at which one row of :func:`compare` would be proven within ``tolerance`` (its 95 %
    bound <= ``tolerance``) if its measured error and per-run spread held: a projection for planning
    an ensemble, not a promise (both estimates move as fills are added). n counts each side's fills;
    a side that already has more keeps them.

    A paired row keeps its residual spread, ``sd = half * sqrt(n) / t(n - 1)``, and needs the smallest
    n with ``|rel_error| + t(n - 1) sd / sqrt(n) <= tolerance``; a Welch row keeps both sides' per-run
    variances. Returns n (a float, >= 2), ``inf`` when the measured error is at or beyond the
    tolerance (no ensemble proves it at that error) or more than ``MAX_FILLS`` would be needed,
    NaN for the reference's rows and rows without a spread.
    """
    rel = abs(float(row["rel_error"]))
    if row.get("verdict") == "the reference" or not math.isfinite(rel):
        return math.nan
    if rel > tolerance:
        return math.inf
    q = 0.5 + confidence / 2
    if row.get("method") == "paired":
        n0 = int(row["n_cand"])
        half0 = (float(row["ci_hi"]) - float(row["ci_lo"])) / 2
        if n0 < 2 or not math.isfinite(half0):
            return math.nan
        sd = half0 * math.sqrt(n0) / float(stats.t.ppf(q, n0 - 1))

        def half(n: int) -> float:
            return float(stats.t.ppf(q, n - 1)) * sd / math.sqrt(n)
    else:
        m_r, m_c, s_r, s_c = (float(row[k]) for k in ("ref_mean", "cand_mean", "ref_sd", "cand_sd"))
        a, b = s_c ** 2 / m_r ** 2, m_c ** 2 * s_r ** 2 / m_r ** 4
        if not (math.isfinite(a) and math.isfinite(b)):
            return math.nan
        n_c, n_r = int(row["n_cand"]), int(row["n_ref"])

        def half(n: int) -> float:          # a side that has more than n fills keeps them
            k_c, k_r = max(n, n_c), max(n, n_r)
            return _t_half([(a / k_c, k_c - 1), (b / k_r, k_r - 1)], confidence)
    if rel + half(MAX_FILLS) > tolerance:
        return math.inf
    lo, hi = 2, MAX_FILLS          # half(n) falls with n: the smallest n that fits, by bisection
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if rel + half(mid) <= tolerance else (mid + 1, hi)
    return float(lo)


def recommend(table: pd.DataFrame, tolerances: dict[str, float]) -> dict | None:
    """The fastest candidate whose 95 % error bound is within the tolerance for every quantity.

    Parameters
    ----------
    table : pandas.DataFrame
        Output of ``compare``.
    tolerances : dict
        ``{quantity: tolerance}``, relative (0.05 = 5 %); a quantity without a row or runs
        for a candidate disqualifies it.

    Returns
    -------
    dict or None
        ``candidate, speedup, speedup_lo, speedup_hi``, ``bounds``, ``rel_errors`` and
        ``tolerances`` (per quantity, relative); None when no candidate qualifies.
    """
    ok = []
    for name, grp in table.groupby("candidate", sort=False):
        by_q = grp.set_index("quantity")
        if all(q in by_q.index and by_q.at[q, "bound"] <= tol for q, tol in tolerances.items()):
            ok.append((name, grp.iloc[0], by_q))
    if not ok:
        return None
    name, row, by_q = max(ok, key=lambda c: np.nan_to_num(c[1]["speedup"], nan=-np.inf))  # first of ties
    return dict(candidate=name, speedup=float(row["speedup"]), speedup_lo=float(row["speedup_lo"]),
                speedup_hi=float(row["speedup_hi"]),
                bounds={q: float(by_q.at[q, "bound"]) for q in tolerances},
                rel_errors={q: float(by_q.at[q, "rel_error"]) for q in tolerances},
                tolerances={q: float(t) for q, t in tolerances.items()})


def best_bounds(table: pd.DataFrame, quantity: str) -> pd.DataFrame:
    """For one quantity, the candidates sorted by speed-up (fastest first) with their relative
    error, interval and 95 % bound (relative) and verdict."""
    rows = table[table["quantity"] == quantity]
    if rows.empty:
        raise ValueError(f"no rows for quantity {quantity!r}")
    cols = ["candidate", "speedup", "speedup_lo", "speedup_hi", "rel_error", "ci_lo", "ci_hi", "bound", "verdict"]
    return rows[cols].sort_values("speedup", ascending=False, kind="stable").reset_index(drop=True)


def pareto_figure(table: pd.DataFrame, path, tolerances: dict | None = None, highlight: str | None = None,
                  notes: dict[str, str] | None = None) -> None:
    """Relative error (%) against speed-up over the reference (log axis), one panel per quantity:
    error bars are the intervals, filled markers resolved differences, the shaded band +/- the
    relative tolerance where given. Each candidate is a number (fastest last), keyed beside the
    panels with its ``notes`` (candidate: text); ``highlight`` (the recommended profile) is a red
    star. Written atomically to ``path`` (format from the suffix)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure          # no pyplot: no global figure state
    from matplotlib.ticker import LogFormatter

    tolerances = tolerances or {}
    path = Path(path)
    quantities = list(dict.fromkeys(table["quantity"]))
    fastest = table.groupby("candidate", sort=False)["speedup"].max().fillna(np.inf).sort_values(kind="stable")
    number = {name: k + 1 for k, name in enumerate(fastest.index)}
    ncols = min(3, max(1, len(quantities)))
    nrows = max(1, -(-len(quantities) // ncols))
    key_cols = 1 + len(number) // 24
    spare = nrows * ncols > len(quantities)          # an empty panel holds the key, else a margin does
    margin = 0.0 if spare else 2.2 * key_cols
    fig = Figure(figsize=(4.8 * ncols + margin, 3.8 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, q in zip(axes, quantities):
        rows = table[(table["quantity"] == q) & table["rel_error"].notna() & table["speedup"].notna()]
        if q in tolerances:
            ax.axhspan(-100 * tolerances[q], 100 * tolerances[q], color="tab:green", alpha=0.15, lw=0)
        ax.axhline(0.0, color="k", lw=0.6)
        for r in rows.itertuples():
            x, y = r.speedup, 100 * r.rel_error
            xerr = [[np.nan_to_num(x - r.speedup_lo)], [np.nan_to_num(r.speedup_hi - x)]]
            yerr = [[np.nan_to_num(y - 100 * r.ci_lo)], [np.nan_to_num(100 * r.ci_hi - y)]]
            star = r.candidate == highlight
            colour = "tab:red" if star else "tab:blue"
            ax.errorbar(x, y, xerr=xerr, yerr=yerr, fmt="*" if star else "o", color=colour, capsize=2,
                        lw=0.8, ms=10 if star else 5, mfc=colour if r.resolved else "none", zorder=3 if star else 2)
            ax.annotate(str(number[r.candidate]), (x, y), xytext=(3, 2), textcoords="offset points", fontsize=6,
                        color=colour)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(LogFormatter(labelOnlyBase=False))   # 2, not 2x10^0
        ax.xaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
        ax.set(title=q, xlabel="speed-up over the reference", ylabel="relative error (%)")
    for ax in axes[len(quantities):]:
        ax.set_visible(False)
    notes = notes or {}
    lines = [f"{k:>2}  {name}" + ("  (recommended)" if name == highlight else "")
             + (f"  {notes[name]}" if name in notes else "") for name, k in number.items()]
    lines += ["", "open: not resolved, filled: resolved", "bars: 95 % intervals"]
    per_col = -(-len(lines) // key_cols)
    keys = ["\n".join(lines[c * per_col:(c + 1) * per_col]) for c in range(key_cols)]
    if spare:                       # the key's left edge, top and column width, in figure fractions
        fig.tight_layout()
        box = axes[len(quantities)].get_position()
        x0, top, width = box.x0, box.y1, box.width / key_cols
    else:
        right = 1 - margin / fig.get_figwidth()
        fig.tight_layout(rect=(0, 0, right, 1))
        x0, top, width = right + 0.01, 0.97, 2.2 / fig.get_figwidth()
    for c, text in enumerate(keys):
        fig.text(x0 + c * width, top, text, va="top", ha="left", fontsize=6.5, family="monospace")
    from postprocess.report.figures import save_figure
    save_figure(fig, path)
