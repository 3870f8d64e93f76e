"""The report's summary card (``postprocess.report.card``), the wall unrolled (``wall_map_plot``) and
Beverloo's prediction beside a run's flow rate (``postprocess.flow_rate.beverloo_prediction``).

The card's numbers are read back from report.html and compared with summary.json's; its checks
fail where the run is not healthy; the page shows the flow rate and EN's line within the first
900 pixels of a 1280-wide window in headless Chromium. No engine, but one test that reads the
shared small engine run (``small_run``)."""
from __future__ import annotations

import copy
import json
import math
import re
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest

from postprocess.flow_rate import BEVERLOO_C, BEVERLOO_K, beverloo_prediction
from postprocess.report import write_report
from postprocess.report.card import CARD_ROWS, health_checks, stated_cause, summary_card
from postprocess.report.figures import plt, wall_map_plot
from siloflow.case_file import case_from_dict, load_case
from siloflow.derived import derive
from conftest import QUICK, needs_liggghts
from test_report_html import fake_report, leaving, needs_chromium, render, with_en  # noqa: F401  (fixture)

NUMBER = r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?"


class CardRows(HTMLParser):
    """report.html's summary card: {key: (label, value, detail)} from the rows ``<tr id="card-<key>">``."""

    def __init__(self):
        super().__init__()
        self.rows, self.key, self.cells = {}, None, []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "tr" and str(a.get("id", "")).startswith("card-"):
            self.key, self.cells = a["id"][5:], []
        elif self.key and tag in ("th", "td"):
            self.cells.append("")

    def handle_data(self, data):
        if self.key and self.cells:
            self.cells[-1] += data

    def handle_endtag(self, tag):
        if tag == "tr" and self.key:
            self.rows[self.key] = tuple(self.cells)
            self.key = None


def card_rows(page: str) -> dict:
    p = CardRows()
    p.feed(page)
    return p.rows


def numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(NUMBER, text)]


def pascals(text: str) -> float:
    """The first pressure of ``text`` ('1.13 kPa', '999.9 +/- 0.4 Pa') in Pa."""
    value, unit = re.search(rf"({NUMBER})(?: \+/- {NUMBER})? (MPa|kPa|Pa)\b", text).groups()
    return float(value) * {"MPa": 1e6, "kPa": 1e3, "Pa": 1.0}[unit]


@pytest.fixture
def en_report(fake_report, tmp_path):
    """The in-memory run's results with an EN comparison, written with its figures: (summary, folder)."""
    summary, out = fake_report
    s = with_en(summary)
    s["design_loads"]["bands"][0]["static_verdict"] = "agrees with EN p_hf (1.02 x)"
    s["design_loads"]["bands"][0]["static_causes"] = ""
    s["force_balance"] = {**s["force_balance"], "ratio": 0.998}      # the fake's walls carry a made-up load
    s["numerical_profile"] = {"name": "fast", "timestep_fraction": 0.1, "stiffness_scale": 0.1,
                              "error_bounds": {"flow_rate": 0.03, "static_band_pressure": 0.038},
                              "benchmark": "benchmarks/cases/accuracy_small.yaml", "unbounded": []}
    figures = {"wall_map.png": wall_map_plot(pd.read_csv(out / "sectors.csv"), s["design_loads"]["bands"])}
    write_report(tmp_path, "run", s, {"bands.csv": pd.read_csv(out / "bands.csv")}, figures)
    return json.loads((tmp_path / "summary.json").read_text()), tmp_path


def test_the_card_states_the_summary_s_numbers(en_report):
    """Each number of the card, read back from report.html, is summary.json's, to the digits shown."""
    summary, out = en_report
    rows = card_rows((out / "report.html").read_text())
    assert list(rows) == list(CARD_ROWS)                                   # every answer, in order
    fr = summary["flow_rate"]
    value, error = numbers(rows["flow"][1])[:2]                           # "20.0 +/- 0.1 g/s"
    assert "g/s" in rows["flow"][1]
    assert abs(value / 1000 - fr["rate"]) <= 0.06 * error / 1000 + 1e-12 and error / 1000 == pytest.approx(fr["stderr"], rel=0.06)
    bev = summary["beverloo_prediction"]
    assert f"C = {BEVERLOO_C:g}, k = {BEVERLOO_K:g}" in rows["flow"][2]
    assert numbers(rows["flow"][2].split("DEM / Beverloo = ")[1])[0] == pytest.approx(fr["rate"] / bev["rate"], abs=0.006)
    bands = summary["bands"]
    top = max(bands, key=lambda b: b["static_pressure"])
    assert pascals(rows["static"][1]) == pytest.approx(top["static_pressure"], rel=0.01)
    assert f"z = {top['z_mid']:.3g} m (band {top['band']} of {len(bands)} bands)" in rows["static"][2]
    dyn = max(bands, key=lambda b: b["max_dynamic_pressure"])
    assert pascals(rows["dynamic"][1]) == pytest.approx(dyn["max_dynamic_pressure"], rel=5e-4)
    assert f"band {dyn['band']})" in rows["dynamic"][2]
    # EN: the counts of the bands' verdicts, and the cause every differing band states
    n = len(summary["design_loads"]["bands"])
    assert rows["en"][1] == (f"{n} bands under the fill: static vs p_hf: {n - 1} above, 1 agree, 0 below; "
                             f"max dynamic vs p_he: 0 above, {n} within")
    assert "stated cause: the wall mobilises little" in rows["en"][2]
    assert rows["health"][1] == "all 4 checks pass"
    assert "walls and bottom carry 0.9980 x the settled bed's weight" in rows["health"][2]
    assert rows["profile"][1] == "fast" and "flow rate 3.0%, static band pressure 3.8%" in rows["profile"][2]
    assert "proven on benchmarks/cases/accuracy_small.yaml" in rows["profile"][2]
    md = (out / "report.md").read_text()
    assert md.index("| Summary | answer | what it rests on |") < md.index("## The run in full")   # the card first
    for label, value, detail in rows.values():
        assert f"| {label} | {value} | {detail} |" in md                                         # the same card


def test_health_names_what_to_look_at(fake_report):
    """A force balance off by 5 %, a guard that stopped the run, a bed 5 % light and a clog are each
    flagged; a healthy summary passes them."""
    summary, _ = fake_report
    s = copy.deepcopy(summary)
    s["force_balance"] = {"ratio": 1.001}
    assert all(ok for ok, _ in health_checks(s))
    s["force_balance"] = {"ratio": 1.05}
    s["guard"] = {"stopped": {"signal": "speed", "step": 1200, "value": 40.0, "limit": 30.0}, "peaks": None}
    s["initial_mass_kg"] = 0.95 * s["planned_bed"]["mass_kg"]
    s["clogged"] = {"t_last_outflow_s": 0.2, "discharged_mass_kg": 0.003}
    flagged = [what for ok, what in health_checks(s) if not ok]
    assert len(flagged) == 4, flagged
    assert any("1.0500 x" in f for f in flagged) and any("speed at step 1200" in f for f in flagged)
    assert any("(-5.0%)" in f for f in flagged) and "the discharge clogged" in flagged
    card = {r.key: r for r in summary_card(s).rows}
    assert card["health"].value.startswith("4 of 4 checks to look at")
    assert card["flow"].value == "clogged: no steady flow rate" and "3 g out" in card["flow"].detail


def test_the_stated_cause_is_the_one_every_band_shares_else_the_most_common():
    band = lambda causes: {"static_verdict": "above EN p_hf", "static_causes": "; ".join(causes)}   # noqa: E731
    assert stated_cause({"bands": [band(["a", "b"]), band(["b", "a"]), band([])]}) == "a"
    assert stated_cause({"bands": [band(["a", "c"]), band(["c", "b"]), band(["b", "c"])]}) == "c"
    assert stated_cause({"bands": [band([])]}) == ""


def test_beverloo_prediction_is_the_law_with_the_literature_constants(quick_dict):
    """The quick case (3 mm beads, 16 mm orifice): C rho_b sqrt(g) (D0 - k d)^2.5 with the measured
    bulk density, by hand; without dumps, packing fraction x grain density; clumps: no prediction."""
    plan = derive(case_from_dict(quick_dict))
    got = beverloo_prediction(plan, {"frame_analyses": {"bulk_density_kg_m3": 1500.0}}, "run")
    assert got["rate"] == pytest.approx(0.58 * 1500.0 * math.sqrt(9.81) * (0.016 - 1.5 * 0.003) ** 2.5, rel=1e-12)
    assert got["rho_b_source"] == "measured"
    planned = beverloo_prediction(plan, {}, "run")
    assert planned["rho_b"] == pytest.approx(plan.fill.packing_fraction * 2500.0) and planned["rho_b_source"] == \
        "case packing fraction"
    clumps = derive(load_case(QUICK.parent / "paper_a_clumps_quick.yaml"))
    assert "clump" in beverloo_prediction(clumps, {}, "run")["error"]


def test_the_wall_map_draws_each_sector_in_its_cell():
    """A cylinder's 2 bands x 4 sectors: each cell spans its arc and its band's heights and carries its
    pressure; with EN's p_hf the ratio panels are drawn (5 panels, else 3); a box's walls by their sides."""
    rows = [{"band": b, "sector": s, "z_mid": 0.05 + 0.1 * b, "z0": 0.1 * b, "z1": 0.1 * (b + 1),
             "azimuth_deg": 45.0 + 90 * s, "arc_deg": 90.0, "static_mean_pressure": 100.0 * (b + 1) + s,
             "dynamic_mean_pressure": 50.0 + s, "discharge_max_pressure": 300.0 + s} for b in range(2) for s in range(4)]
    sectors = pd.DataFrame(rows)
    fig = wall_map_plot(sectors, [{"band": 0, "en_p_hf": 100.0, "en_p_he": 150.0}])
    try:
        panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert len(panels) == 5
        static = panels[0].collections[0]
        np.testing.assert_allclose(static.get_array(), sectors.static_mean_pressure)
        x0, y0 = static.get_paths()[5].vertices.min(axis=0)      # band 1, sector 1: 90-180 deg, 0.1-0.2 m
        x1, y1 = static.get_paths()[5].vertices.max(axis=0)
        assert (x0, x1) == pytest.approx((90.0, 180.0)) and (y0, y1) == pytest.approx((0.1, 0.2))
        ratio = np.ma.filled(panels[3].collections[0].get_array(), np.nan)
        np.testing.assert_allclose(ratio[:4], sectors.static_mean_pressure[:4] / 100.0)
        assert np.isnan(ratio[4:]).all()                          # band 1 has no EN load: grey
    finally:
        plt.close(fig)
    box = sectors.assign(arc_deg=np.nan, azimuth_deg=[0.0, 90.0, 180.0, 270.0] * 2)
    fig = wall_map_plot(box)
    try:
        panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert len(panels) == 3
        assert [t.get_text() for t in panels[0].get_xticklabels()] == ["+x wall", "+y wall", "-x wall", "-y wall"]
    finally:
        plt.close(fig)


def test_a_sector_s_largest_discharge_sample_is_in_sectors_csv(fake_report):
    """sectors.csv's discharge_max_pressure: the largest sample after the opening, per sector; each band's
    largest is its max dynamic pressure or above it (a band is its sectors' mean)."""
    summary, out = fake_report
    sectors = pd.read_csv(out / "sectors.csv")
    samples = pd.read_csv(out / "wall_pressure_sectors.csv")
    opened = samples[samples.time > 0.2 + 1e-3]
    expected = opened.groupby(["band", "sector"]).pressure.max()
    got = sectors.set_index(["band", "sector"]).discharge_max_pressure
    pd.testing.assert_series_equal(got.sort_index(), expected.sort_index(), check_names=False)
    for b in summary["bands"]:
        assert got.loc[b["band"]].max() >= b["max_dynamic_pressure"] - 1e-9


@needs_chromium
def test_chromium_shows_the_flow_rate_and_en_within_the_first_screen(en_report, tmp_path):
    """At 1280 x 900 CSS pixels the card's flow-rate and EN rows end above 900 px; no console error."""
    _, out = en_report
    seen = render(out / "report.html", tmp_path / "card.png", tmp_path, width=1280, height=900,
                  boxes=("#card-flow", "#card-en", "#card-profile"))
    assert seen["console"] == []
    for row in ("#card-flow", "#card-en"):
        top, bottom = seen["boxes"][row]
        assert 0 < top < bottom <= 900, (row, top, bottom)


@needs_liggghts
@pytest.mark.engine
def test_a_real_run_s_card_and_wall_map(small_run):
    """The small engine run: its report.html opens with the card, whose flow rate is the summary's,
    and shows the wall unrolled; its planned bed is the one the engine inserted."""
    _, folder, record, summary = small_run
    page = (folder / "results" / "report.html").read_text()
    rows = card_rows(page)
    assert rows["flow"][1].split(" (")[0] in page and "health" in rows
    assert summary["planned_bed"]["grains"] == summary["particles_inserted"] + summary["fill_losses"]
    assert summary["initial_mass_kg"] == pytest.approx(summary["planned_bed"]["mass_kg"], rel=0.02)
    assert (folder / "results" / "wall_map.png").stat().st_size > 10_000
    assert page.index('id="summary-card"') < page.index('alt="wall_map.png"')


@needs_chromium
@pytest.mark.parametrize("report", ["paper_a", "paper_b"])
def test_chromium_renders_the_committed_claims_reports_without_console_errors(report, tmp_path):
    """The claims reports in reports/ (make paper-a-report / paper-b-report): no console error, no
    request leaving the page, every figure decoded."""
    page = QUICK.parents[1] / "reports" / report / "report.html"
    seen = render(page, tmp_path / f"{report}.png", tmp_path, width=1280, height=900)
    assert seen["console"] == [] and leaving(seen["requests"], page) == []
    assert seen["images"] and all(done and w > 0 for done, w in seen["images"])
