"""results/report.html, written by the report layer (``postprocess.report``) beside report.md:
the same strings as report.md, every figure embedded as a base64 PNG, every text escaped, no
script, no link, no request leaving the page (checked in headless Chromium, with a page that
does make requests to show the check catches them). No engine: the run is built in memory
(``test_janssen_fit.FakeRun``) or the results are given directly."""
from __future__ import annotations

import base64
import copy
import fcntl
import html
import io
import json
import os
import re
import select
import shutil
import signal
import subprocess
import time
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest

import postprocess.first_results as fr
from postprocess.report import post_process
from postprocess.report.figures import plt
from postprocess.report import CONTENT_SECURITY_POLICY, flow_rate_line, report_blocks, write_report
from test_janssen_fit import FakeRun

CHROMIUM = shutil.which("chromium")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian package chromium; "
                                    "make install-engine installs it)")
DATA_PNG = "data:image/png;base64,"


@pytest.fixture(scope="module")
def fake_report(tmp_path_factory):
    """analyse() on the in-memory run: (summary, results folder)."""
    run = FakeRun(tmp_path_factory.mktemp("report"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fr, "RunOutputs", lambda folder: run)
        summary = post_process(run.folder)
    return summary, run.run.results


def with_en(summary: dict) -> dict:
    """``summary`` with an EN 1991-4 comparison whose settled bed mobilises mu_eff = 0.135 of mu_w = 0.5."""
    s = copy.deepcopy(summary)
    bands = [{"band": b["band"], "en_p_hf": 900.0, "static_over_p_hf": b["static_pressure"] / 900.0, "en_p_he": 1000.0,
              "max_dynamic_over_p_he": b["max_dynamic_pressure"] / 1000.0, "dem_discharge_factor": b["discharge_factor"],
              "static_verdict": "above EN p_hf", "static_causes": "the wall mobilises little",
              "dynamic_verdict": "within EN p_he"} for b in s["bands"]]
    s["design_loads"] = {"computed": True, "solid": "the simulated grains", "classification": "slender", "C_h": 1.15,
                         "bands": bands, "bed_state": {
                             "protocol": "rain", "wall_friction_share": 0.3, "janssen_share_en": 0.7, "mu_eff": 0.135,
                             "K_eff": 0.4, "K_bed": None, "K_bed_ci": None, "K_en": 0.6, "mu_en": 0.5, "mu_w": 0.5}}
    return s


class Links(HTMLParser):
    """Every tag and every attribute that can make a browser fetch something."""
    FETCHING = {"src", "href", "srcset", "action", "formaction", "data", "poster", "background", "xlink:href",
                "manifest", "ping", "codebase", "archive", "longdesc", "cite", "usemap", "icon"}

    def __init__(self):
        super().__init__()
        self.tags, self.urls = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.urls += [(tag, k, v) for k, v in attrs if k in self.FETCHING]


def parsed(text: str) -> Links:
    p = Links()
    p.feed(text)
    p.close()
    return p


def markdown_strings(md: str) -> list[str]:
    """The strings of report.md as an HTML page shows them: bullets, paragraphs and table cells."""
    out = []
    for line in md.splitlines():
        if not line.strip() or line.startswith("|---"):
            continue
        if line.startswith("|"):
            out += [c.strip() for c in line.strip().strip("|").split(" | ")]
        else:
            out.append(re.sub(r"^(# |## |- |  - )", "", line))
    return out


# ---------------------------------------------------------------- report.html, no browser

def test_report_html_holds_report_md_and_its_figures_and_nothing_else(fake_report):
    summary, out = fake_report
    page = (out / "report.html").read_text()
    md = (out / "report.md").read_text()
    line = flow_rate_line(summary["flow_rate"])
    assert line in md and line[2:] in page                       # the headline, the same string
    for s in markdown_strings(md):                               # every number, error and flag of report.md
        assert html.escape(s, quote=False) in page, s
    assert f'<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">' in page
    links = parsed(page)
    assert "script" not in links.tags and "link" not in links.tags and "<script" not in page.lower()
    assert links.urls and all(tag == "img" and k == "src" and v.startswith(DATA_PNG) for tag, k, v in links.urls), \
        [(t, k, v[:40]) for t, k, v in links.urls]
    without_images = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", page)
    assert re.findall(r"http(?!-equiv)", without_images) == [] and "file://" not in without_images
    # every figure the run wrote, embedded byte for byte
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["first_results.png", "wall_map.png"]
    embedded = [base64.b64decode(v[len(DATA_PNG):]) for _, _, v in links.urls]
    # the wall unrolled right below the summary card, the other figures after the report's text
    assert embedded == [(out / "wall_map.png").read_bytes(), (out / "first_results.png").read_bytes()]
    assert page.index('id="summary-card"') < page.index('alt="wall_map.png"') < page.index("The run in full")
    # every table written beside it, as an HTML table (a long one as its statistics)
    for name in ("bands.csv", "discharge.csv", "wall_pressure.csv", "wall_pressure_sectors.csv"):
        assert f"<h3>{name}</h3>" in page
    bands = pd.read_csv(out / "bands.csv")
    section = page.split("<h3>bands.csv</h3>")[1].split("<h3>")[0]
    assert section.count("<tr") == len(bands) + 1 and section.count("<th") >= len(bands.columns)
    long = pd.read_csv(out / "wall_pressure.csv")
    assert f"{len(long)} rows x {len(long.columns)} columns; per-column statistics" in page


def test_static_pressures_state_the_beds_mobilisation_once_per_table(fake_report, tmp_path):
    """With an EN comparison whose bed state has mu_eff, the band table's caption and the EN
    table's caption say it; without one, nothing is said."""
    summary, _ = fake_report
    md = (fake_report[1] / "report.md").read_text()
    assert "mobilises" not in md                        # a slab: no EN comparison, no force balance of a cylinder
    note = "the bed mobilises mu_eff = 0.14 on the wall, 0.27 of mu_w = 0.5 (fill protocol: rain)"
    write_report(tmp_path, "run", with_en(summary), {}, {})
    md = (tmp_path / "report.md").read_text()
    assert md.count(note) == 2, md
    assert f"+/- its batch-means standard error; {note}. Dynamic:" in md
    assert f"design_vs_dem.csv, design_loads.png. DEM static: {note}." in md
    assert (tmp_path / "report.html").read_text().count(note) == 2
    older = with_en(summary)
    del older["design_loads"]["bed_state"]["mu_w"]      # a summary written before mu_w was kept
    assert "0.27 of EN's mu = 0.5" in "\n".join(b.text for b in report_blocks(older, "run") if hasattr(b, "text"))


def test_every_text_is_escaped(fake_report, tmp_path):
    """A run folder and a band named with markup: shown as text, never as markup."""
    summary = with_en(fake_report[0])
    summary["bands"][0]["band"] = "<b>x</b>"
    summary["design_loads"]["bands"][0]["band"] = "<b>x</b>"
    summary["design_loads"]["bed_state"]["protocol"] = "rain & <i>pour</i>"
    table = pd.DataFrame({"band": ["<b>x</b>"], "static_pressure": [1.0]})
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    name = "<img src=x onerror=alert(1)> & co"
    write_report(tmp_path, name, summary, {"bands.csv": table}, {"fig.png": fig})
    page = (tmp_path / "report.html").read_text()
    assert "<b>" not in page and "<i>" not in page and "<img src=x" not in page and "onerror=alert(1)>" not in page
    assert page.count("&lt;b&gt;x&lt;/b&gt;") >= 3                 # band table, EN table, bands.csv
    assert "<title>Run report: &lt;img src=x onerror=alert(1)&gt; &amp; co</title>" in page
    assert "<h1>Run report: &lt;img src=x onerror=alert(1)&gt; &amp; co</h1>" in page
    assert "rain &amp; &lt;i&gt;pour&lt;/i&gt;" in page
    links = parsed(page)
    assert [(t, k) for t, k, _ in links.urls] == [("img", "src")] and links.urls[0][2].startswith(DATA_PNG)
    assert base64.b64decode(links.urls[0][2][len(DATA_PNG):]) == (tmp_path / "fig.png").read_bytes()
    assert (tmp_path / "report.md").read_text().startswith(f"# Run report: {name}\n")


# ---------------------------------------------------------------- headless Chromium

class DevTools:
    """Headless Chromium driven over ``--remote-debugging-pipe`` (the DevTools protocol: JSON
    messages ending in a NUL byte, commands on its fd 3, answers and events on its fd 4)."""

    def __init__(self, profile: Path, log: Path):
        cmd_r, self.cmd_w = os.pipe()
        self.out_r, out_w = os.pipe()
        a, b = (fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (cmd_r, out_w))
        os.close(cmd_r)
        os.close(out_w)
        argv = [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--remote-debugging-pipe",
                "--no-first-run", f"--user-data-dir={profile}", "about:blank"]
        with open(log, "wb") as err:
            self.proc = subprocess.Popen(["bash", "-c", f'exec "$@" 3<&{a} 4>&{b} {a}<&- {b}>&-', "bash", *argv],
                                         pass_fds=(a, b), stdin=subprocess.DEVNULL, stdout=err, stderr=err,
                                         start_new_session=True)
        os.close(a)
        os.close(b)
        self.buf, self.events, self.last = b"", [], 0

    def _message(self, deadline: float) -> dict:
        while b"\0" not in self.buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.out_r], [], [], left)[0]:
                raise TimeoutError("no answer from chromium")
            chunk = os.read(self.out_r, 1 << 20)
            if not chunk:
                raise EOFError("chromium closed its DevTools pipe")
            self.buf += chunk
        msg, _, self.buf = self.buf.partition(b"\0")
        return json.loads(msg)

    def send(self, method: str, params: dict | None = None, session: str | None = None, timeout: float = 15.0):
        self.last += 1
        os.write(self.cmd_w, json.dumps({"id": self.last, "method": method, "params": params or {},
                                         **({"sessionId": session} if session else {})}).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            msg = self._message(deadline)
            if msg.get("id") == self.last:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]
            self.events.append(msg)

    def wait_for(self, method: str, timeout: float = 15.0) -> dict:
        deadline = time.monotonic() + timeout
        while not any(e.get("method") == method for e in self.events):
            self.events.append(self._message(deadline))
        return next(e for e in self.events if e.get("method") == method)

    def close(self) -> None:
        try:
            self.send("Browser.close", timeout=5.0)
            self.proc.wait(timeout=10)
        except (OSError, EOFError, TimeoutError, RuntimeError, subprocess.TimeoutExpired):
            pass
        finally:
            if self.proc.poll() is None:
                os.killpg(self.proc.pid, signal.SIGKILL)      # the browser this test started, and its children
                self.proc.wait()
            os.close(self.cmd_w)
            os.close(self.out_r)


def console_errors(events: list[dict]) -> list[str]:
    """The errors a page gave its console (DevTools events): console.error and assert calls, uncaught
    exceptions, and the browser's own error entries (a resource that failed to load, a request the
    Content-Security-Policy refused)."""
    out = []
    for e in events:
        method, params = e.get("method"), e.get("params", {})
        if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            out.append(" ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
        elif method == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            out.append(str(details.get("exception", {}).get("description") or details.get("text", "exception")))
        elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
            out.append(f"{params['entry'].get('text', '')} ({params['entry'].get('url', '')})")
    return out


def render(page: Path, screenshot: Path, tmp: Path, width: int = 1200, height: int = 3000, boxes=()) -> dict:
    """Load ``page`` (file://) in headless Chromium at ``width`` x ``height`` CSS pixels, save a
    screenshot; return {requests: every URL the page asked for (Network.requestWillBeSent, the
    page's own included, whether or not a policy then blocked it), images: [(loaded, natural width)],
    console: :func:`console_errors`, boxes: {selector: [top, bottom] in CSS pixels from the page's top,
    or None where nothing matches} of each CSS selector in ``boxes``}."""
    browser = DevTools(tmp / "profile", tmp / "chromium.log")
    try:
        target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for method in ("Network.enable", "Page.enable", "Runtime.enable", "Log.enable"):
            browser.send(method, session=session)
        browser.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                            "mobile": False}, session=session)
        browser.send("Page.navigate", {"url": page.resolve().as_uri()}, session=session)
        browser.wait_for("Page.loadEventFired")
        images = browser.send("Runtime.evaluate", {"expression": "JSON.stringify(Array.from(document.images).map("
                                                   "i => [i.complete, i.naturalWidth]))", "returnByValue": True},
                              session=session)["result"]["value"]
        found = browser.send("Runtime.evaluate", {"expression": "JSON.stringify(" + json.dumps(list(boxes)) + ".map(s => {"
                                                  "const e = document.querySelector(s); if (!e) return null; "
                                                  "const r = e.getBoundingClientRect(); "
                                                  "return [r.top + window.scrollY, r.bottom + window.scrollY]; }))",
                                                  "returnByValue": True}, session=session)["result"]["value"]
        png = browser.send("Page.captureScreenshot", {"format": "png"}, session=session)["data"]
        screenshot.write_bytes(base64.b64decode(png))
        requests = [e["params"]["request"]["url"] for e in browser.events if e.get("method") == "Network.requestWillBeSent"]
    finally:
        browser.close()
    return {"requests": requests, "images": json.loads(images), "console": console_errors(browser.events),
            "boxes": dict(zip(boxes, json.loads(found)))}


def leaving(requests: list[str], page: Path) -> list[str]:
    """The requests that leave the page: all but its own file:// URL and data: URLs."""
    own = page.resolve().as_uri()
    return [u for u in requests if u != own and not u.startswith("data:")]


@needs_chromium
def test_chromium_renders_the_report_and_no_request_leaves_it(fake_report, tmp_path):
    _, out = fake_report
    page = out / "report.html"
    shot = tmp_path / "report.png"
    seen = render(page, shot, tmp_path)
    assert page.resolve().as_uri() in seen["requests"], seen["requests"]
    assert leaving(seen["requests"], page) == []
    assert seen["images"] and all(done and w > 0 for done, w in seen["images"]), seen["images"]   # decoded
    assert seen["console"] == []
    assert shot.stat().st_size > 20_000
    rgb = (matplotlib.image.imread(shot)[:, :, :3] * 255).astype(np.uint32)
    assert rgb.shape == (3000, 1200, 3)
    assert len(np.unique(rgb[..., 0] << 16 | rgb[..., 1] << 8 | rgb[..., 2])) > 50   # text, tables, a figure


@needs_chromium
def test_chromium_check_catches_a_page_that_asks_for_a_file_or_the_network(tmp_path):
    """The check above on pages that do ask: a relative image (a file beside the page) and an
    http one are caught, and so are both behind the report's own Content-Security-Policy
    (blocked there, but still asked for: the check is stricter than the policy)."""
    buf = io.BytesIO()
    matplotlib.image.imsave(buf, np.eye(4), format="png")
    png = base64.b64encode(buf.getvalue()).decode()
    body = f'<h1>bad</h1><img src="{DATA_PNG}{png}"><img src="other.png"><img src="http://example.com/x.png">'
    for name, head in (("plain.html", ""), ("csp.html", f'<meta http-equiv="Content-Security-Policy" '
                                                         f'content="{CONTENT_SECURITY_POLICY}">')):
        page = tmp_path / name
        page.write_text(f"<!DOCTYPE html><html><head>{head}</head><body>{body}</body></html>")
        seen = render(page, tmp_path / f"{name}.png", tmp_path, width=400, height=300)
        assert sorted(leaving(seen["requests"], page)) == sorted([(tmp_path / "other.png").as_uri(),
                                                                  "http://example.com/x.png"]), seen["requests"]
        assert seen["console"], name         # the missing file (and the refused requests) are console errors
        assert any(u.startswith(DATA_PNG) for u in seen["requests"])


def test_verdicts_say_what_every_band_shares_once_and_keep_each_band_s_own_numbers():
    """The EN verdicts of many bands: a cause every differing band has, and the dynamic verdicts'
    common explanation, are stated once; each band keeps its ratio and its own causes."""
    from postprocess.report import markdown, verdict_blocks
    shared, note = "the wall mobilises mu_eff = 0.27", "the DEM maximum is a peak"
    verdicts = [{"band": k, "static_verdict": f"above EN p_hf ({2 + k / 10:.2f} x, 5 standard errors)",
                 "static_causes": "; ".join([shared, f"Janssen gives {300 - k} Pa here"]
                                            + (["the band is inside the surface's cone"] if k == 2 else [])),
                 "dynamic_verdict": f"above EN p_he ({1.5 + k / 10:.2f} x): {note}"} for k in range(3)]
    verdicts.append({"band": 3, "static_verdict": "no EN filling pressure at this height", "static_causes": "",
                     "dynamic_verdict": "no comparison (no EN discharge pressure)"})
    text = markdown(verdict_blocks(verdicts))
    assert text.count(shared) == 1 and text.count(note) == 1, text
    for k in range(3):
        assert f"- band {k}: static above EN p_hf ({2 + k / 10:.2f} x, 5 standard errors); cause: Janssen gives " \
               f"{300 - k} Pa here" in text and f"above EN p_he ({1.5 + k / 10:.2f} x)" in text, text
    assert text.count("inside the surface's cone") == 1 and "band 3: static no EN filling pressure" in text
    # one band alone: nothing is "common", its line says everything
    alone = markdown(verdict_blocks(verdicts[:1]))
    assert shared in alone and note in alone and "common" not in alone


def test_the_console_prints_every_band_s_static_pressure_with_its_error_the_fit_and_the_verdict_counts(fake_report):
    """What ``siloflow run`` prints beside the flow rate (issue 35: static pressures with their
    errors, the Janssen fit, the EN verdicts): the same cells as report.md, and the counts of the
    verdicts with their range of ratios."""
    from postprocess.report import console_lines, static_cell
    summary = with_en(fake_report[0])
    lines = console_lines(summary)
    static = next(line for line in lines if line.startswith("static wall pressure by band"))
    assert "the bed mobilises mu_eff = 0.14 on the wall, 0.27 of mu_w = 0.5" in static
    for b in summary["bands"]:
        assert f"{b['band']}: {static_cell(b).removesuffix(' Pa')}" in static
    fit = (summary.get("frame_analyses") or {}).get("janssen_static")
    assert any(line.startswith("Janssen fit of the settled profile") for line in lines) == bool(fit), lines
    ratios = [b["static_over_p_hf"] for b in summary["design_loads"]["bands"]]
    en = next(line for line in lines if line.startswith("EN 1991-4"))
    assert f"{len(ratios)} above ({min(ratios):.2f}-{max(ratios):.2f} x), 0 agrees, 0 below" in en, en
    dynamic = [b["max_dynamic_over_p_he"] for b in summary["design_loads"]["bands"]]
    assert f"0 above, {len(dynamic)} within ({min(dynamic):.2f}-{max(dynamic):.2f} x)" in en, en
    summary["frame_analyses"] = {"janssen_static": {"error": "too few bands"}}
    assert "Janssen fit of the settled profile: not fitted: too few bands" in console_lines(summary)
