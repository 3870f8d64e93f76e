"""``make paper-b SCALE=quick|paper`` (issue 38): paper B's polydisperse silo at three apertures
that share one fill, coarse-grained, and the claims report ``reports/paper_b/`` (report.md,
report.html, figures, and the small result tables it is made from).

    python -m siloflow.paper_b --scale quick            # run what is missing, post-process, report
    python -m siloflow.paper_b --scale paper [--yes]    # the paper's size: prints the cost, stops unless --yes
    python -m siloflow.paper_b --from-results reports/paper_b/results   # the report from committed results

What it runs: the scale's deck (``decks/paper_b_quick.yaml`` or ``decks/paper_b.yaml``) with the
outputs paper B needs (no wall-pressure sensors, which cost time and which paper B does not read:
``docs/skipping.md``), swept over the apertures (``siloflow sweep --set geometry.orifice_radius=...``)
with one fill for all (the fill cache: paper B shrinks the grains after settling, then opens the
outlet), then ``siloflow cg`` and ``siloflow cg-scaling`` on the runs. Resumable: a finished run,
its cg and its extracted results are kept. The claims are computed by ``postprocess.paper_b`` and
written by ``postprocess.report.claims_report``.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import yaml

from .atomic_files import write_text

ROOT = Path(__file__).resolve().parents[1]
#: where the report goes, and the result tables it is made from
REPORT_DIR = ROOT / "reports" / "paper_b"
RESULTS_DIR_NAME = "results"
#: what paper B reads of a run: no wall pressure (sensor meshes cost 1.5x the time), the dumps of
#: the free surface (Wr), the bulk solid fraction and the coarse-graining (particles and contacts)
PAPER_B_RESULTS = ["flow_rate", "force_balance", "free_surface", "porosity", "coarse_graining"]


@dataclass(frozen=True)
class Scale:
    """One scale of the study: the deck, the apertures (in r_b, the largest radius), the dump
    interval (s), the batches of the steady window, and the kernel widths (in r_b) of the flow
    fields (phi, v_z) and of the stress fields."""

    name: str
    deck: str
    apertures_rb: tuple
    dump_interval: float
    batches: int
    width_flow_rb: float
    width_stress_rb: float
    why: str
    engine: dict | None = None      # engine fields that replace the deck's


SCALES = {
    "quick": Scale(
        "quick", "decks/paper_b_quick.yaml", (4.5, 5.5, 6.5), 0.02, 5, 1.0, 1.0,
        "R = 4.5, 5.5 and 6.5 r_b: the quick silo (Rc = 16 r_b, 8,000 grains) holds an outlet up to "
        "about 0.4 Rc; the smallest is 9 r_b = 5.5 mean grain diameters wide, above the 3D clogging "
        "range (about 4-5 diameters, docs/results.md), and the three span a factor 1.44 in R for the "
        "v_z(0) ~ sqrt(R) and h_c ~ R fits. Kernel width w = r_b for every field: at R/r_b = 4.5-6.5 "
        "paper B's w = 2 r_b for phi and v_z would smooth the outlet profile over a third to a half of "
        "R, and w = r_b/2 for the pressures leaves too few grains per kernel at 8,000 grains (paper B's "
        "Fig. 9 finds h_c invariant to w). Time step t_c/10 instead of the deck's t_c/50 and one MPI rank: "
        "the accuracy benchmark (docs/accuracy.md) measured dt = 0.1 t_c within its 3 % flow-rate "
        "tolerance, and on this shared 2-core machine one rank runs faster than two (MPI ranks spin "
        "while they wait).", {"ranks": 1, "timestep_fraction": 0.1}),
    "paper": Scale(
        "paper", "decks/paper_b.yaml", (8.0, 10.0, 12.0), 0.02, 10, 2.0, 0.5,
        "R = 8, 10 and 12 r_b (paper B: 12 r_b among others), paper B's kernel widths: w = 2 r_b for "
        "phi and v_z, w = r_b/2 for the pressures."),
}


def rb_of(deck_data: dict) -> float:
    """The largest grain radius r_b (m) of a paper-B case."""
    return float(max(deck_data["particles"]["radii"]))


def study_case(scale: Scale) -> dict:
    """The scale's deck with the outputs paper B reads and the scale's dump interval."""
    data = yaml.safe_load((ROOT / scale.deck).read_text())
    data["outputs"] = {**data.get("outputs", {}), "results": list(PAPER_B_RESULTS),
                       "dump_interval": scale.dump_interval}
    if scale.engine:
        data["engine"] = {**data.get("engine", {}), **scale.engine}
    return data


def orifice_set(scale: Scale, data: dict) -> str:
    """``--set geometry.orifice_radius=...``: the apertures in metres."""
    rb = rb_of(data)
    return "geometry.orifice_radius=" + ",".join(f"{a * rb:.10g}" for a in scale.apertures_rb)


def write_study_case(scale: Scale, work: Path) -> Path:
    """Write the study's case (unchanged when it is already there: the sweep resumes)."""
    path = work / f"paper_b_{scale.name}.yaml"
    text = (f"# paper B's {scale.name} study (siloflow/paper_b.py): {scale.deck} with the outputs it reads\n"
            + yaml.safe_dump(study_case(scale), sort_keys=False))
    work.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        write_text(path, text)
    return path


def siloflow_cmd(*args) -> list[str]:
    return [sys.executable, "-m", "siloflow.cli", *map(str, args)]


def run_sweep(scale: Scale, work: Path) -> Path:
    """``siloflow sweep`` over the apertures (resumes a stopped one); the sweep folder."""
    case = write_study_case(scale, work)
    out = work / "sweep"
    data = yaml.safe_load(case.read_text())
    cmd = siloflow_cmd("sweep", case, "--set", orifice_set(scale, data), "--cores",
                       (scale.engine or {}).get("ranks", data.get("engine", {}).get("ranks", 2)), "-o", out)
    print("$", " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scale", choices=sorted(SCALES), default="quick")
    ap.add_argument("--work", type=Path, help="run folder (default runs/paper_b_<scale>)")
    ap.add_argument("--yes", action="store_true", help="run the paper scale after its cost estimate")
    ap.add_argument("--runs-only", action="store_true", help="run the sweep, nothing else")
    args = ap.parse_args(argv)
    scale = SCALES[args.scale]
    work = args.work or ROOT / "runs" / f"paper_b_{scale.name}"
    run_sweep(scale, work)
    return 0


if __name__ == "__main__":
    sys.exit(main())
