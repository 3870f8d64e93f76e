"""The report's text: its blocks (a title, bullet lists, paragraphs and tables of strings) from a
run's summary (:func:`report_blocks`), rendered as Markdown (report.md, :func:`markdown`) and, by
``report.html_page``, as HTML; and the lines ``siloflow run``/``post`` print (:func:`console_lines`).

One list of blocks feeds both reports, so report.html states every number of report.md as the
same string.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

from siloflow.plan import unbounded_note
from siloflow.run_folder import SUMMARY_NAME

from ..numbers import mass_rate, mass_rate_value, pressure
from .card import Card, en_count_text, en_counts, summary_card

# ---------------------------------------------------------------- the blocks of a report

class Title(NamedTuple):
    """The report's heading."""
    text: str


class Heading(NamedTuple):
    """A section's heading."""
    text: str


class Items(NamedTuple):
    """A bullet list: Markdown lines ``- item`` and ``  - sub-item``, after an optional ``lead`` line."""
    lines: list
    lead: str | None = None


class Text(NamedTuple):
    """A paragraph (a table's caption, a statement)."""
    text: str


class Table(NamedTuple):
    """A table of strings (or :class:`Link` cells): its header and its rows."""
    header: list
    rows: list


class Link(NamedTuple):
    """A table cell that links to another page: its text and its URL (relative to the page)."""
    text: str
    href: str


def cell_text(cell) -> str:
    """A table cell as report.md writes it: a :class:`Link` as ``[text](href)``."""
    return f"[{cell.text}]({cell.href})" if isinstance(cell, Link) else str(cell)


#: the summary card's header, as a table (report.md) and in report.html
CARD_HEADER = ["Summary", "answer", "what it rests on"]


def card_table(card: Card) -> Table:
    """The summary card as a table of strings: label, value, detail per row."""
    return Table(CARD_HEADER, [[r.label, r.value, r.detail] for r in card.rows])


def markdown(blocks) -> str:
    """report.md: the blocks separated by blank lines."""
    def md(b) -> str:
        if isinstance(b, Title):
            return f"# {b.text}"
        if isinstance(b, Items):
            return "\n".join(([b.lead] if b.lead else []) + list(b.lines))
        if isinstance(b, Table):
            return "\n".join([f"| {' | '.join(b.header)} |", "|" + "---|" * len(b.header),
                              *(f"| {' | '.join(map(cell_text, row))} |" for row in b.rows)])
        if isinstance(b, Card):
            return md(card_table(b))
        if isinstance(b, Heading):
            return f"## {b.text}"
        return b.text
    return "\n\n".join(md(b) for b in blocks) + "\n"


# ---------------------------------------------------------------- the report's lines

def _fmt(value, spec: str = ".4g") -> str:
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        return "n/a"


def _cell(value, spec: str) -> str:
    """A table cell: the number, or "-" where there is none (no EN value at that height: NaN)."""
    text = _fmt(value, spec)
    return "-" if text in ("nan", "n/a") else text


def _ci(ci, spec: str = ".3g") -> str:
    return f"[{_fmt(ci[0], spec)}, {_fmt(ci[1], spec)}]" if ci else "[n/a]"


def _ranges(numbers) -> str:
    """1, 2, 3, 5 -> '1-3, 5'."""
    out, run = [], []
    for k in sorted(numbers):
        if run and k != run[-1] + 1:
            out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else f"{run[0]}")
            run = []
        run.append(k)
    if run:
        out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else f"{run[0]}")
    return ", ".join(out)


def janssen_lines(j: dict) -> list[str]:
    """The report's lines on the band-true Janssen fit (summary's ``janssen_static``)."""
    if not j:
        return []
    if "K" not in j:
        return [f"- Janssen fit of the settled profile: not fitted: {j.get('error', 'no fit')}"]
    how = (f"band-averaged below the free surface, {j['n_bands_used']} band(s) {_ranges(j['bands_used'])}"
           + ("; corner band excluded" if j.get("exclude_corner") else "; corner band included") + ")")
    values = (f"K = {_fmt(j['K'], '.3f')} {_ci(j['K_ci'])}, mu_eff = {_fmt(j['mu_eff'], '.3f')} {_ci(j['mu_eff_ci'])}, "
              f"mobilisation mu_eff / mu_w = {_fmt(j['mobilisation'], '.2f')} {_ci(j['mobilisation_ci'], '.2f')} "
              f"of mu_w = {_fmt(j['mu_w'], '.3g')}, r2 {_fmt(j['r2'], '.3f')}")
    hyd = (f"  - hydrostatic comparison p = K rho_b g d: K = {_fmt(j['hydrostatic_K'], '.3f')} "
           f"{_ci(j['hydrostatic_K_ci'])}, r2 {_fmt(j['hydrostatic_r2'], '.3f')}")
    if j["resolved"]:
        return [f"- Janssen fit of the settled profile ({how}: {values} (95 % intervals)", hyd]
    return [f"- Janssen fit of the settled profile ({how}: not resolved: {j['reason']}",
            f"  - fitted values, not to be used as material data: {values}", hyd]


def profile_line(p: dict | None) -> str:
    """The report's line on the numerical profile (engine.profile) and the error bounds it carries."""
    if not p:
        return "- numerical profile: not recorded (rendered by an older siloflow)"
    line = (f"- numerical profile {p['name']}: time step {_fmt(p['timestep_fraction'], 'g')} of the critical time, "
            f"stiffness x {_fmt(p['stiffness_scale'], 'g')}")
    if p["name"] == "fast":
        bounds = ", ".join(f"{q} {b:.1%}" for q, b in (p.get("error_bounds") or {}).items())
        question = f" (proven for {p['question'].replace('_', ' ')})" if p.get("question") else ""
        line += (f"; 95 % error bounds against the papers' settings{question}: {bounds}, measured on the benchmark's "
                 f"case (siloflow bench, {p.get('benchmark')})"
                 f"{unbounded_note(p.get('unbounded') or [], p.get('measured') or {})}; another case's own error "
                 "is not measured" if bounds else "; its error bounds are not measured yet")
    return line


def clog_line(clogged: dict, fr: dict) -> str:
    """What a clogged discharge (:func:`discharge.clog`) is said to be, with the straight line over its
    whole discharge (``fr``: the summary's flow rate) beside it, not as a result."""
    return (f"the discharge CLOGGED: nothing left the silo after t = {_fmt(clogged['t_last_outflow_s'], '.3g')} s "
            f"from opening ({_fmt(clogged['discharged_mass_kg'] * 1000)} g out), so the flow rate is not a steady "
            "one; an orifice this size clogs by chance, so run more seeds or widen it (fitted over the whole "
            f"discharge: {mass_rate(fr['rate'], fr.get('stderr'))})")


def flow_rate_line(fr: dict, clogged: dict | None = None) -> str:
    """The report's flow-rate line: the one steady rate, its batch-means error, its window, or the
    clog that left no steady rate."""
    if clogged:
        return f"- {clog_line(clogged, fr)}"
    line = (f"- steady flow rate Wf = {mass_rate(fr['rate'], fr.get('stderr'))} (t = {_fmt(fr['t_start'], '.3g')}-"
            f"{_fmt(fr['t_end'], '.3g')} s, {fr.get('n_samples')} samples, r2 {_fmt(fr['r2'], '.4f')}")
    if fr.get("batches"):
        line += (f"; standard error by batch means of {fr['batches']} batches, the error that matches the spread "
                 f"of seeds (the straight line's own, {mass_rate_value(fr.get('fit_stderr'))},"
                 " takes the samples as independent)")
    elif "batches" in fr:
        line += "; its error is not resolved: the window holds too few samples for batch means"
    return line + ")"


def steady_window_line(steady: dict, fr: dict) -> str:
    """The detected steady window, the dynamic pressures' window; not a second flow rate: its
    median sample rate is compared with Wf in units of Wf's error."""
    line = (f"- steady discharge detected (the window of the dynamic pressures): t = {_fmt(steady['t_start'], '.3g')}-"
            f"{_fmt(steady['t_end'], '.3g')} s")
    if not steady.get("resolved", True):
        return line + f": not resolved: {steady['reason']}"
    line += f" ({steady['n_samples']} samples)"
    diff = steady["median_rate"] - fr["rate"]
    se = fr.get("stderr")
    if se is not None and math.isfinite(se) and se > 0 and abs(diff) > 2 * se:
        line += (f"; its median sample rate {mass_rate_value(steady['median_rate'])} differs "
                 f"from Wf by {diff / se:+.1f} standard errors: the rate drifts over Wf's window (the silo empties "
                 "or the flow is still starting), so Wf is an average over that window")
    return line


def static_cell(b: dict) -> str:
    """A band's static pressure with its error, or why its error is not resolved."""
    value, se = b.get("static_pressure"), b.get("static_pressure_stderr")
    if se is not None and math.isfinite(se):
        return pressure(value, se)
    why = []
    if b.get("static_batches") == 0:
        why.append(f"the static window holds {b.get('static_samples')} samples (batch means need 10)")
    if b.get("static_sectors", 2) < 2:
        why.append("a band of one sector shows no spread around the wall")
    return f"{_fmt(value, '.1f')} Pa (error not resolved: {'; '.join(why) or 'see bands.csv'})"


def mobilisation_note(summary: dict) -> str | None:
    """The settled bed's measured wall-friction mobilisation (``design_loads.bed_state``), said
    beside the static pressures: mu_eff and its share of the grains' wall friction mu_w (of EN's
    mu for a summary without mu_w), and the fill protocol; None when the bed's mu_eff is not
    measured (no force balance of a flat-bottomed cylinder, no EN comparison)."""
    state = (summary.get("design_loads") or {}).get("bed_state") or {}
    mu_eff = state.get("mu_eff")
    if mu_eff is None:
        return None
    mu_w = state.get("mu_w")
    share = (f"{mu_eff / mu_w:.2f} of mu_w = {mu_w:.3g}" if mu_w else
             f"{mu_eff / state['mu_en']:.2f} of EN's mu = {state['mu_en']:.3g}")
    return f"the bed mobilises mu_eff = {mu_eff:.2g} on the wall, {share} (fill protocol: {state['protocol']})"


def en_verdict_blocks(en: dict) -> list:
    """The report's bed state and per-band verdicts of the EN comparison (no ratio without one)."""
    state, blocks = en.get("bed_state") or {}, []
    if state:
        line = f"The settled bed ({state['protocol']} fill)"
        if state.get("mu_eff") is not None:
            line += (f": the wall carries {state['wall_friction_share']:.2f} of its weight by friction (Janssen with "
                     f"EN's mu = {state['mu_en']:.3g} and K = {state['K_en']:.3g}: {state['janssen_share_en']:.2f}); "
                     f"its friction over its normal force, the mobilised mu_eff, is {state['mu_eff']:.2g} "
                     f"({state['mu_eff'] / state['mu_en']:.2f} of EN's mu), and Janssen's law carries that share with "
                     f"K_eff = {_fmt(state.get('K_eff'), '.2g')}")
        else:
            line += ": its wall friction's mobilisation is not measured (needs the force balance of a flat-bottomed cylinder)"
        if state.get("K_bed") is not None:
            line += f"; its own K = {state['K_bed']:.3g}"
        blocks.append(Text(line + "."))
    verdicts = [b for b in en.get("bands", []) if b.get("static_verdict")]
    if verdicts:
        blocks += verdict_blocks(verdicts)
    return blocks


def console_lines(summary: dict) -> list[str]:
    """What ``siloflow run``/``post`` print of the static loads beside the flow rate: each band's
    static pressure with its error, the Janssen fit's headline, and a count of the EN 1991-4
    verdicts (their causes are in report.md / report.html)."""
    lines = []
    bands = [b for b in summary.get("bands") or [] if b.get("static_pressure") is not None]
    if bands:
        note = mobilisation_note(summary)
        lines.append("static wall pressure by band (Pa, mean +/- standard error" + (f"; {note}" if note else "")
                     + "): " + "; ".join(f"{b['band']}: {static_cell(b).removesuffix(' Pa')}" for b in bands))
    fit = janssen_lines((summary.get("frame_analyses") or {}).get("janssen_static", {}))
    if fit:
        lines.append(fit[0].removeprefix("- "))
    counts = en_counts(summary.get("design_loads") or {})
    if counts:
        lines.append(f"EN 1991-4 ({counts['bands']} bands under the fill): {en_count_text(counts)}"
                     "; the measured causes per band: report.html")
    return lines


#: where a dynamic verdict's figure ends and its explanation begins ("above EN p_he (1.8 x): ...")
_EXPLAINED = "): "


def verdict_blocks(verdicts: list[dict]) -> list:
    """The per-band verdicts with what every band shares said once: a cause (or a dynamic verdict's
    explanation) found in every band that has causes is stated under "Causes common to ..." and left
    out of the band lines, which keep their own numbers and band-specific causes."""
    causes = {b["band"]: [c for c in str(b.get("static_causes") or "").split("; ") if c] for b in verdicts}
    with_causes = [c for c in causes.values() if c]
    common = [c for c in with_causes[0] if all(c in other for other in with_causes)] if len(with_causes) > 1 else []
    dynamic = {b["band"]: str(b["dynamic_verdict"]).partition(_EXPLAINED) for b in verdicts}
    notes = [d[2] for d in dynamic.values() if d[1]]
    shared_note = notes[0] if len(notes) > 1 and all(n == notes[0] for n in notes) else None
    lines = []
    for b in verdicts:
        own = [c for c in causes[b["band"]] if c not in common]
        head, sep, note = dynamic[b["band"]]
        dyn = head + ")" if sep and note == shared_note else "".join(dynamic[b["band"]])
        lines.append(f"- band {b['band']}: static {b['static_verdict']}" + (f"; cause: {'; '.join(own)}" if own else "")
                     + f"; maximum dynamic {dyn}")
    blocks = []
    if common or shared_note:
        blocks.append(Items([f"- {c}" for c in common] + ([f"- maximum dynamic: {shared_note}"] if shared_note else []),
                            lead="Causes common to every band that differs from EN:"))
    blocks.append(Items(lines, lead="Verdicts per band:"))
    return blocks


def _facts(summary: dict) -> list[str]:
    """The report's first bullet list: the run, its flow rate, its settled bed."""
    fb, fr = summary["force_balance"], summary["flow_rate"]
    lines = [f"- particles inserted: {summary['particles_inserted']}, mass {_fmt(summary['initial_mass_kg'] * 1000)} g"
             + (f" ({summary['fill_losses']} atoms left the box while pouring; the bed settled without them)"
                if summary.get("fill_losses") else ""),
             f"- settled at KE/PE = {_fmt(summary['settled_ke_pe'], '.2e')}; outlet opened at t = "
             f"{_fmt(summary['time_open_s'])} s",
             (f"- force balance of the settled bed: walls + bottom carry {_fmt(fb['ratio'], '.4f')} x the weight "
              f"({_fmt(fb['wall_friction_share'], '.2f')} of it by wall friction)" if fb else
              "- force balance: not measured (outputs.results asks for neither force_balance nor wall_pressure)"),
             flow_rate_line(fr, summary.get("clogged")),
             f"- discharged {_fmt(summary['discharged_mass_kg'] * 1000)} g; {_fmt(summary['mass_in_silo_end_kg'] * 1000)} g left"]
    engine = summary.get("engine")
    if engine:
        lines += [f"- engine: {engine['name']} on {engine['ranks']} MPI rank(s), {_fmt(summary['engine_wall_time_s'], '.3g')} s"]
    lines += [profile_line(summary.get("numerical_profile"))]
    steady = summary.get("steady_window_detected")
    if steady:
        lines += [steady_window_line(steady, fr)]
    fa = summary.get("frame_analyses", {})
    if "bulk_solid_fraction" in fa:
        if "cross_section_solid_fraction" in fa:
            lines += [f"- settled bed: bulk solid fraction {_fmt(fa['bulk_solid_fraction'], '.3f')} (core), "
                      f"{_fmt(fa['cross_section_solid_fraction'], '.3f')} (whole cross-section); bulk density "
                      f"{_fmt(fa['bulk_density_kg_m3'], '.4g')} kg/m3 (core); free surface at "
                      f"{_fmt(fa['settled_surface_height_m'] * 1000)} mm"]
        else:
            lines += [f"- settled bed: free surface at {_fmt(fa['settled_surface_height_m'] * 1000)} mm; "
                      f"no bulk solid fraction: {fa['bulk_solid_fraction']['error']}"]
        if "coordination_settled" in fa:
            c = fa["coordination_settled"]
            lines += [f"- coordination number (core, {fa['coordination_convention']}): {_fmt(c['z_mean'], '.2f')}, "
                      f"mechanical {_fmt(c['z_mech'], '.2f')}"]
        if "flow_rate_surface" in fa:
            wr = fa["flow_rate_surface"]
            if wr.get("resolved", True):
                lines += [f"- free-surface flow rate Wr = {_fmt(wr['rate'] * 1000)} g/s = "
                          f"{_fmt(fa['flow_rate_surface_over_outlet'], '.3f')} +/- "
                          f"{_fmt(fa.get('flow_rate_surface_over_outlet_stderr'), '.2g')} x Wf (the surface descended "
                          f"{_fmt(wr.get('surface_descent_grain_diameters'), '.3g')} grain diameters)"]
            else:
                lines += [f"- free-surface flow rate Wr: not resolved: {wr['reason']}"]
        lines += janssen_lines(fa.get("janssen_static", {}))
    else:
        lines += [f"- frame analyses: {fa.get('dumps', 'none')}"]
    return lines


def _band_blocks(summary: dict) -> list:
    """The band pressures: their caption (the windows, the bed's mobilisation) and table."""
    ps = summary.get("pressure_statistics") or {}
    win = ps.get("dynamic_window") or {}
    mobilised = mobilisation_note(summary)
    blocks = []
    if win.get("t_start") is not None:
        blocks.append(Text(
            f"Band pressures (Pa). Static: mean over t = {_fmt(ps['static_window']['t_start'], '.3g')}-"
            f"{_fmt(ps['static_window']['t_end'], '.3g')} s +/- its batch-means standard error"
            + (f"; {mobilised}" if mobilised else "")
            + f". Dynamic: over the {win['source']} t = {_fmt(win['t_start'], '.3g')}-{_fmt(win['t_end'], '.3g')} s "
            f"({win['n_samples']} samples" + (")" if win.get("resolved", True) else f"; not resolved: {win['reason']})")
            + "; max dynamic and C_h = max dynamic / static over the whole discharge."))
    elif mobilised:
        blocks.append(Text(f"Band pressures (Pa). Static: {mobilised}."))
    rows = [[str(b["band"]), _fmt(b["z_mid"], ".3f"), static_cell(b),
             f"{_fmt(b.get('dynamic_mean_pressure'), '.1f')} +/- {_fmt(b.get('dynamic_std_pressure'), '.2g')}",
             _fmt(b.get("dynamic_p95_pressure"), ".1f"), _fmt(b.get("dynamic_max_pressure"), ".1f"),
             _fmt(b["max_dynamic_pressure"], ".1f"), _fmt(b["discharge_factor"], ".2f")] for b in summary["bands"]]
    return blocks + [Table(["band", "z (m)", "static p", "dynamic mean +/- sd", "p95", "max (window)", "max dynamic",
                            "C_h"], rows)]


def _eccentric_blocks(summary: dict) -> list:
    """An eccentric outlet's near and far walls per band (summary's ``eccentric_discharge``)."""
    ecc = summary.get("eccentric_discharge")
    if not ecc:
        return []
    rows = [[str(b["band"]), _fmt(b["z_mid"], ".3f"), _fmt(b["near_pressure"], ".1f"), _fmt(b["far_pressure"], ".1f"),
             f"{_fmt(b['difference'], '+.1f')} +/- {_fmt(b['difference_stderr'], '.2g')}", _cell(b["ratio"], ".2f")]
            for b in ecc["bands"]]
    where = f"x {_fmt(ecc['outlet_offset_m'], '.4g')} m" + (f", y {_fmt(ecc['outlet_offset_y_m'], '.4g')} m"
                                                             if "outlet_offset_y_m" in ecc else "")
    return [Text(f"Eccentric outlet (at {where} off the middle, towards sector "
                 f"{ecc['near_sector']}): {ecc['what']}. Every sector: sectors.csv (Pa), sectors.png."),
            Table(["band", "z (m)", "near (Pa)", "far (Pa)", "near - far (Pa)", "near / far"], rows)]


def _en_blocks(summary: dict) -> list:
    """EN 1991-4's pressures beside the DEM's, with the verdicts; or why they are not computed."""
    en = summary.get("design_loads") or {}
    if not en:
        return []
    if not en.get("computed"):
        return [Text(f"EN 1991-4 loads: not computed ({en.get('reason')})")]
    mobilised = mobilisation_note(summary)
    rows = [[str(b["band"]), _cell(b["en_p_hf"], ".1f"), _cell(b["static_over_p_hf"], ".2f"), _cell(b["en_p_he"], ".1f"),
             _cell(b["max_dynamic_over_p_he"], ".2f"), _cell(b["dem_discharge_factor"], ".2f")] for b in en["bands"]]
    return [Text(f"EN 1991-4 beside the DEM ({en['classification']} silo, solid: {en['solid']}; "
                 f"C_h = {_fmt(en['C_h'], '.3g')}): design_vs_dem.csv, design_loads.png"
                 + (f". DEM static: {mobilised}." if mobilised else "")),
            Table(["band", "EN p_hf (Pa)", "DEM static / p_hf", "EN p_he (Pa)", "DEM max dynamic / p_he", "DEM C_h"],
                  rows),
            *en_verdict_blocks(en)]


def report_blocks(summary: dict, name: str) -> list:
    """The report of a run named ``name`` (its folder's name) from its summary, as blocks
    (:class:`Title`, :class:`Items`, :class:`Text`, :class:`Table`) that :func:`markdown` and
    :func:`html_blocks` render."""
    blocks = [Title(f"Run report: {name}"), summary_card(summary), Heading("The run in full"), Items(_facts(summary))]
    if summary["bands"]:
        blocks += _band_blocks(summary)
    blocks += _eccentric_blocks(summary)
    blocks += _en_blocks(summary)
    if "pressure_comparison" in summary:
        blocks.append(Table(["band", "max measured (Pa)", "max simulated (Pa)", "difference", "W (Eq. 34)"],
                            [[str(r["band"]), _fmt(r["max_measured_Pa"], ".1f"), _fmt(r["max_simulated_Pa"], ".1f"),
                              _fmt(r["relative_difference"], "+.1%"), _fmt(r["W"], ".1%")]
                             for r in summary["pressure_comparison"]]))
    warnings = summary.get("engine_warnings") or []
    if warnings:
        blocks.append(Text(f"Engine warnings ({len(warnings)}): see {SUMMARY_NAME}"))
    return blocks


def report_text(summary: dict, run) -> str:
    """A short human-readable report of a run's results (Markdown); ``run.folder`` names it."""
    return markdown(report_blocks(summary, Path(run.folder).name))
