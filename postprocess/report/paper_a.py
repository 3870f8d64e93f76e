"""Paper A's claims report (reports/paper_a/): the claims table, Table 3's layout, the pressure at
monitoring points 1, 3 and 5 against time for both models (Fig. 11-12's layout) and the two
models' force chains side by side at one moment of discharge (Fig. 14's).

:func:`write_paper_a_report` writes it from what ``postprocess.paper_a`` measured;
:func:`regenerate_paper_a_report` writes it again, byte for byte, from the ``data/`` it left."""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from siloflow.atomic_files import read_json, write_text
from siloflow.errors import ReadError

from ..paper_a import (
    FIGURE_POINTS,
    MODELS,
    MeasuredClaim,
    chains_from_table,
    chains_table,
)
from .claims_report import claims_blocks, write_claims_report
from .figures import LineCollection
from .text import Table, Text

#: the data folder beside the report, from which it is regenerated
DATA = "data"

TITLE = "Paper A: the multi-element wheat model against spheres"


def pressure_plot(series: pd.DataFrame):
    """Normal pressure against time since opening at points 1, 3, 5, both models (Fig. 11-12)."""
    fig, axes = plt.subplots(1, len(FIGURE_POINTS), figsize=(5 * len(FIGURE_POINTS), 4), sharey=True)
    for ax, point in zip(axes, FIGURE_POINTS):
        for m, style in zip(MODELS, ("-", "--")):
            part = series[(series.model == m) & (series.point == point)]
            ax.plot(part.time_s, part.pressure_Pa, style, lw=0.9, label=f"{m} model")
        ax.axvline(0.0, color="k", lw=0.6)
        ax.set(title=f"monitoring point {point}", xlabel="time since the outlet opened (s, paper's silo)")
    axes[0].set_ylabel("normal wall pressure (Pa, paper's silo)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def chains_plot(chains: dict, moment: float):
    """The two models' force chains side by side (line width ~ normal force, one scale for both)."""
    fig, axes = plt.subplots(1, len(chains), figsize=(5.5 * len(chains), 6))
    top = max((float(c.forces.max()) for c in chains.values() if len(c.forces)), default=1.0)
    for ax, (m, c) in zip(axes, chains.items()):
        if len(c.forces):
            ax.add_collection(LineCollection(c.segments * 1000, linewidths=3.0 * c.forces / top, colors="k"))
            ax.autoscale()
        ax.set_aspect("equal")
        ax.set(title=f"{m} model: {len(c.forces)} contacts in the mid-plane slice", xlabel="x (mm)", ylabel="z (mm)")
    fig.suptitle(f"force chains {moment:.3g} s after the outlet opened (line width ~ normal force, max {top:.3g} N)")
    fig.tight_layout()
    return fig


def lead_text(meta: dict) -> list[str]:
    """The report's opening paragraphs: what ran, at which scale, how numbers and verdicts are made."""
    seeds = meta["seeds"]
    return [
        f"Scale: {meta['scale']}. Runs: {seeds['spheres']} of the sphere model "
        f"({', '.join(meta['cases']['spheres'])}) and {seeds['clumps']} of the multi-element model "
        f"({', '.join(meta['cases']['clumps'])}); the silo's lengths are x {meta['length_scale']:g} the paper's. "
        f"Pressures are scaled to the paper's silo by x {meta['pressure_scale']:g} (Janssen: the wall pressure "
        f"grows with the silo's size at the same bulk solid) and times by x {1 / meta['time_scale']:.3g} "
        "(Froude: t ~ sqrt(L/g)); the grains are not scaled, so a quick silo is only "
        f"{meta['grains_across']:.0f} grains wide and the scaling is an approximation.",
        "Each number is a mean with its 95 % interval (Student's t on the samples the row names). With one run "
        "of a model the samples are places in that run (the two side walls, the bed's layers, the measuring "
        "regions) or nearby frames: few and correlated, so the intervals are wide and many comparisons stay "
        "'not resolved'. More seeds (--seeds) narrow them. A verdict is computed (postprocess/claims.py): "
        "'holds' when the claim is true over the whole interval, 'fails' when false over all of it, "
        "'not resolved' otherwise; 'shown' rows set our number beside the paper's without a claim.",
        f"Made by: {meta['command']}",
    ]


def write_paper_a_report(folder, claims: list[MeasuredClaim], numbers: dict, meta: dict, series: pd.DataFrame,
                         chains: dict) -> list[Path]:
    """Write reports/paper_a (``folder``): report.md, report.html, the figures, and ``data/``
    (Table 3, the pressure series, the force chains, claims.json) from which
    :func:`regenerate_paper_a_report` writes it again."""
    folder = Path(folder)
    table_3 = pd.DataFrame(numbers["table_3"])
    tables = {"table_3.csv": table_3, "pressure_series.csv": series,
              **{f"force_chains_{m}.csv": chains_table(c) for m, c in chains.items()}}
    figures = {"pressure_points.png": pressure_plot(series),
               "force_chains.png": chains_plot(chains, numbers["contacts_time_after_open_s"])}
    after = [Text("Table 3's layout (maximum dynamic wall pressure, Pa; ours scaled to the paper's silo, with the "
                  "95 % interval's ends):"),
             Table(list(table_3.columns), [[_cell(v) for v in rec] for rec in table_3.itertuples(index=False)])]
    blocks = claims_blocks(TITLE, [Text(t) for t in lead_text(meta)], [c.row() for c in claims], after,
                           list(figures))
    written = write_claims_report(folder, TITLE, blocks, figures, tables, results_dir=DATA)
    write_text(folder / DATA / "claims.json", json.dumps(
        {"claims": [c.to_json() for c in claims], "numbers": numbers, "meta": meta}, indent=1, allow_nan=False) + "\n")
    return written + [folder / DATA / "claims.json"]


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def regenerate_paper_a_report(folder) -> list[Path]:
    """Write the report in ``folder`` again from its ``data/`` (no run)."""
    folder = Path(folder)
    try:
        data = read_json(folder / DATA / "claims.json", "paper A's claims", allow_nan=True)
        series = pd.read_csv(folder / DATA / "pressure_series.csv")
        chains = {m: chains_from_table(pd.read_csv(folder / DATA / f"force_chains_{m}.csv")) for m in MODELS}
        claims = [MeasuredClaim.from_json(d) for d in data["claims"]]
    except (OSError, ValueError, KeyError, ReadError) as exc:
        raise ReadError(f"{folder}: no report data to regenerate from ({exc})") from None
    return write_paper_a_report(folder, claims, data["numbers"], data["meta"], series, chains)
