"""The page of a sweep and of several runs (issue 60): ``report.html`` of ``siloflow sweep``
(:func:`sweep_report`) and the page beside ``siloflow beverloo``'s table (:func:`beverloo_report`).

A page holds the runs' table with a link to each run's own page (``results/report.html``),
Beverloo's fit with its data and its 95 % band (:func:`beverloo_figure`), and the flow rate and
wall loads against each swept value (:func:`swept_figures`). It is the report's blocks
(``report.text``) rendered by ``html_page.report_html`` (self-contained: inline style, no script,
only ``data:`` images); its only other URLs are the :class:`~postprocess.report.text.Link` cells,
relative links to the runs' ``results/report.html``. Numbers are SI here; g/s, mm and kPa only on
the page.
"""
from __future__ import annotations

import io
import math
import os
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pandas as pd

from siloflow.errors import ReadError, SiloflowError
from siloflow.run_folder import RESULTS, RunFolder

from ..flow_rate import BeverlooFit, as_number, flow_verdict
from ..flow_rate import beverloo as beverloo_law
from ..numbers import MASS_RATE_UNITS, PRESSURE_UNITS, unit_for, with_error
from .figures import plt
from .html_page import report_html
from .run import REPORT_HTML
from .text import Heading, Items, Link, Table, Text, Title

#: the sweep's table in its folder, and the figure of Beverloo's fit
SWEEP_TABLE, BEVERLOO_PNG = "sweep.csv", "beverloo.png"
#: the confidence level of the fit's band
LEVEL = 0.95
#: the figures' resolution (dots per inch)
DPI = 110
#: a list of the swept values shows at most this many
SHOWN_VALUES = 8


# ---------------------------------------------------------------- a run's numbers and page

def run_numbers(summary: dict) -> dict:
    """What the pages take from a run's summary (SI, NaN where it holds none): ``rate`` and
    ``rate_stderr`` (steady flow rate, kg/s), ``unsteady`` (why the rate is no steady one, ''
    when it is: ``flow_rate.flow_verdict``), ``clogged`` (True, False, None if unknown),
    ``static`` and ``static_stderr`` (the largest static band pressure, Pa) and ``dynamic`` (the
    largest band's ``max_dynamic_pressure``, Pa)."""
    fr = summary.get("flow_rate") if isinstance(summary.get("flow_rate"), dict) else {}
    verdict = flow_verdict(summary)
    bands = [b for b in summary.get("bands") or [] if isinstance(b, dict)]
    static = [(as_number(b.get("static_pressure")), as_number(b.get("static_pressure_stderr"))) for b in bands]
    static = [s for s in static if math.isfinite(s[0])]
    top = max(static, key=lambda s: s[0]) if static else (math.nan, math.nan)
    dynamic = [p for p in (as_number(b.get("max_dynamic_pressure")) for b in bands) if math.isfinite(p)]
    return {"rate": as_number(fr.get("rate")), "rate_stderr": as_number(fr.get("stderr")), "unsteady": verdict["unsteady"],
            "clogged": verdict["clogged"], "static": top[0], "static_stderr": top[1],
            "dynamic": max(dynamic) if dynamic else math.nan}


def run_page_href(run_folder, page_folder) -> str | None:
    """The URL of a run's page (``results/report.html``) relative to ``page_folder``, the folder
    the page linking to it is written in; None when the run has none."""
    page = Path(run_folder).absolute() / RESULTS / REPORT_HTML
    if not page.is_file():
        return None
    return quote(Path(os.path.relpath(page, Path(page_folder).absolute())).as_posix())


def png_bytes(fig) -> bytes:
    """A figure as PNG bytes; the figure is closed."""
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=DPI)
    finally:
        plt.close(fig)
    return buf.getvalue()


def _page(blocks: list, name: str, title: str, tables: dict, figures: dict) -> str:
    """``report_html``'s page of ``blocks``, the figures' PNG (``figures``: file name -> Figure,
    closed here) and the CSV ``tables`` (beside the page)."""
    pngs = {}
    try:
        for fname, fig in figures.items():
            pngs[fname] = png_bytes(fig)
    finally:
        for fname, fig in figures.items():
            if fname not in pngs:
                plt.close(fig)
    return report_html(blocks, name, tables, pngs, title=title, tables_where="beside this page")


def _value_text(value) -> str:
    """A swept value as the page shows it: numbers with :g, NaN (a ``null`` in --set) as null."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if isinstance(value, (int, float, np.integer, np.floating)):
        return "null" if value != value else f"{value:g}"
    return str(value)


def _units(values, units) -> tuple[str, float]:
    """The unit (name, size) of ``units`` for the largest finite of ``values``."""
    finite = [abs(float(v)) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    return unit_for(max(finite) if finite else math.nan, units)


def _cell(value, error, size: float) -> str:
    """``value +/- error`` in a unit of ``size``, '-' without a value."""
    if not (isinstance(value, (int, float)) and math.isfinite(value)):
        return "-"
    return with_error(value / size, error / size if math.isfinite(error) else error)


def _plain(value, size: float) -> str:
    """``value`` in a unit of ``size`` to 4 significant figures, '-' without a value."""
    return f"{value / size:.4g}" if isinstance(value, (int, float)) and math.isfinite(value) else "-"


# ---------------------------------------------------------------- Beverloo's fit

def _slots(table: pd.DataFrame) -> bool:
    used = table[table.left_out == ""]
    return bool(len(used)) and bool(used.L.notna().all())


def law_text(slots: bool) -> str:
    """Beverloo's law as the page writes it."""
    return ("W = C rho_b sqrt(g) L (D0 - k d)^(3/2) (slots of width D0, length L)" if slots
            else "W = C rho_b sqrt(g) (D0 - k d)^(5/2)")


def band_multiplier(fit: BeverlooFit, level: float = LEVEL) -> float:
    """The multiplier of a standard error at ``level`` (two-sided): the normal law's when the fit's
    covariance comes from the runs' own errors (``fit.errors_given``), else Student's t with the fit's
    n - 2 degrees of freedom (C and k fitted; its covariance scaled by the residuals); NaN for a fit of
    2 runs or fewer."""
    from scipy import stats
    if fit.n_runs <= 2:
        return math.nan
    q = 0.5 + level / 2
    return float(stats.norm.ppf(q) if fit.errors_given else stats.t.ppf(q, fit.n_runs - 2))


def law_stderr(law, fit: BeverlooFit) -> np.ndarray:
    """The standard error of ``law(C, k)`` (an array over D0/d) at the fitted C and k, from their
    standard errors and covariance by the delta method: J Sigma J^T, J the law's derivatives in C
    (the law is proportional to C) and in k (central difference)."""
    w = np.asarray(law(fit.C, fit.k), float)
    h = 1e-6 * max(abs(fit.k), 1.0)
    dk = (np.asarray(law(fit.C, fit.k + h), float) - np.asarray(law(fit.C, fit.k - h), float)) / (2 * h)
    dc = w / fit.C if fit.C else np.zeros_like(w)
    var = dc ** 2 * fit.C_stderr ** 2 + 2 * dc * dk * fit.C_k_covariance + dk ** 2 * fit.k_stderr ** 2
    return np.sqrt(np.clip(var, 0.0, None))


def _band_resolved(fit: BeverlooFit, level: float) -> bool:
    return all(math.isfinite(v) for v in (band_multiplier(fit, level), fit.C_stderr, fit.k_stderr,
                                           fit.C_k_covariance))


def _reference(table: pd.DataFrame) -> dict:
    """The grains, bulk density and slot the law is drawn for: the fitted runs' medians."""
    used = table[table.left_out == ""]
    slots = _slots(table)
    return {"d": float(used.d.median()), "rho_b": float(used.rho_b.median()),
            "L": float(used.L.median()) if slots else None, "ends": bool(used.L_ends.iloc[0]) if slots else False}


def reference_scale(table: pd.DataFrame, fit: BeverlooFit, g: float) -> np.ndarray:
    """Each run's factor onto the curve's grains, bulk density and slot (:func:`_reference`): the
    law's W at the run's D0/d with the reference's d, rho_b and L over the law's W with the run's own
    (1 where the law gives none). At a given D0/d the law scales W by rho_b d^(5/2) (a slot's
    rho_b L d^(3/2)), whatever C, so a run of other grains sits on the curve once scaled."""
    ref = _reference(table)
    x = (table.D0 / table.d).to_numpy(float)
    own = beverloo_law(table.D0, table.d, 1.0, fit.k, table.rho_b, g,
                       table.L.to_numpy(float) if ref["L"] is not None else None, table.L_ends)
    at_ref = beverloo_law(x * ref["d"], ref["d"], 1.0, fit.k, ref["rho_b"], g, ref["L"], ref["ends"])
    own, at_ref = np.asarray(own, float) * np.ones(len(x)), np.asarray(at_ref, float) * np.ones(len(x))
    ok = np.isfinite(own) & np.isfinite(at_ref) & (own > 0)
    return np.where(ok, at_ref / np.where(ok, own, 1.0), 1.0)


def _scaled(scale: np.ndarray) -> bool:
    return not np.allclose(scale, 1.0, rtol=1e-9, atol=0.0)


def beverloo_caption(table: pd.DataFrame, fit: BeverlooFit, g: float, level: float = LEVEL) -> str:
    """What :func:`beverloo_figure` draws, in words: its points, its curve and how its band is made."""
    ref = _reference(table)
    t = band_multiplier(fit, level)
    how = ("the normal law: the fit weighs the runs by their own batch-means errors" if fit.errors_given else
           f"Student's t with {fit.n_runs - 2} degree(s) of freedom: the fit's errors are scaled by its residuals")
    band = (f"the band: the fitted law's {level:.0%} confidence band, +/- {t:.3g} of its standard error ({how}), "
            "propagated from C and k with their covariance (delta method)"
            if _band_resolved(fit, level) else "no band: the fit's standard errors are not resolved")
    drawn = f"d = {ref['d'] * 1000:.3g} mm, rho_b = {ref['rho_b']:.4g} kg/m3"
    if ref["L"] is not None:
        drawn += f", L = {ref['L'] * 1000:.3g} mm"
    left = (table.left_out != "").sum()
    scaled = (f"; runs of other grains or bulk density scaled onto the curve's by the law's own factor at their D0/d "
              f"(rho_b d^({'3/2' if ref['L'] is not None else '5/2'}) over the curve's), as are their errors"
              if _scaled(reference_scale(table, fit, g)) else "")
    return (f"Beverloo's law {law_text(ref['L'] is not None)} fitted over {fit.n_runs} runs: each run's steady flow "
            f"rate W with +/- 2 standard errors against D0/d; the curve drawn for {drawn} (the fitted runs' medians)"
            f"{scaled}; {band}" + (f"; {left} run(s) left out of the fit as open markers, named" if left else ""))


def beverloo_figure(table: pd.DataFrame, fit: BeverlooFit, g: float, level: float = LEVEL):
    """Beverloo's fit drawn: each fitted run's steady flow rate W with +/- 2 standard errors against
    D0/d, the law with the fitted C and k, and its confidence band at ``level`` (:func:`law_stderr`,
    :func:`band_multiplier`). Runs left out of the fit (clogged, never
    steady) are open markers, named. The curve is drawn for the fitted runs' median grains, bulk
    density (and slot length); runs of others are scaled onto it (:func:`reference_scale`).
    ``table``: ``flow_rate.beverloo_table``'s rows (SI); slots (L not NaN) take the slot law.
    ``g``: gravity (m/s2). Returns the Figure."""
    scale = reference_scale(table, fit, g)
    table = table.assign(W=table.W * scale, W_stderr=table.W_stderr * scale)
    used, left = table[table.left_out == ""], table[table.left_out != ""]
    ratio = (table.D0 / table.d).astype(float)
    ref = _reference(table)
    unit, size = _units(table.W.tolist(), MASS_RATE_UNITS)
    lo, hi = float(ratio.min()), float(ratio.max())
    pad = 0.15 * (hi - lo) + 0.3
    xs = np.linspace(max(fit.k, lo - pad), hi + pad, 200)

    def law(C: float, k: float):
        return beverloo_law(xs * ref["d"], ref["d"], max(C, 0.0), k, ref["rho_b"], g, ref["L"], ref["ends"]) / size

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.plot(xs, law(fit.C, fit.k), color="C0", lw=1.5, label=f"Beverloo: C = {fit.C:.3g}, k = {fit.k:.3g}")
    if _band_resolved(fit, level):
        mid, half = law(fit.C, fit.k), band_multiplier(fit, level) * law_stderr(law, fit)
        ax.fill_between(xs, np.clip(mid - half, 0, None), mid + half, color="C0", alpha=0.2, lw=0,
                        label=f"{level:.0%} confidence band of the fit")
    errors = (2 * used.W_stderr.astype(float) / size).fillna(0.0)
    ax.errorbar(ratio[used.index], used.W / size, yerr=errors, fmt="o", color="k", ms=5, capsize=3,
                label=f"runs fitted ({len(used)}), +/- 2 SE")
    for k, (idx, row) in enumerate(left.iterrows()):
        y = row.W / size if math.isfinite(row.W) and row.W > 0 else 0.0
        why = "clogged" if "clogged" in str(row.left_out) else "unsteady"
        ax.plot([ratio[idx]], [y], "o", mfc="none", mec="C3", ms=7, label="left out (clogged, unsteady)" if k == 0
                else None)
        ax.annotate(f"{Path(str(row.run)).name}: {why}", (ratio[idx], y), textcoords="offset points",
                    xytext=(5, 5), fontsize=7, color="C3")
    at = f" at d = {ref['d'] * 1000:.3g} mm, rho_b = {ref['rho_b']:.4g} kg/m3" if _scaled(scale) else ""
    ax.set(xlabel="D0 / d (outlet width over grain diameter)", ylabel=f"steady flow rate W{at} ({unit})",
           title="Beverloo's law fitted across the runs")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def fit_blocks(table: pd.DataFrame, fit: BeverlooFit, over: str) -> list:
    """The fit's lines, after the law and what it is fitted ``over``: C and k with their standard
    errors, the runs, the residual, the runs left out with why."""
    names = {str(r): Path(str(r)).name for r in table.run}
    lines = [f"- C = {with_error(fit.C, fit.C_stderr)}, k = {with_error(fit.k, fit.k_stderr)} (+/- one standard "
             "error)",
             f"- {fit.n_runs} runs fitted; rms relative residual {fit.rms_relative_residual:.1%}"]
    lines += [f"- left out of the fit: {names[str(row.run)]}: {row.left_out}"
              for row in table[table.left_out != ""].itertuples()]
    return [Items(lines, lead=f"Beverloo's law {law_text(_slots(table))}, fitted over {over}:")]


def fit_data_table(table: pd.DataFrame, fit: BeverlooFit, g: float, page_folder) -> Table:
    """The fit's data: one row per run with its D0, d, D0/d, rho_b, W +/- SE, the fit's W and the
    residual (fitted runs), why it is left out, and a link to its page."""
    ref_slots = _slots(table)
    unit, size = _units(table.W.tolist(), MASS_RATE_UNITS)
    model = beverloo_law(table.D0, table.d, fit.C, fit.k, table.rho_b, g, table.L if ref_slots else None,
                         table.L_ends)
    header = ["run", "D0 (mm)", "d (mm)", "D0/d", *(["L (mm)"] if ref_slots else []), "rho_b (kg/m3)",
              f"W ({unit})", f"fit's W ({unit})", "residual", "left out", "page"]
    rows = []
    for row, w in zip(table.itertuples(), np.asarray(model, float)):
        fitted = row.left_out == ""
        href = run_page_href(row.run, page_folder)
        rows.append([Path(str(row.run)).name, f"{row.D0 * 1000:.4g}", f"{row.d * 1000:.4g}", f"{row.D0 / row.d:.3g}",
                     *([f"{row.L * 1000:.4g}"] if ref_slots else []), f"{row.rho_b:.4g}",
                     _cell(row.W, row.W_stderr, size), f"{w / size:.4g}" if fitted else "-",
                     f"{(row.W - w) / w:+.1%}" if fitted and w > 0 else "-", row.left_out or "-",
                     Link(REPORT_HTML, href) if href else "none"])
    return Table(header, rows)


def beverloo_report(table: pd.DataFrame, fit: BeverlooFit, g: float, page_folder, table_name: str = "beverloo.csv",
                    level: float = LEVEL) -> str:
    """The page of ``siloflow beverloo`` (written beside its table, in ``page_folder``): the fit
    (C, k, the runs, the residual, the runs left out and why), its data with a link to each run's
    page, the figure (:func:`beverloo_figure`) and the table (``table_name``). ``table``, ``fit``:
    ``siloflow.answers.beverloo``'s; ``g``: gravity (m/s2)."""
    title = f"Beverloo's law over {fit.n_runs} runs"
    blocks = [Title(title), *fit_blocks(table, fit, f"the {fit.n_runs} runs that flowed steadily")]
    blocks += [Heading("The runs"), fit_data_table(table, fit, g, page_folder),
               Text(f"{BEVERLOO_PNG}: {beverloo_caption(table, fit, g, level)}.")]
    return _page(blocks, title, title, {table_name: table},
                 {BEVERLOO_PNG: beverloo_figure(table, fit, g, level)})


# ---------------------------------------------------------------- against the swept values

def set_paths(sweep_table: pd.DataFrame) -> list[str]:
    """The ``--set`` paths of a sweep table (``sweep.csv``): its columns between ``name`` and ``seed``."""
    columns = list(sweep_table.columns)
    if "name" not in columns or "seed" not in columns:
        return []
    return columns[columns.index("name") + 1:columns.index("seed")]


def swept_fields(sweep_table: pd.DataFrame) -> list[str]:
    """The ``--set`` paths whose value varies across the sweep's runs."""
    return [p for p in set_paths(sweep_table) if sweep_table[p].map(_value_text).nunique() > 1]


def _positions(values: pd.Series) -> tuple[pd.Series, list | None]:
    """A swept field's values as x positions: the numbers themselves, else (text, booleans) 0, 1,
    ... in order of appearance with their tick labels."""
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        return values.astype(float), None
    texts = values.map(_value_text)
    order = list(dict.fromkeys(texts))
    return texts.map({t: k for k, t in enumerate(order)}).astype(float), order


def _swept_plot(data: pd.DataFrame, field: str, others: list[str]):
    """Flow rate (left) and wall loads (right) against ``field``; a line per combination of the
    ``others`` swept fields. ``data``: the sweep table's complete runs with :func:`run_numbers`'."""
    x, ticks = _positions(data[field])
    rate_unit, rate_size = _units(data.rate.tolist(), MASS_RATE_UNITS)
    p_unit, p_size = _units(data.static.tolist() + data.dynamic.tolist(), PRESSURE_UNITS)
    if others:
        labels = data[others].map(_value_text).apply(lambda r: ", ".join(f"{o} = {v}" for o, v in zip(others, r)),
                                                     axis=1)
    else:
        labels = pd.Series("", index=data.index)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, label in enumerate(dict.fromkeys(labels)):
        grp, color = data[labels == label], f"C{k % 10}"
        gx = x[grp.index]
        steady = grp.unsteady == ""
        tag = f" ({label})" if label else ""
        ax1.errorbar(gx[steady], grp.rate[steady] / rate_size, yerr=(2 * grp.rate_stderr[steady] / rate_size).fillna(0),
                     fmt="o", color=color, ms=4, capsize=3, label=f"runs, +/- 2 SE{tag}")
        if (~steady).any():
            ax1.plot(gx[~steady], grp.rate[~steady].fillna(0).clip(lower=0) / rate_size, "o", mfc="none", mec=color,
                     ms=6, label=f"clogged or unsteady{tag}")
        mean = grp.rate[steady].groupby(gx[steady]).mean()
        ax1.plot(mean.index, mean / rate_size, "-", color=color, lw=1, label=f"mean at each value{tag}")
        static_err = (2 * grp.static_stderr / p_size).fillna(0)
        ax2.errorbar(gx, grp.static / p_size, yerr=static_err, fmt="o", color=color, ms=4, capsize=3,
                     label=f"largest static band, +/- 2 SE{tag}")
        ax2.plot(gx, grp.dynamic / p_size, "s", mfc="none", mec=color, ms=5, label=f"largest max dynamic band{tag}")
        for column, style in (("static", "-"), ("dynamic", "--")):
            mean = grp[column].groupby(gx).mean()
            ax2.plot(mean.index, mean / p_size, style, color=color, lw=1)
    ax1.set(xlabel=field, ylabel=f"steady flow rate ({rate_unit})", title=f"Flow rate against {field}")
    ax2.set(xlabel=field, ylabel=f"wall pressure ({p_unit})", title=f"Wall loads against {field} (lines: means)")
    for ax in (ax1, ax2):
        if ticks is not None:
            ax.set_xticks(range(len(ticks)), ticks)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def swept_figures(sweep_table: pd.DataFrame, summaries: dict) -> dict:
    """For each swept field (:func:`swept_fields`) a figure ``vs_<field>.png``: the steady flow rate
    with +/- 2 standard errors (left), and the wall loads (right): each run's largest static band
    pressure (+/- 2 standard errors) and largest dynamic band pressure (``max_dynamic_pressure``),
    against the field's value. Runs of several seeds at one value: each run drawn, and their mean
    as a line; a run whose flow is no steady one (clogged, unsteady) is an open marker, out of the
    flow rate's mean. With other swept fields, a line per combination of their values.
    ``summaries``: run name -> its summary (runs without one are not drawn). Returns {file name:
    Figure}."""
    rows = [{"name": name, **run_numbers(summaries[name])} for name in sweep_table["name"] if name in summaries]
    if not rows:
        return {}
    fields = swept_fields(sweep_table)
    data = sweep_table.set_index("name")[fields].join(pd.DataFrame(rows).set_index("name"), how="inner")
    figures: dict = {}
    try:
        for field in fields:
            figures[f"vs_{field}.png"] = _swept_plot(data, field, [f for f in fields if f != field])
    except BaseException:
        for fig in figures.values():
            plt.close(fig)
        raise
    return figures


# ---------------------------------------------------------------- the sweep's page

def _run_folder(folder: Path, name: str, run) -> Path:
    """A sweep table row's run folder: its ``run`` (relative: from the sweep folder), or
    ``runs/<name>`` of the sweep folder when that path is gone (a moved sweep folder)."""
    path = Path(str(run))
    path = path if path.is_absolute() else folder / path
    if not path.is_dir() and (folder / "runs" / name).is_dir():
        return folder / "runs" / name
    return path


def _values_line(sweep_table: pd.DataFrame, paths: list[str]) -> str:
    def values(p):
        shown = list(dict.fromkeys(sweep_table[p].map(_value_text)))
        return ", ".join(shown[:SHOWN_VALUES]) + (f" and {len(shown) - SHOWN_VALUES} more" if len(shown) > SHOWN_VALUES
                                                   else "")
    return "; ".join(f"{p} = {values(p)}" for p in paths)


def variants_table(sweep_table: pd.DataFrame, runs: dict, numbers: dict, page_folder) -> Table:
    """The variants' table: name, the swept values (and the seed when it varies), status, flow rate
    +/- SE, clogged, the largest static (+/- SE) and dynamic band pressures, a link to the run's page.
    ``runs``: name -> run folder; ``numbers``: name -> :func:`run_numbers` (runs with a readable summary)."""
    paths = swept_fields(sweep_table) or set_paths(sweep_table)
    seeds = sweep_table["seed"].nunique() > 1 if "seed" in sweep_table else False
    rate_unit, rate_size = _units([n["rate"] for n in numbers.values()], MASS_RATE_UNITS)
    p_unit, p_size = _units([n[q] for n in numbers.values() for q in ("static", "dynamic")], PRESSURE_UNITS)
    header = ["run", *paths, *(["seed"] if seeds else []), "status", f"flow rate ({rate_unit})", "clogged",
              f"largest static ({p_unit})", f"largest max dynamic ({p_unit})", "page"]
    rows = []
    for row in sweep_table.to_dict("records"):
        name = str(row["name"])
        n = numbers.get(name)
        href = run_page_href(runs[name], page_folder)
        clogged = "-" if n is None else {True: "yes", False: "no"}.get(n["clogged"], "unknown")
        rows.append([name, *(_value_text(row[p]) for p in paths), *([_value_text(row["seed"])] if seeds else []),
                     str(row["status"]), _cell(n["rate"], n["rate_stderr"], rate_size) if n else "-", clogged,
                     _cell(n["static"], n["static_stderr"], p_size) if n else "-",
                     _plain(n["dynamic"], p_size) if n else "-",
                     Link(REPORT_HTML, href) if href else "none"])
    return Table(header, rows)


def sweep_report(folder, fit_runs) -> str:
    """The page of the sweep in ``folder`` (its ``report.html``), from its ``sweep.csv`` and its
    runs' ``results/summary.json``: a lead (how many runs complete, failed, clogged), the variants'
    table (:func:`variants_table`), Beverloo's fit over the complete runs that flowed steadily
    (``fit_runs(run folders) -> (table, fit)``: ``siloflow.answers.beverloo``, as ``siloflow beverloo
    OUT/sweep.csv`` fits them; when it refuses, why, and no figure), the figures (:func:`beverloo_figure`, :func:`swept_figures`) and
    ``sweep.csv``. A complete run whose summary cannot be read is named, its numbers left out.
    Raises ``ReadError`` when ``sweep.csv`` cannot be read."""
    folder = Path(folder).absolute()
    try:
        table = pd.read_csv(folder / SWEEP_TABLE)
    except (OSError, ValueError) as exc:
        raise ReadError(f"cannot read the sweep table {folder / SWEEP_TABLE}: {exc}") from None
    if not {"run", "name", "status"} <= set(table.columns):
        raise ReadError(f"{folder / SWEEP_TABLE} is not a sweep table (no run, name or status column)")
    table["name"] = table["name"].astype(str)
    runs = {row["name"]: _run_folder(folder, row["name"], row["run"]) for row in table.to_dict("records")}
    summaries, unreadable = {}, []
    for name in table.loc[table.status == "complete", "name"]:
        try:
            summaries[name] = RunFolder(runs[name]).read_summary()
        except (ReadError, OSError) as exc:
            unreadable.append(f"- {name}: {exc}: its numbers are left out of this page and of the fit")
    numbers = {name: run_numbers(s) for name, s in summaries.items()}
    counts = {status: int((table.status == status).sum()) for status in ("complete", "failed", "unfinished")}
    clogged = sorted(name for name, n in numbers.items() if n["clogged"])
    paths = set_paths(table)
    seeds = table["seed"].nunique() if "seed" in table else 1
    values = _values_line(table, swept_fields(table) or paths)
    lead = [f"- {len(table)} runs" + (f" over {values}" if values else "") + (f", {seeds} seeds each" if seeds > 1
                                                                              else "")
            + f": {counts['complete']} complete, "
            f"{counts['failed']} failed" + (f", {counts['unfinished']} unfinished" if counts["unfinished"] else ""),
            f"- {len(clogged)} clogged (no steady flow rate; out of Beverloo's fit)"
            + (f": {', '.join(clogged)}" if clogged else ""),
            f"- each run's own page: the link in its row; the table of results: {SWEEP_TABLE}, beside this page"]
    title = f"Sweep report: {folder.name}"
    blocks = [Title(title), Items(lead + unreadable)]

    figures: dict = {}
    fitted = [runs[name] for name in summaries]
    if not fitted:
        fit_part = [Text("Beverloo's fit: not given: no complete run with readable results.")]
    else:
        try:
            bev, fit = fit_runs(fitted)
        except (SiloflowError, ValueError) as exc:
            why, *rest = str(exc).splitlines()
            fit_part = [Text(f"Beverloo's fit: not given: {why}")]
            if rest:
                fit_part.append(Items([f"- {line.strip()}" for line in rest if line.strip()]))
        else:
            g = float(bev[bev.left_out == ""].g.iloc[0])
            fit_part = fit_blocks(bev, fit, "the complete runs that flowed steadily (as siloflow beverloo "
                                            f"{SWEEP_TABLE} fits them)")
            fit_part.append(Text(f"{BEVERLOO_PNG}: {beverloo_caption(bev, fit, g)}."))
            figures[BEVERLOO_PNG] = beverloo_figure(bev, fit, g)
    try:
        swept = swept_figures(table, summaries)
    except BaseException:
        for fig in figures.values():
            plt.close(fig)
        raise
    figures.update(swept)
    captions = [f"- {fname}: the steady flow rate (+/- 2 SE; open: clogged or unsteady) and the wall loads (the "
                "largest static band pressure +/- 2 SE, the largest max dynamic band pressure) of each run against "
                f"{fname[3:-4]}; lines: the means over the runs at each value" for fname in swept]
    blocks += [Heading("Variants"), variants_table(table, runs, numbers, folder), Heading("Beverloo's fit"),
               *fit_part, *([Items(captions, lead="Against the swept values:")] if captions else [])]
    return _page(blocks, folder.name, title, {SWEEP_TABLE: table}, figures)
