"""The report's summary card: the answers a designer reads first, each with the trust it carries.

One row per question (:data:`CARD_ROWS`): the flow rate with its error and Beverloo's prediction
beside it; the largest static and dynamic wall pressures with their heights; EN 1991-4 in one line
(how many bands lie above, within or below p_hf and p_he, and the stated cause); the run's health
(force balance, guard, clogging, bed against the plan); the numerical profile and the bound it
carries. Every number comes from the run's summary (``results/summary.json``) as it is, formatted
only. Rendered first in report.md and report.html (``report.text``, ``report.html_page``).
"""
from __future__ import annotations

import math
from typing import NamedTuple

from ..flow_rate import as_number
from ..numbers import mass_rate, mass_rate_value, pressure, pressure_value

#: the card's rows in order: key (the HTML row's id is ``card-<key>``) -> label
CARD_ROWS = {"flow": "Flow rate", "static": "Largest static wall pressure", "dynamic": "Largest dynamic wall pressure",
             "en": "EN 1991-4", "health": "Run health", "profile": "Numerical profile"}
#: a settled bed whose walls and bottom carry its weight within this share passes the force balance
FORCE_BALANCE_TOLERANCE = 0.02
#: a bed whose mass differs from the plan's by more than this share is flagged (a rain fill draws
#: each grain's size at random; a placed fill gives the plan's mix exactly)
BED_MASS_TOLERANCE = 0.02
#: the first words of EN 1991-4's verdicts per band (``postprocess.en_verdicts``), as counted
STATIC_VERDICTS, DYNAMIC_VERDICTS = ("above", "agrees", "below"), ("above", "within")


class CardRow(NamedTuple):
    """One answer: ``key`` (:data:`CARD_ROWS`), its label, the value, and what it rests on."""
    key: str
    label: str
    value: str
    detail: str


class Card(NamedTuple):
    """The summary card: its rows, in :data:`CARD_ROWS` order (rows without data left out)."""
    rows: list


def en_counts(design_loads: dict) -> dict | None:
    """EN 1991-4's verdicts counted over the bands under the fill that EN gives a p_hf (``design_loads``:
    the summary's): {bands, static: {word: [ratios]}, dynamic: {word: [ratios]}}; None without verdicts."""
    rows = [b for b in (design_loads or {}).get("bands", []) if b.get("static_verdict")
            and math.isfinite(as_number(b.get("en_p_hf")))]
    if not rows:
        return None

    def counted(verdict: str, ratio: str, words: tuple) -> dict:
        return {w: [b[ratio] for b in rows if str(b.get(verdict)).startswith(w)] for w in words}
    return {"bands": len(rows), "static": counted("static_verdict", "static_over_p_hf", STATIC_VERDICTS),
            "dynamic": counted("dynamic_verdict", "max_dynamic_over_p_he", DYNAMIC_VERDICTS)}


def en_count_text(counts: dict, ranges: bool = True) -> str:
    """'static against p_hf: 4 above (4.1-5.0 x), 0 agrees, 0 below; maximum dynamic against p_he: ...';
    without ``ranges``: 'static vs p_hf: 4 above, 0 agree, 0 below; max dynamic vs p_he: 4 above, 0 within'."""
    def said(hits: dict) -> str:
        return ", ".join(f"{len(h)} {w if ranges else w.removesuffix('s')}"
                         + (f" ({min(h):.2f}-{max(h):.2f} x)" if h and ranges else "") for w, h in hits.items())
    if not ranges:
        return f"static vs p_hf: {said(counts['static'])}; max dynamic vs p_he: {said(counts['dynamic'])}"
    return f"static against p_hf: {said(counts['static'])}; maximum dynamic against p_he: {said(counts['dynamic'])}"


def stated_cause(design_loads: dict) -> str:
    """The cause EN's comparison states for the bands that differ from EN: the first cause every such
    band shares, else the one most bands give ('' when none is stated)."""
    causes = [[c for c in str(b.get("static_causes") or "").split("; ") if c]
              for b in (design_loads or {}).get("bands", []) if b.get("static_verdict")]
    causes = [c for c in causes if c]
    if not causes:
        return ""
    common = [c for c in causes[0] if all(c in other for other in causes)]
    if common:
        return common[0]
    every = [c for band in causes for c in band]
    return max(dict.fromkeys(every), key=every.count)


def _flow_row(summary: dict) -> CardRow:
    fr, clog = summary.get("flow_rate") or {}, summary.get("clogged")
    bev = summary.get("beverloo_prediction") or {}
    if "rate" in bev:
        detail = (f"Beverloo with C = {bev['C']:g}, k = {bev['k']:g} and the bed's "
                  f"{'measured' if bev.get('rho_b_source') == 'measured' else 'planned'} bulk density "
                  f"{bev['rho_b']:.4g} kg/m3: {mass_rate_value(bev['rate'])}")
        if not clog and as_number(fr.get("rate")) > 0 and bev["rate"] > 0:
            detail += f"; DEM / Beverloo = {fr['rate'] / bev['rate']:.2f}"
    else:
        detail = f"no Beverloo prediction: {bev.get('error', 'not computed (an older summary)')}"
    if clog:
        return CardRow("flow", CARD_ROWS["flow"], "clogged: no steady flow rate",
                       f"{as_number(clog.get('discharged_mass_kg')) * 1000:.3g} g out, nothing after t = "
                       f"{as_number(clog.get('t_last_outflow_s')):.3g} s from opening; {detail}")
    value = mass_rate(fr.get("rate"), fr.get("stderr"))
    error = " (standard error by batch means)" if fr.get("batches") else ""
    return CardRow("flow", CARD_ROWS["flow"], value + error, detail)


def _pressure_rows(summary: dict) -> list[CardRow]:
    bands = [b for b in summary.get("bands") or [] if math.isfinite(as_number(b.get("static_pressure")))]
    if not bands:
        return []
    where = f"of {len(bands)} bands"
    s = max(bands, key=lambda b: b["static_pressure"])
    rows = [CardRow("static", CARD_ROWS["static"], pressure(s["static_pressure"], s.get("static_pressure_stderr")),
                    f"at z = {s['z_mid']:.3g} m (band {s['band']} {where}), the settled bed")]
    dynamic = [b for b in bands if math.isfinite(as_number(b.get("max_dynamic_pressure")))]
    if dynamic:
        d = max(dynamic, key=lambda b: b["max_dynamic_pressure"])
        rows.append(CardRow("dynamic", CARD_ROWS["dynamic"], pressure_value(d["max_dynamic_pressure"]),
                            f"at z = {d['z_mid']:.3g} m (band {d['band']}), the largest sample of the discharge; "
                            f"{as_number(d.get('discharge_factor')):.2f} x its static pressure; the steady discharge's "
                            f"mean there {pressure_value(d.get('dynamic_mean_pressure'))}"))
    return rows


def _en_row(summary: dict) -> CardRow | None:
    en = summary.get("design_loads")
    if not en:
        return None
    if not en.get("computed"):
        return CardRow("en", CARD_ROWS["en"], "not computed", str(en.get("reason") or ""))
    counts = en_counts(en)
    if counts is None:
        return CardRow("en", CARD_ROWS["en"], "no band under the fill to compare", "")
    cause = stated_cause(en)
    return CardRow("en", CARD_ROWS["en"], f"{counts['bands']} bands under the fill: " + en_count_text(counts, ranges=False),
                   (f"stated cause: {cause}" if cause else "no cause stated") + "; each band's verdict below")


def health_checks(summary: dict) -> list[tuple[bool, str]]:
    """The run's checks as (passed, what was measured): force balance, the guard, clogging, the bed
    against the plan. A check without data is left out."""
    checks = []
    fb = summary.get("force_balance")
    if fb:
        ratio = as_number(fb.get("ratio"))
        checks.append((abs(ratio - 1) <= FORCE_BALANCE_TOLERANCE,
                       f"walls and bottom carry {ratio:.4f} x the settled bed's weight"))
    guard = summary.get("guard") or {}
    if guard.get("stopped"):
        g = guard["stopped"]
        checks.append((False, f"the guard stopped the run ({g.get('signal')} at step {g.get('step')})"))
    elif guard.get("peaks"):
        peaks, r = guard["peaks"], as_number(guard.get("smallest_radius_m"))
        overlap = as_number(peaks.get("max_overlap"))
        checks.append((True, f"guard never tripped (fastest grain {as_number(peaks.get('max_speed')):.3g} m/s, deepest "
                             f"overlap {overlap * 1000:.3g} mm" + (f" = {overlap / r:.3g} of the smallest radius)"
                                                           if r > 0 else ")")))
    if "clogged" in summary:
        checks.append((not summary["clogged"], "the discharge clogged" if summary["clogged"] else "no clog"))
    planned = summary.get("planned_bed") or {}
    mass, plan_mass = as_number(summary.get("initial_mass_kg")), as_number(planned.get("mass_kg"))
    if plan_mass > 0 and math.isfinite(mass):
        off = mass / plan_mass - 1
        lost = summary.get("fill_losses") or 0
        checks.append((abs(off) <= BED_MASS_TOLERANCE,
                       f"bed of {summary.get('particles_inserted')} grains ({planned.get('grains')} planned), "
                       f"{mass * 1000:.4g} g against {plan_mass * 1000:.4g} g planned ({off:+.1%})"
                       + (f", {lost} lost in the fill" if lost else "")))
    return checks


def _health_row(summary: dict) -> CardRow:
    checks = health_checks(summary)
    failed = [what for ok, what in checks if not ok]
    value = (f"{len(failed)} of {len(checks)} checks to look at: " + "; ".join(failed)) if failed else \
        f"all {len(checks)} checks pass"
    return CardRow("health", CARD_ROWS["health"], value, "; ".join(what for ok, what in checks if ok))


def _profile_row(summary: dict) -> CardRow | None:
    p = summary.get("numerical_profile")
    if not p:
        return None
    settings = f"time step {as_number(p.get('timestep_fraction')):g} of the contact time, stiffness x {as_number(p.get('stiffness_scale')):g}"
    if p.get("name") == "fast":
        bounds = ", ".join(f"{q.replace('_', ' ')} {as_number(b):.1%}" for q, b in (p.get("error_bounds") or {}).items())
        detail = (f"{settings}; 95 % error bounds against the papers' settings: {bounds}, proven on "
                  f"{p.get('benchmark') or 'the benchmark case'}; this case's own error is not measured"
                  if bounds else f"{settings}; its error bounds are not measured yet")
        if p.get("unbounded"):
            detail += f"; not bounded: {', '.join(p['unbounded'])}"
        return CardRow("profile", CARD_ROWS["profile"], "fast", detail)
    if p.get("name") == "reference":
        return CardRow("profile", CARD_ROWS["profile"], "reference", f"{settings}: the papers' settings")
    return CardRow("profile", CARD_ROWS["profile"], str(p.get("name")),
                   f"{settings}; no error bound is claimed against the papers' settings")


def summary_card(summary: dict) -> Card:
    """The card of a run's summary: its rows in :data:`CARD_ROWS` order."""
    rows = [_flow_row(summary), *_pressure_rows(summary), _en_row(summary), _health_row(summary),
            _profile_row(summary)]
    return Card([r for r in rows if r is not None])
