"""The numerical-stability envelope of a case (``siloflow stability``): short runs over a grid of
time-step fractions x stiffness scales (x dust density scales where the case has dust), each
through the fill's impacts, a settled bed and a burst of discharge, with the instability guard on
(``siloflow.guard``: speed, overlap, escapes, energy growth, NaN) and the engine's own failures.

Each point is ``stable`` (the run completed), ``unstable`` (the guard or the engine stopped it for an
instability: the signal is recorded) or ``inconclusive`` (it failed for another reason). Every run
also reports the largest overlap and speed it reached against the guard's limits, so a stable
point shows how near the edge it ran. Resumable through ``siloflow.run_table``.
"""
from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Callable, Optional

from .case import PROFILE_FIELDS
from .run_table import run_name

FRACTIONS = (0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0)
STIFFNESS = (1.0, 1e-2, 1e-4)
#: kinetic/potential energy at which a burst's bed counts as settled enough to go on
BURST_SETTLE_RATIO = 1e-3
#: failures that are instabilities, by what the failure says (besides the guard's own)
_UNSTABLE = [("escape", re.compile(r"left the box|Lost atoms|without passing the outlet|through a wall", re.I)),
             ("timestep_check", re.compile(r"time-step is .* of (rayleigh|hertz)", re.I)),
             ("crash", re.compile(r"SIGSEGV|segmentation", re.I))]
_GUARD = re.compile(r"siloflow's guard \((\w+)\)")


#: most values one axis of the grid may have (every value is a run for each value of the other axes)
MAX_AXIS_VALUES = 20
#: the case schema's seed range (``siloflow.case.Case.seed``)
MAX_SEED = 2 ** 31 - 1


def check_options(fractions, stiffness, dust_scales=None, seed: Optional[int] = None, burst: float = 0.1) -> None:
    """Refuse a grid or option no envelope run could use, before anything runs: ``SetupError``
    naming the option (``siloflow stability``'s ``--fractions``, ``--stiffness``, ``--dust``,
    ``--seed``, ``--burst``). Each axis: 1 to :data:`MAX_AXIS_VALUES` distinct values in its range."""
    from .errors import SetupError

    def number(v) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    axes = (("--fractions", fractions, 1e-3, 1.0, "time-step fractions of the critical time"),
            ("--stiffness", stiffness, 1e-8, 1.0, "stiffness scales"),
            ("--dust", dust_scales, 1.0, 1e6, "dust density scales"))
    for option, values, lo, hi, what in axes:
        if values is None and option == "--dust":
            continue
        values = [values] if isinstance(values, (str, bytes)) else list(values)
        if not values:
            raise SetupError(f"{option}: give at least one value ({what})")
        if len(values) > MAX_AXIS_VALUES:
            raise SetupError(f"{option}: {len(values)} values, at most {MAX_AXIS_VALUES} (each is a run for every "
                             "point of the other axes)")
        bad = [v for v in values if not (number(v) and lo <= v <= hi)]
        if bad:
            raise SetupError(f"{option}: {what} must be numbers in [{lo:g}, {hi:g}], not "
                             + ", ".join(map(repr, bad[:5])))
        repeated = sorted({float(v) for v in values if sum(float(w) == float(v) for w in values) > 1})
        if repeated:
            raise SetupError(f"{option}: {', '.join(f'{v:g}' for v in repeated)} given more than once")
    if seed is not None and not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed <= MAX_SEED):
        raise SetupError(f"--seed: must be a whole number from 0 to {MAX_SEED} (a case's seed), not {seed!r}")
    if not (number(burst) and 1e-3 <= burst <= 10.0):
        raise SetupError(f"--burst: the discharge burst must be from 0.001 to 10 s, not {burst!r}")


def burst_case(base: dict, fraction: float, stiffness: float, seed: int, burst: float,
               dust_scale: Optional[float] = None) -> dict:
    """The case fields of one envelope point: the case at this time-step fraction and stiffness,
    the settling capped and loose, a short static window, ``burst`` s of discharge, the flow rate
    its only result (the leanest deck), the guard on with the case's limits."""
    data = copy.deepcopy(base)
    engine = {k: v for k, v in data.get("engine", {}).items() if k not in PROFILE_FIELDS}
    guard = {**engine.get("guard", {}), "enabled": True}
    engine.update(profile="custom", timestep_fraction=fraction, stiffness_scale=stiffness, guard=guard)
    settle = dict(data["fill"].get("settle", {}))
    interval = settle.get("check_interval", 0.02)
    settle.update(ke_pe_ratio=max(settle.get("ke_pe_ratio", 1e-6), BURST_SETTLE_RATIO),
                  max_time=min(settle.get("max_time", 1.0), 10 * interval))
    data["fill"] = {**data["fill"], "settle": settle}
    data["discharge"] = {k: v for k, v in data["discharge"].items() if k in ("opening", "empty_fraction")}
    data["discharge"]["duration"] = burst
    sample = min(data.get("outputs", {}).get("sample_interval", 0.01), burst / 4)
    data["outputs"] = {"results": ["flow_rate"], "sample_interval": sample, "figures": False}
    data["fill"]["settle"]["static_window"] = max(settle.get("static_window", 0.0), 2.5 * sample)
    if dust_scale is not None:
        data["particles"]["dust"] = {**data["particles"]["dust"], "density_scale": dust_scale}
    tag = f"dt{fraction:g}-E{stiffness:g}" + (f"-dust{dust_scale:g}" if dust_scale is not None else "")
    data.update(engine=engine, seed=seed, name=run_name(base["name"], tag, f"s{seed}"))
    return data


def classify(reason: str) -> tuple[str, str]:
    """(state, signal) of a failed point from its failure message."""
    m = _GUARD.search(reason)
    if m:
        return "unstable", m.group(1)
    for signal, pattern in _UNSTABLE:
        if pattern.search(reason):
            return "unstable", signal
    return "inconclusive", ""


def peaks(folder: Path) -> dict:
    """The largest speed (m/s) and pair overlap (fraction of the smallest grain radius) a run reached
    (the guard's ``guard_peaks`` in its run record), each against the guard's limit (``speed_ratio``,
    ``overlap_ratio``: 1 = at the limit); NaN for a run that never started. From its row
    (:func:`siloflow.run_row.run_row`)."""
    from .run_row import run_row
    row = run_row(folder)
    return {k: row[k] for k in ("max_speed", "max_overlap_fraction", "speed_ratio", "overlap_ratio")}


def run_envelope(case_file: Path, out: Path, fractions=FRACTIONS, stiffness=STIFFNESS, dust_scales=None,
                 seed: Optional[int] = None, burst: float = 0.1,
                 report: Callable[[str], None] = lambda s: None) -> list[dict]:
    """Run every grid point not yet in ``out/runs.csv``; return all rows."""
    from .case_file import case_from_dict
    from .errors import CaseError, SetupError
    from .run_table import PlannedRun, case_digest, run_missing
    from .study_case import read_study_case
    check_options(fractions, stiffness, dust_scales, seed, burst)
    base, case = read_study_case(case_file)
    seed = case.seed if seed is None else seed
    has_dust = getattr(case.particles, "dust", None) is not None
    if dust_scales is not None and not has_dust:
        raise CaseError([("--dust", "the case has no dust (particles.dust) to scale")], str(case_file))
    dusts = list(dust_scales) if dust_scales is not None else [None]
    planned = [PlannedRun(key={"timestep_fraction": f, "stiffness_scale": s, "dust_scale": ds, "seed": seed},
                          case=burst_case(base, f, s, seed, burst, ds))
               for ds in dusts for s in sorted(stiffness, reverse=True) for f in sorted(fractions)]
    for p in planned:                   # every point's case is valid before the first one runs
        try:
            case_from_dict(p.case)
        except CaseError as exc:
            raise CaseError(exc.problems, f"{case_file}, envelope point {p.case['name']}") from None

    def numbers(folder) -> dict:
        from .run_row import run_row
        row = run_row(folder)
        return {k: row[k] for k in ("wall_s", "max_speed", "max_overlap_fraction", "speed_ratio", "overlap_ratio")}

    def measure(folder):
        return {"signal": "", **numbers(folder)}

    def failed(folder, reason):
        state, signal = classify(reason)
        return {"signal": signal, "verdict": state, **numbers(folder)}

    rows = run_missing(out, planned, measure, failed, report, case_digest(base))
    if not rows:
        raise SetupError("no point of the envelope ran: each was refused before it started (the reasons are "
                         "above); nothing to conclude")
    for r in rows:
        r["verdict"] = "stable" if r["state"] == "complete" else r.get("verdict") or classify(r["reason"])[0]
        if (r.get("max_speed") or 0.0) < 0:      # LIGGGHTS' max over no grain (-1e20), kept by older rows
            r.update(max_speed=math.nan, speed_ratio=math.nan)
    return rows


def safe_edges(rows: list[dict]) -> list[dict]:
    """Per stiffness (and dust) scale: the largest stable fraction below the smallest unstable one
    (``safe``), that unstable fraction (``unstable``) and their ratio (``margin``: how far the step
    can grow from the safe edge before it fails; NaN when no point was unstable)."""
    import pandas as pd
    df = pd.DataFrame(rows)
    out = []
    for (s, ds), g in df.groupby(["stiffness_scale", df["dust_scale"].fillna(-1)]):
        unstable = g[g.verdict == "unstable"].timestep_fraction
        first_bad = float(unstable.min()) if len(unstable) else math.nan
        ok = g[(g.verdict == "stable") & ((g.timestep_fraction < first_bad) if len(unstable) else True)]
        safe = float(ok.timestep_fraction.max()) if len(ok) else math.nan
        out.append({"stiffness_scale": float(s), "dust_scale": None if ds == -1 else float(ds), "safe": safe,
                    "unstable": first_bad, "margin": first_bad / safe if len(ok) and len(unstable) else math.nan,
                    "signal": ",".join(sorted(set(g[g.verdict == "unstable"].signal.astype(str))))})
    return out


def conclude(out: Path, rows: list[dict]) -> list[dict]:
    """``envelope.csv`` (every point), ``edges.json`` (:func:`safe_edges`) and ``envelope.png``."""
    import pandas as pd
    from .atomic_files import write_text
    out = Path(out)
    edges = safe_edges(rows)
    write_text(out / "envelope.csv", pd.DataFrame(rows).to_csv(index=False))
    clean = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in e.items()} for e in edges]
    write_text(out / "edges.json", json.dumps(clean, indent=1) + "\n")
    envelope_figure(pd.DataFrame(rows), edges, out / "envelope.png")
    return edges


def envelope_figure(df, edges: list[dict], path: Path) -> None:
    """Time-step fraction (x, log) against the grid's rows (y: one per stiffness scale, and dust
    density scale where the case has dust): stable points green circles, unstable red crosses labelled
    with their signal, inconclusive grey squares; the safe edge of each row as a bar."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    def key(stiffness, dust) -> tuple:
        dust = None if dust is None or dust != dust else float(dust)
        return float(stiffness), dust

    keys = [key(s, d) for s, d in zip(df.stiffness_scale, df["dust_scale"] if "dust_scale" in df else [None] * len(df))]
    rows = sorted(set(keys), key=lambda k: (-k[0], k[1] or 0.0))
    y_of = {k: i for i, k in enumerate(rows)}
    labels = [f"stiffness x{s:g}" + (f", dust x{d:g}" if d is not None else "") for s, d in rows]
    ys = [y_of[k] for k in keys]
    fig = Figure(figsize=(7.5, 1.6 + 0.55 * len(rows)))
    ax = fig.add_subplot()
    for verdict, style in (("stable", dict(marker="o", color="tab:green")),
                           ("unstable", dict(marker="x", color="tab:red")),
                           ("inconclusive", dict(marker="s", color="0.6"))):
        pick = [i for i, v in enumerate(df.verdict) if v == verdict]
        ax.scatter([df.timestep_fraction.iloc[i] for i in pick], [ys[i] for i in pick], s=60, label=verdict, **style)
        if verdict == "unstable":
            for i in pick:
                ax.annotate(str(df.signal.iloc[i]), (df.timestep_fraction.iloc[i], ys[i]), fontsize=7,
                            xytext=(3, 4), textcoords="offset points")
    for e in edges:
        if e["safe"] is not None and math.isfinite(e["safe"]):          # None: read back from edges.json
            y = y_of[key(e["stiffness_scale"], e.get("dust_scale"))]
            ax.plot([e["safe"]] * 2, [y - 0.3, y + 0.3], color="k", lw=2)
    ax.set_xscale("log")
    ax.set_yticks(range(len(rows)), labels)
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlabel("time step / critical time")
    ax.set_title("stability envelope (bar: largest safe time step)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    from postprocess.report.figures import save_figure
    save_figure(fig, path, dpi=120)
