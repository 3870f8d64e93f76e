"""What a LIGGGHTS step costs, by what the deck holds: sensor meshes and the neighbour skin.

``make bench-deck`` (resumable: a (variant, repeat) already in the table is not run again). The
case is the accuracy benchmark's (benchmarks/cases/accuracy_small.yaml: 1000 grains of paper B's
7 sizes) at dt = 0.1 t_c and 1/100 of the stiffness (candidate E1e-2_dt0.1), rendered by ``siloflow render``; each variant runs the deck's fill
stage only (its first ``run``: insertion and the grains' fall onto the floor, the stage where the
reference spends a third of its steps), on 2 ranks, one engine job at a time, repeats interleaved.
The time is LIGGGHTS' own "Loop time" of that run (no start-up, no mesh reading).

Variants:
- ``sensors 5x4`` (the case: 5 bands x 4 sectors = 20 sensor meshes, skin 0.5 r_max): the baseline;
- ``sensors 5x3``: 15 sensor meshes (the smallest number of sectors a case may have);
- ``one side wall``: ``outputs.results`` without ``wall_pressure``: the same facets as one plain mesh;
- ``skin 0.25 r`` and ``skin 1.0 r``: the baseline deck with the ``neighbor`` line's skin changed
  (a deck edit for this measurement only: siloflow writes 0.5 r_max).

Writes benchmarks/results/deck_costs/deck_costs.csv (every timing) and summary.csv, deck_costs.png
(mean loop time with the standard deviation of the repeats, and the ratio to the baseline).
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runs import LOOP, ROOT  # noqa: E402

sys.path.insert(0, str(ROOT))
from siloflow.atomic_files import write_text  # noqa: E402
from siloflow.engine.liggghts.deck import before_stage_run  # noqa: E402
from siloflow.engine.liggghts.engine import LiggghtsEngine  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "deck_costs"
WORK = ROOT / "benchmarks" / "work" / "deck_costs"
CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"
NEIGHBOR = re.compile(r"^neighbor\s+(\S+)\s+bin$", re.M)
REPEATS = 3
RANKS = 2
#: the settings measured (pinned, not the published fast profile: the table resumes on them)
TIMESTEP_FRACTION, STIFFNESS_SCALE = 0.1, 0.01


def case_of(variant: str) -> dict:
    """The case fields a variant renders (the skin variants render the baseline)."""
    data = yaml.safe_load(CASE.read_text())
    data["engine"] = {**{k: v for k, v in data["engine"].items() if k != "profile"}, "profile": "custom",
                      "timestep_fraction": TIMESTEP_FRACTION, "stiffness_scale": STIFFNESS_SCALE, "ranks": RANKS}
    if variant == "sensors 5x3":
        data["sensors"] = {**data["sensors"], "sectors": 3}
    if variant == "one side wall":
        data["outputs"] = {**data["outputs"], "results": ["flow_rate", "force_balance", "porosity", "coordination"]}
    data["name"] = "deck_cost_" + re.sub(r"[^a-z0-9]+", "_", variant)
    return data


def fill_deck(folder: Path, skin_factor: float | None) -> str:
    """The rendered deck cut after its fill stage's ``run``; the skin times ``skin_factor`` / 0.5
    when given (siloflow's skin is 0.5 r_max)."""
    text = (folder / "in.liggghts").read_text()
    head = before_stage_run(text, "fill")
    deck = text[:text.index("\n", len(head)) + 1]         # with the fill's run line
    if skin_factor is not None:
        skin = float(NEIGHBOR.search(deck).group(1))
        deck = NEIGHBOR.sub(f"neighbor        {skin * skin_factor / 0.5:.8g} bin", deck, count=1)
    return deck


VARIANTS = {"sensors 5x4": None, "sensors 5x3": None, "one side wall": None, "skin 0.25 r": 0.25, "skin 1.0 r": 1.0}


def render_folder(case_path: Path, folder: Path) -> None:
    """``siloflow render`` of the case file into ``folder`` (LIGGGHTS), through the engine's API."""
    from siloflow.case_file import load_case
    from siloflow.engine import get_engine
    case = load_case(case_path)
    get_engine("liggghts").prepare(case, folder, keep=[case_path])


def prepare(variant: str) -> Path:
    """The variant's deck folder (rendered once) with ``fill.in``."""
    base = variant if VARIANTS[variant] is None else "sensors 5x4"
    data = case_of(base)
    folder = WORK / data["name"]
    if not (folder / "in.liggghts").is_file():
        WORK.mkdir(parents=True, exist_ok=True)
        case_path = WORK / f"{data['name']}.yaml"
        case_path.write_text(yaml.safe_dump(data))
        render_folder(case_path, folder)
    name = "fill_" + re.sub(r"[^a-z0-9]+", "_", variant) + ".in"
    (folder / name).write_text(fill_deck(folder, VARIANTS[variant]))
    return folder / name


def loop_time(deck: Path) -> tuple[float, int, int]:
    """Run ``deck`` in its folder on RANKS ranks; (loop time s, steps, atoms) of its run."""
    log = deck.with_suffix(".log")
    cmd = LiggghtsEngine().command(RANKS, deck=deck.name, log=log.name)
    subprocess.run(cmd, cwd=deck.parent, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, check=True)
    m = LOOP.findall(log.read_text())
    if not m:
        raise SystemExit(f"{log}: no loop time")
    t, _, steps, atoms = m[-1]
    return float(t), int(steps), int(atoms)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    table = OUT / "deck_costs.csv"
    rows = pd.read_csv(table).to_dict(orient="records") if table.is_file() else []
    done = {(r["variant"], int(r["repeat"])) for r in rows}
    decks = {v: prepare(v) for v in VARIANTS}
    for k in range(REPEATS):
        for v in VARIANTS:                     # interleaved: a slow spell of the machine hits all
            if (v, k) in done:
                continue
            t, steps, atoms = loop_time(decks[v])
            rows.append({"variant": v, "repeat": k, "loop_s": t, "steps": steps, "atoms": atoms})
            write_text(table, pd.DataFrame(rows).to_csv(index=False))
            print(f"{v:14s} repeat {k}: {t:.2f} s for {steps} steps", flush=True)
    report(pd.DataFrame(rows))


def report(df: pd.DataFrame) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    g = df.groupby("variant", sort=False).loop_s
    summary = pd.DataFrame({"runs": g.size(), "loop_mean_s": g.mean(), "loop_sd_s": g.std(ddof=1)})
    base = summary.loc["sensors 5x4"]
    summary["ratio_to_baseline"] = summary.loop_mean_s / base.loop_mean_s
    # the ratio's relative sd from both means' relative standard errors
    rel = lambda r: (r.loop_sd_s / r.loop_mean_s) / r.runs ** 0.5  # noqa: E731
    summary["ratio_sd"] = summary.ratio_to_baseline * (summary.apply(rel, axis=1) ** 2 + rel(base) ** 2) ** 0.5
    summary.loc["sensors 5x4", "ratio_sd"] = 0.0
    write_text(OUT / "summary.csv", summary.to_csv())
    print(summary.round(3).to_string())
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.barh(summary.index, summary.loop_mean_s, xerr=summary.loop_sd_s, color="tab:blue")
    for y, (m, r) in enumerate(zip(summary.loop_mean_s, summary.ratio_to_baseline)):
        ax.text(m, y, f"  x{r:.2f}", va="center")
    ax.set_xlabel("fill stage, LIGGGHTS loop time on 2 ranks (s)")
    ax.invert_yaxis()
    ax.set_title("accuracy_small at dt 0.1 t_c, stiffness 1/100: what the deck costs")
    fig.tight_layout()
    fig.savefig(OUT / "deck_costs.png", dpi=120)


if __name__ == "__main__":
    main()
