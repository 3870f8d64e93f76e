"""Issue 60 item 3: the page of a sweep (``siloflow sweep`` writes OUT/report.html) and of several runs
(``siloflow beverloo -o X.csv`` writes X.html): the variants' table with a link to each run's own page,
Beverloo's fit with its data and its band, flow rate and wall loads against the swept value; the page
is replaced only while it holds what siloflow wrote; Chromium renders it with no request leaving it
and no console error. A fake 3-orifice sweep (plus a clogged run) through the CLI, its runs written by
a fake runner in the sweep's worker processes: no engine runs here."""
from __future__ import annotations

import base64
import hashlib
import io
import json
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import matplotlib.image
import pandas as pd
import pytest
from typer.testing import CliRunner

from postprocess.numbers import with_error
from postprocess.report.figures import plt
from postprocess.report.sweep_page import swept_figures
from siloflow import sweep
from siloflow.atomic_files import write_json
from siloflow.case_file import load_case
from siloflow.cli import app
from siloflow.cli.study_commands import write_sweep_report
from siloflow.derived import derive
from siloflow.errors import SetupError
from siloflow.run_folder import RECORD_NAME, RESULTS, RunFolder, write_status

from conftest import QUICK
from test_reliability_round4_beverloo import CLOG, law, steady
from test_report_html import DATA_PNG, leaving, needs_chromium, render
from test_sweep import FakeEngine

runner = CliRunner(env={"COLUMNS": "400"})

#: the sweep's orifice radii (m) and each run's flow rate over Beverloo's (C 0.58, k 1.5): the smallest clogs
NOISE = {0.005: None, 0.006: 1.012, 0.007: 0.991, 0.008: 1.004}
RUN_PAGE = "<!DOCTYPE html><html><head><title>a run</title></head><body><h1>a run</h1></body></html>\n"


def fake_run(case_file, folder, cache, resuming):
    """A finished run of a variant, in its worker as ``sweep.run_variant`` (no engine): its plan, a
    record, its status, a summary whose flow rate follows Beverloo (C 0.58, k 1.5, d 3 mm, rho_b 1500 kg/m3) times
    :data:`NOISE` (the smallest orifice clogged: 2 g/s over its whole discharge), three wall bands,
    and its own page."""
    case = load_case(case_file)
    folder = Path(folder)
    (folder / RESULTS).mkdir(parents=True)
    run = RunFolder(folder)
    run.write_plan(derive(case))
    (folder / RECORD_NAME).write_text(json.dumps({
        "folder": str(folder), "engine": "fake", "command": ["fake"], "returncode": 0, "wall_time": 1.0,
        "stage_steps": {}, "inserted": 10, "settled_ke_pe": 1e-6, "completed": True,
        "fill_cache": {"key": "k", "hit": False}}))
    r = case.geometry.orifice_radius
    noise = NOISE[r]
    W = 0.002 if noise is None else law(r) * noise
    bands = [{"band": b, "z_mid": 0.025 + 0.05 * b, "static_pressure": p, "static_pressure_stderr": 0.02 * p,
              "max_dynamic_pressure": 1.5 * p + 1e5 * r, "dynamic_mean_pressure": 1.1 * p}
             for b, p in enumerate((900.0, 700.0, 300.0))]
    write_json(run.summary_file, {"flow_rate": {"rate": W, "stderr": 0.01 * W, "t_start": 0.3, "t_end": 0.8},
                                  "frame_analyses": {"bulk_density_kg_m3": 1500.0},
                                  "clogged": CLOG if noise is None else None, "steady_window_detected": steady(),
                                  "bands": bands, "force_balance": {"ratio": 0.99}})
    (folder / RESULTS / "report.html").write_text(RUN_PAGE)
    write_status(folder, "complete")                       # a sweep run again keeps it


def run_sweep_command(mp, out: Path, radii: str):
    """``siloflow sweep QUICK --set geometry.orifice_radius=<radii>`` with the fake engine and runs."""
    mp.setattr(sweep, "sweep_engine", lambda variants, need_binary=True: FakeEngine())
    mp.setattr(sweep, "run_variant", fake_run)
    return runner.invoke(app, ["sweep", str(QUICK), "--set", f"geometry.orifice_radius={radii}",
                               "--set", "engine.ranks=1", "--cores", "2", "-o", str(out)])


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """The 4-orifice sweep (one clogged) through the CLI, then ``siloflow beverloo`` on its table:
    (sweep folder, the sweep's output, the beverloo table's path)."""
    tmp = tmp_path_factory.mktemp("sweep_page")
    out = tmp / "sw"
    with pytest.MonkeyPatch.context() as mp:
        result = run_sweep_command(mp, out, "0.005,0.006,0.007,0.008")
    assert result.exit_code == 0, result.output
    bev = tmp / "fits" / "bev.csv"
    bev.parent.mkdir()
    fitted = runner.invoke(app, ["beverloo", str(out / "sweep.csv"), "-o", str(bev)])
    assert fitted.exit_code == 0, fitted.output
    return out, result.output, bev


class Page(HTMLParser):
    """A page's links (``a href``), images (``img src``, ``alt``) and every other URL-bearing attribute."""

    def __init__(self, text: str):
        super().__init__()
        self.links, self.images, self.other, self.tags = [], [], [], []
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        attrs = dict(attrs)
        if tag == "a":
            self.links.append(attrs.get("href"))
        elif tag == "img":
            self.images.append((attrs.get("alt"), attrs.get("src")))
        self.other += [(tag, k) for k in ("src", "href", "srcset", "action", "data", "poster", "background")
                       if k in attrs and not (tag == "a" and k == "href") and not (tag == "img" and k == "src")]


def section(page: str, heading: str) -> str:
    """The page's text from the heading ``<h2>heading</h2>`` to the next ``<h2>``."""
    return page.split(f"<h2>{heading}</h2>")[1].split("<h2>")[0]


def fit_statement(fit: dict) -> str:
    return f"C = {with_error(fit['C'], fit['C_stderr'])}, k = {with_error(fit['k'], fit['k_stderr'])}"


def check_self_contained(text: str, folder: Path) -> list[Path]:
    """No script, only data: PNG images, and links only relative ones to existing runs' report.html;
    returns the linked files."""
    page = Page(text)
    assert "script" not in page.tags and "<script" not in text.lower() and page.other == []
    assert page.images and all(src.startswith(DATA_PNG) for _, src in page.images)
    without_images = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", text)
    assert re.findall(r"https?:", without_images) == [] and "file:" not in without_images
    linked = []
    for href in page.links:
        assert not re.match(r"^[a-z][a-z0-9+.-]*:", href, re.I) and not href.startswith("/"), href
        path = (folder / unquote(href)).resolve()
        assert path.is_file() and path.name == "report.html" and path.parent.name == RESULTS, href
        linked.append(path)
    return linked


# ---------------------------------------------------------------- the sweep's page

def test_a_3_orifice_sweep_writes_a_page_with_the_variants_the_fit_and_its_figure(swept):
    out, output, bev = swept
    page_file = out / "report.html"
    assert f"page: {page_file}" in output
    text = page_file.read_text()
    table = pd.read_csv(out / "sweep.csv")
    names = table.name.tolist()
    clogged = names[0]                                   # the 5 mm orifice
    # the lead: the runs, complete, clogged
    assert "4 runs over geometry.orifice_radius = 0.005, 0.006, 0.007, 0.008: 4 complete, 0 failed" in text
    assert f"1 clogged (no steady flow rate; out of Beverloo's fit): {clogged}" in text
    # the variants' table: a row per run, its flow rate in g/s with its error, a working link per run
    variants = section(text, "Variants")
    assert variants.count("<tr>") == 1 + len(names)
    assert "<th>geometry.orifice_radius</th>" in variants and "engine.ranks" not in variants   # swept, not set once
    for row in table.to_dict("records"):
        cells = re.search(rf"<tr><td>{row['name']}</td>(.*?)</tr>", variants).group(1)
        assert cells.startswith(f"<td>{row['geometry.orifice_radius']:g}</td><td>complete</td>")
        assert f"<td>{with_error(row['flow_rate_kg_s'] * 1000, row['flow_rate_stderr_kg_s'] * 1000)}</td>" in cells
        assert ("<td>yes</td>" in cells) == (row["name"] == clogged)
        assert f'<a href="runs/{row["name"]}/results/report.html">report.html</a>' in cells
    linked = check_self_contained(text, out)
    assert sorted(linked) == sorted((out / "runs" / n / RESULTS / "report.html").resolve() for n in names)
    # Beverloo's fit: the numbers of siloflow beverloo on the same table, the clogged run left out
    fit = json.loads(bev.with_suffix(".json").read_text())
    assert fit["runs"] == 3 and fit["C"] == pytest.approx(0.58, rel=0.05) and fit["k"] == pytest.approx(1.5, rel=0.1)
    assert fit_statement(fit) in section(text, "Beverloo's fit")
    assert f"<li>3 runs fitted; rms relative residual {fit['rms_relative_residual']:.1%}</li>" in text
    assert f"<li>left out of the fit: {clogged}: its discharge clogged" in text
    assert "propagated from C and k with their covariance (delta method)" in text   # how the band is made, said
    # the figures: Beverloo's, and flow rate and wall loads against the orifice, embedded, decodable
    images = dict(Page(text).images)
    assert list(images) == ["beverloo.png", "vs_geometry.orifice_radius.png"]
    for src in images.values():
        png = base64.b64decode(src[len(DATA_PNG):])
        assert png.startswith(b"\x89PNG") and matplotlib.image.imread(io.BytesIO(png)).shape[0] > 300
    assert "<figcaption>beverloo.png</figcaption>" in text
    # the table of results, below
    assert "<h3>sweep.csv</h3>" in text
    # sweep.json records the page as siloflow's
    record = json.loads((out / "sweep.json").read_text())
    assert record["files"]["report.html"] == [hashlib.sha256(page_file.read_bytes()).hexdigest()]


def test_the_beverloo_page_beside_its_table(swept, tmp_path):
    """``siloflow beverloo -o X.csv``: X.html with the fit (the numbers of X.json), each run's data
    with a link to its page (relative to X.html's folder), the figure; replaced while unchanged, an
    edited one refused with nothing written."""
    out, _, bev = swept
    page_file = bev.with_suffix(".html")
    text = page_file.read_text()
    fit = json.loads(bev.with_suffix(".json").read_text())
    assert fit_statement(fit) in text and "<title>Beverloo's law over 3 runs</title>" in text
    runs = section(text, "The runs")
    assert runs.count("<tr>") == 1 + 4
    linked = check_self_contained(text, page_file.parent)
    assert len(linked) == 4 and all(p.is_relative_to((out / "runs").resolve()) for p in linked)
    assert '<a href="../sw/runs/' in runs                                  # relative to the page's folder
    assert "its discharge clogged" in runs and "<h3>bev.csv</h3>" in text
    assert [alt for alt, _ in Page(text).images] == ["beverloo.png"]
    assert fit["page_sha256"] == [hashlib.sha256(page_file.read_bytes()).hexdigest()]
    # again: the page it wrote is replaced
    again = runner.invoke(app, ["beverloo", str(out / "sweep.csv"), "-o", str(bev)])
    assert again.exit_code == 0 and f"page: {page_file}" in again.output, again.output
    # an edited page, or one siloflow did not write, is refused before anything is written
    mine = tmp_path / "mine.csv"
    mine.with_suffix(".html").write_text("my notes")
    for target in (bev, mine):
        target.with_suffix(".html").write_text("my notes")
        target.unlink(missing_ok=True)
        refused = runner.invoke(app, ["beverloo", str(out / "sweep.csv"), "-o", str(target)])
        assert refused.exit_code == 1 and "does not overwrite it" in refused.output, refused.output
        assert target.with_suffix(".html").read_text() == "my notes" and not target.exists()


def test_a_refused_fit_says_why_and_draws_no_beverloo_figure(tmp_path, monkeypatch):
    out = tmp_path / "sw2"
    result = run_sweep_command(monkeypatch, out, "0.006,0.007")
    assert result.exit_code == 0 and f"page: {out / 'report.html'}" in result.output, result.output
    text = (out / "report.html").read_text()
    assert "<p>Beverloo's fit: not given: a Beverloo fit needs at least 3 runs" in text
    assert [alt for alt, _ in Page(text).images] == ["vs_geometry.orifice_radius.png"]
    assert "beverloo.png" not in text and section(text, "Variants").count("<tr>") == 3
    check_self_contained(text, out)


def test_the_page_is_replaced_only_while_siloflow_s_and_an_unreadable_summary_is_a_note(tmp_path, monkeypatch):
    out = tmp_path / "sw"
    assert run_sweep_command(monkeypatch, out, "0.005,0.006,0.007,0.008").exit_code == 0
    page_file = out / "report.html"
    first = page_file.read_text()
    # a run's summary unreadable: the sweep resumed (nothing to run) still writes the page, naming it
    broken = out / "runs" / "quick-002" / RESULTS / "summary.json"
    broken.write_text("{not json")
    result = run_sweep_command(monkeypatch, out, "0.005,0.006,0.007,0.008")
    assert result.exit_code == 0 and "page:" in result.output, result.output
    text = page_file.read_text()
    assert text != first and "quick-002" in text and "its numbers are left out of this page and of the fit" in text
    row = re.search(r"<tr><td>quick-002</td>(.*?)</tr>", section(text, "Variants")).group(1)
    assert "<td>complete</td><td>-</td><td>-</td>" in row                 # no flow rate, no clog verdict
    assert "a Beverloo fit needs at least 3 runs" in text                 # two flowing runs left
    # an edited page: refused before the sweep runs, and by the page writer; never overwritten
    page_file.write_text(text + "<!-- my notes -->")
    edited = page_file.read_text()
    result = run_sweep_command(monkeypatch, out, "0.005,0.006,0.007,0.008")
    assert result.exit_code == 1 and "report.html (edited since siloflow wrote it)" in result.output, result.output
    with pytest.raises(SetupError, match="edited since siloflow wrote it"):
        write_sweep_report(out)
    assert page_file.read_text() == edited
    # moved out, the page is written again
    page_file.rename(tmp_path / "kept.html")
    assert write_sweep_report(out) == (out / "report.html").absolute() and page_file.read_text() == text


def test_swept_figures_draw_each_seed_and_the_mean_per_value_for_each_swept_field():
    """Two swept fields (a number, a text) x 2 seeds, one run clogged: a figure per field, every run
    drawn, a mean line per value of the other field over the steady runs; a field set once draws none."""
    rows, summaries = [], {}
    for r in (0.006, 0.008):
        for fill in ("rain", "pour"):
            for seed in (1, 2):
                name = f"q-{len(rows):03d}"
                rows.append({"run": f"/nowhere/{name}", "name": name, "geometry.orifice_radius": r,
                             "fill.protocol": fill, "engine.ranks": 1, "seed": seed, "status": "complete"})
                clogged = name == "q-007"
                summaries[name] = {"flow_rate": {"rate": r * (1 + 0.02 * seed) * (1.1 if fill == "pour" else 1.0),
                                                 "stderr": 1e-4}, "clogged": CLOG if clogged else None,
                                   "bands": [{"static_pressure": 500.0 + 100 * seed, "static_pressure_stderr": 5.0,
                                              "max_dynamic_pressure": 900.0 + 1e4 * r}]}
    table = pd.DataFrame(rows)
    figures = swept_figures(table, summaries)
    try:
        assert list(figures) == ["vs_geometry.orifice_radius.png", "vs_fill.protocol.png"]
        rate = figures["vs_geometry.orifice_radius.png"].axes[0]
        means = {line.get_label(): line.get_ydata() for line in rate.get_lines() if "mean" in line.get_label()}
        steady = table[table.name != "q-007"]
        for fill in ("rain", "pour"):
            expected = [1000 * sum(summaries[n]["flow_rate"]["rate"] for n in grp.name) / len(grp)
                        for _, grp in steady[steady["fill.protocol"] == fill].groupby("geometry.orifice_radius")]
            assert means[f"mean at each value (fill.protocol = {fill})"] == pytest.approx(expected)   # g/s
        ticks = [t.get_text() for t in figures["vs_fill.protocol.png"].axes[0].get_xticklabels()]
        assert ticks == ["rain", "pour"]
        loads = figures["vs_geometry.orifice_radius.png"].axes[1]
        assert loads.get_ylabel() == "wall pressure (Pa)"
    finally:
        for fig in figures.values():
            plt.close(fig)


# ---------------------------------------------------------------- headless Chromium

@needs_chromium
def test_chromium_renders_the_pages_with_no_request_leaving_them_and_no_console_error(swept, tmp_path):
    out, _, bev = swept
    page = out / "report.html"
    seen = render(page, tmp_path / "sweep.png", tmp_path, width=1200, height=2400)
    assert page.resolve().as_uri() in seen["requests"] and leaving(seen["requests"], page) == [], seen["requests"]
    assert len(seen["images"]) == 2 and all(done and w > 0 for done, w in seen["images"]), seen["images"]
    # the console check, shown to catch errors on a page that makes them
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><body><script>console.error("boom")</script>'
                   '<script>throw new Error("thrown")</script><img src="missing.png"></body></html>')
    assert seen["console"] == []
    assert render(bev.with_suffix(".html"), tmp_path / "bev.png", tmp_path, width=1200, height=900)["console"] == []
    caught = " | ".join(render(bad, tmp_path / "bad.png", tmp_path, width=400, height=300)["console"])
    assert "boom" in caught and "thrown" in caught and "missing.png" in caught, caught
