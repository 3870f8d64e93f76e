"""Paper B's claims report (issue 38): the claims computed on synthetic tables whose answers are
known (they must hold, fail, or stay unresolved), the report writer, the committed quick-scale
report regenerated from its committed results, and the paper scale's refusal without --yes.
No engine runs."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from postprocess import paper_b as pb
from postprocess.claims import FAILS, HOLDS, NOT_RESOLVED, SHOWN, ClaimRow

ROOT = Path(__file__).resolve().parents[1]
RB = 1 / 64


def synthetic_tables(seed: int = 1, noise: float = 0.01, phi_bulk: float = 0.60, vz_power: float = 0.5,
                     kinetic_scale_with_R: bool = True, contact_depends_on_R: bool = False,
                     batches: int = 5) -> dict:
    """The tables of three runs (R = 4.5, 5.5, 6.5 r_b) built from paper B's laws: v_z(0) = a R^vz_power,
    v_z(r) = v_z(0) sqrt(1 - (r/R)^2), phi(r) = phi_c (1 - 0.2 (r/R)^2), Wf = rho_p pi R^2 times the
    profiles' integral, Wr = Wf, a contact pressure rising from the outlet (1 - exp(-z / 2R)), a
    kinetic pressure peaking at h_c = R (or at a fixed height), partial kinetic pressure
    proportional to r^2 per size while phi_j goes as r^3; ``noise`` relative Gaussian noise per batch
    (the contact pressure's profile independent of R unless ``contact_depends_on_R``)."""
    rng = np.random.default_rng(seed)
    rho_p, g, Rc = 7520.0, 10.0, 16 * RB
    keys = (4.5, 5.5, 6.5)
    radii = RB * (0.5 + np.arange(2, 9) / 16)      # the deck's seven sizes, r_b/2 + r_b/8 to r_b
    t = {n: [] for n in pb.TABLES}

    def jitter(size=None):
        return 1 + noise * rng.standard_normal(size)

    for k in keys:
        R = k * RB
        vc0 = 1.2 * (R / (5 * RB)) ** vz_power
        phic0 = 0.5
        t[pb.RUNS].append({"R_over_rb": k, "R": R, "rb": RB, "Rc": Rc, "rho_p": rho_p, "g": g, "dt": 2.5e-5,
                           "t_open": 1.0, "t_start": 1.3, "t_end": 2.8, "batches": batches, "width_flow": RB,
                           "width_stress": RB, "nr": 50, "nz": 150, "particles": 8000, "initial_mass": 500.0,
                           "discharged_mass": 100.0, "run_flow_rate": 1.0, "run_flow_rate_stderr": 0.01,
                           "settled_bulk_solid_fraction": 0.61, "engine_wall_s": 600.0})
        edges = np.linspace(1.3, 2.8, batches + 1)
        x = np.linspace(0.025, 0.975, 20)
        z = np.arange(-0.05, 8 * R, 0.004)          # the grid reaches below the outlet plane, as a run's does
        h_c = R if kinetic_scale_with_R else 5 * RB
        for b in range(batches):
            vc, phic = vc0 * jitter(), phic0 * jitter()
            # W = rho_p phi_c v_c 2 pi R^2 int_0^1 (1 - 0.2 x^2) sqrt(1 - x^2) x dx = ... (1/3 - 0.2 * 2/15)
            wf = rho_p * phic * vc * 2 * math.pi * R ** 2 * (1 / 3 - 0.2 * 2 / 15)
            hc_b = h_c * jitter()
            t[pb.BATCHES].append({"R_over_rb": k, "batch": b, "t0": edges[b], "t1": edges[b + 1], "frames": 15,
                                  "Wf": wf * jitter(), "Wr": wf * jitter(), "surface_speed": 0.1,
                                  "phi_bulk": phi_bulk * (1 + 0.3 * noise * rng.standard_normal()),
                                  "phi_c": phic, "v_c": vc, "h_c": hc_b})
            for xi, e in zip(x, jitter(len(x)) - 1):
                t[pb.OUTLET].append({"R_over_rb": k, "batch": b, "r": xi * R, "r_over_R": xi,
                                     "solid_fraction": phic * (1 - 0.2 * xi ** 2) * (1 + 0.1 * e),
                                     "v_z": -vc * math.sqrt(1 - xi ** 2) * (1 + 0.1 * e)})
            pc = 3000 * (1 - np.exp(-np.clip(z, 0, None) / (2 * (R if contact_depends_on_R else 5.5 * RB)))) * jitter(len(z)) ** 0.1
            pk = 2.0 * np.exp(-((z - hc_b) / (0.8 * h_c)) ** 2) * jitter(len(z)) ** 0.1
            for zi, c, kk in zip(z, pc, pk):
                t[pb.AXIAL].append({"R_over_rb": k, "batch": b, "height": zi, "contact_pressure": c,
                                    "kinetic_pressure": kk, "solid_fraction": 0.55, "v_z": -0.5})
            share = radii ** 2 / np.sum(radii ** 2)
            phis = 0.55 * radii ** 3 / np.sum(radii ** 3)
            for r, s, f in zip(radii, share, phis):
                for zi, kk in zip(z[::5], pk[::5]):
                    t[pb.SPECIES].append({"R_over_rb": k, "batch": b, "radius": r, "height": zi,
                                          "kinetic_pressure": kk * s * jitter() ** 0.1, "solid_fraction": f})
            tt = np.linspace(1.0, 3.0, 21)
            for ti in tt:
                t[pb.FLOW].append({"R_over_rb": k, "time": ti, "Wf_kg_s": wf, "Wr_kg_s": wf})
        for zi in z[::10]:
            for ri in np.linspace(0.005, Rc, 5):
                t[pb.MAPS].append({"R_over_rb": k, "height": zi, "r": ri, "contact_pressure": 1000.0,
                                   "kinetic_pressure": 1.0, "solid_fraction": 0.55, "v_z": -0.5})
    return {n: pd.DataFrame(v) for n, v in t.items()}


def verdicts(tables) -> dict:
    return {r.claim: r.verdict for r in pb.analyse(tables).rows}


def find(v: dict, start: str) -> str:
    (key,) = [k for k in v if k.startswith(start)]
    return v[key]


def test_claims_hold_on_tables_built_from_paper_b_laws():
    v = verdicts(synthetic_tables(noise=0.004))
    for claim in ("Wr(t)", "The flow quickly", "Flow rate collapses", "No discontinuity", "Contact pressure nearly", "phi(r)/phi(0)", "v_z(r)/v_z(0) at",
                  "v_z(r)/v_z(0) =", "v_z(0) ~ sqrt(R)", "The kinetic-pressure peak height", "Contact pressure decreases",
                  "Kinetic pressure peaks", "Axial kinetic-pressure", "Kinetic pressure is orders",
                  "Partial kinetic pressure is larger", "Small particles", "Bulk solid fraction"):
        assert find(v, claim) == HOLDS, claim
    assert find(v, "Wf(t)") == SHOWN


def test_claims_fail_when_the_laws_are_broken():
    v = verdicts(synthetic_tables(phi_bulk=0.50, vz_power=1.0, kinetic_scale_with_R=False, contact_depends_on_R=True))
    assert find(v, "Contact pressure nearly") == FAILS
    assert find(v, "Bulk solid fraction") == FAILS
    assert find(v, "v_z(0) ~ sqrt(R)") == FAILS
    assert find(v, "The kinetic-pressure peak height") == FAILS
    assert find(v, "Axial kinetic-pressure") == FAILS


def test_claims_stay_unresolved_in_noise():
    v = verdicts(synthetic_tables(noise=0.25, phi_bulk=0.615))
    assert find(v, "Bulk solid fraction") == NOT_RESOLVED
    assert find(v, "v_z(0) ~ sqrt(R)") == NOT_RESOLVED
    assert find(v, "Flow rate collapses") == NOT_RESOLVED


def test_slab_solid_fraction_of_a_simple_cubic_lattice():
    # spheres of radius a on a cubic lattice of spacing 2a fill pi/6 of space
    a = 0.01
    g = np.arange(-0.2, 0.2001, 2 * a)
    pos = np.array([(x, y, z) for x in g for y in g for z in np.arange(a, 0.3, 2 * a)])
    pos = pos[np.hypot(pos[:, 0], pos[:, 1]) < 0.25]
    phi = pb.slab_solid_fraction(pos, np.full(len(pos), a), surface=0.25, spread=0.0, d=2 * a, radius=0.15)
    assert phi == pytest.approx(math.pi / 6, rel=0.02)


def test_batch_edges_and_slopes():
    e = pb.batch_edges(1.0, 2.0, 4)
    assert list(e) == pytest.approx([1.0, 1.25, 1.5, 1.75, 2.0])
    t = np.linspace(0, 1, 11)
    assert pb.slope_in(t, 3 * t + 1, 0.2, 0.8) == pytest.approx(3.0)
    with pytest.raises(ValueError):
        pb.batch_edges(1.0, 1.0, 4)


def test_claims_report_writer(tmp_path):
    from postprocess.report.claims_report import claims_blocks, write_claims_report

    rows = [ClaimRow("a | b", "paper 1", "ours 2", "+/- 1", HOLDS, "line\nbreak"),
            ClaimRow("c", "p", "o", "u", FAILS), ClaimRow("d", "p", "o", "u", NOT_RESOLVED),
            ClaimRow("e", "p", "o", "-", SHOWN)]
    written = write_claims_report(tmp_path, "T <x>", claims_blocks("T <x>", [], rows), tables={"t.csv": pd.DataFrame({"a": [1]})})
    md = (tmp_path / "report.md").read_text()
    assert "| a / b | paper 1 | ours 2 | +/- 1 | holds | line break |" in md
    assert "3 claims tested: 1 hold, 1 fail, 1 not resolved; 1 rows shown without a test." in md
    html = (tmp_path / "report.html").read_text()
    assert "<title>T &lt;x&gt;</title>" in html and "<td>not resolved</td>" in html
    assert (tmp_path / "results" / "t.csv").is_file() and tmp_path / "report.html" in written


def test_the_full_report_from_synthetic_tables(tmp_path):
    from postprocess.report.paper_b import FIGURES, write_paper_b_report

    tables = synthetic_tables()
    study = {"scale": "quick", "deck": "decks/paper_b_quick.yaml", "why": "synthetic", "runs": []}
    write_paper_b_report(tmp_path, pb.analyse(tables), study, tables)
    md = (tmp_path / "report.md").read_text()
    assert all(f"![{f}]({f})" in md for f in FIGURES) and all((tmp_path / f).is_file() for f in FIGURES)
    back = pb.read_tables(tmp_path / "results")
    assert [r.verdict for r in pb.analyse(back).rows] == [r.verdict for r in pb.analyse(tables).rows]


def _strip_images(html: str) -> str:
    return re.sub(r'src="data:image/png;base64,[^"]*"', 'src=""', html)


@pytest.mark.skipif(not (ROOT / "reports" / "paper_b" / "results" / pb.RUNS).is_file(),
                    reason="no committed paper-B results")
def test_committed_report_regenerates_from_committed_results(tmp_path):
    """`make paper-b-report`: the committed report.md (and report.html but its images) is what the
    committed result tables give."""
    from siloflow import reproduce_paper_b as driver

    committed = ROOT / "reports" / "paper_b"
    driver.report_from_results(committed / "results", tmp_path)
    assert (tmp_path / "report.md").read_text() == (committed / "report.md").read_text()
    assert _strip_images((tmp_path / "report.html").read_text()) == _strip_images(
        (committed / "report.html").read_text())


def test_paper_scale_refuses_without_yes(tmp_path, capsys, monkeypatch):
    from siloflow import reproduce_paper_b as driver

    ran = []
    monkeypatch.setattr(driver, "run_sweep", lambda *a, **k: ran.append(a))
    rc = driver.main(["--scale", "paper", "--work", str(tmp_path / "w"), "--rate", "1.0e5"])
    out = capsys.readouterr().out
    assert rc == 2 and not ran
    assert "particle-steps" in out and "core-hours" in out and "--yes" in out and "disk" in out


def test_the_study_record_names_runs_from_the_checkout(tmp_path, monkeypatch):
    """The committed study.json names the coarse-graining runs relative to the checkout it runs in
    (the current folder; a path outside it stays as it is), not by this machine's absolute path."""
    import pandas as pd

    from postprocess.paper_b import RUNS
    from siloflow.reproduce_paper_b import SCALES, study_record
    checkout = tmp_path / "checkout"
    checkout.mkdir()
    monkeypatch.chdir(checkout)
    inside = checkout / "runs" / "paper_b_quick" / "sweep" / "runs" / "x-000" / "results" / "cg"
    cg = {"runs": [{"folder": str(inside), "R": 0.07}, {"folder": str(tmp_path / "cg"), "R": 0.08}]}
    record = study_record(SCALES["quick"], [], {RUNS: pd.DataFrame(columns=["R_over_rb", "R", "particles"])}, cg)
    assert [r["folder"] for r in record["cg_scaling"]["runs"]] == [
        "runs/paper_b_quick/sweep/runs/x-000/results/cg", str(tmp_path / "cg")]
