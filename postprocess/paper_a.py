"""Paper A's claims (the multi-element wheat model against plain spheres) measured on run folders.

Paper A (``../shared/papers/multi-element-silo-discharge.txt``, numbers in ``REFERENCES.md``) runs
its sphere model and its multi-element model (3-sphere clumps plus dust) in a slab silo and
compares them with each other and with a laboratory test. :func:`paper_a_claims` turns one or more
run folders of each model into claims (:class:`MeasuredClaim`): the paper's number, ours with
its uncertainty, and a verdict computed by :mod:`postprocess.claims`. Nothing here writes files;
``postprocess.report.paper_a`` does.

Every uncertainty says where it comes from. Over several seeds the sample of seeds gives it;
with one run of a model, the samples are the two side walls (wall pressures), the bed's layers
(coordination), the measuring regions (porosity) or the frames near a moment (contacts): the
spread of what one run measures at several places, with their few degrees of freedom, so a
single quick run leaves most comparisons "not resolved" rather than claiming what it cannot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from siloflow.atomic_files import read_json
from siloflow.errors import ReadError
from siloflow.run_folder import RESULT_TABLES, RunFolder

from .claims import ClaimRow, Estimate, greater, ratio_about, weighted_sum
from .coordination import Coordination, normal_force, rows_of
from .dumps import Frame, read_frames
from .force_chains import ForceChains, force_chains

#: Paper A's numbers (REFERENCES.md, Paper A). Table 3: maximum dynamic wall pressure (Pa) at the
#: monitoring points, (test, sphere model, clump model)
TABLE_3 = {1: (2845.540, 3455.140, 3027.398), 3: (1906.340, 2170.029, 1982.010),
           5: (1679.017, 1501.752, 1531.333), 7: (1056.897, 1232.434, 1123.435)}
#: Eq. 34's W of each model against the test (on its full pressure series, which is not public)
PAPER_W = {"spheres": 0.29175, "clumps": 0.1128}
#: porosity (3D-converted, Eq. 36-37), the test's 40.04 %
PAPER_POROSITY = {"spheres": 0.4220, "clumps": 0.3913, "test": 0.4004}
#: coordination number (the paper's 2D model)
PAPER_COORDINATION = {"spheres": 3.67, "clumps": 4.66}
#: contacts at 2.4 s of discharge, and the grains (clumps; the dust besides: 2,382 balls)
PAPER_CONTACTS = {"spheres": 31279, "clumps": 61403}
PAPER_GRAINS = {"spheres": 23000, "clumps": 24676}
PAPER_CONTACT_TIME = 2.4
#: discharge times (s)
PAPER_DISCHARGE_TIME = {"spheres": 29.1, "clumps": 31.4}
#: "about twice the contacts": the ratio counted as about the paper's within this fraction
ABOUT = 0.25
#: the points of Fig. 11-12 (Fig. 12: point 1 only)
FIGURE_POINTS = (1, 3, 5)
#: a strong contact carries more than the mean normal force; an arching one is within this angle
#: of the horizontal (deg)
ARCH_ANGLE_DEG = 30.0
MODELS = ("spheres", "clumps")


@dataclass(frozen=True)
class MeasuredClaim:
    """One claim as measured: its report ``section``, the ``claim``, what the paper says (``paper``,
    text), our measurement (``ours``, an :class:`Estimate` in ``unit``, or None), the ``verdict``
    (holds / fails / not resolved, or "shown" for a row that only places numbers side by side) and
    how the number and its uncertainty were obtained (``basis``). :meth:`row` is its report row."""

    section: str
    claim: str
    paper: str
    ours: Estimate | None
    unit: str
    verdict: str
    basis: str

    def row(self) -> ClaimRow:
        """The report's row (``postprocess.claims.ClaimRow``): ours and its 95 % interval as text."""
        if self.ours is None:
            return ClaimRow(f"{self.section}: {self.claim}", self.paper, "not measured", "", self.verdict, self.basis)
        lo, hi = self.ours.interval()
        unit = f" {self.unit}" if self.unit else ""
        return ClaimRow(f"{self.section}: {self.claim}", self.paper, f"{self.ours.value:.4g}{unit}",
                        f"95 % [{lo:.4g}, {hi:.4g}]", self.verdict, self.basis)

    def to_json(self) -> dict:
        """JSON-ready (the estimate as value, stderr, dof; an infinite dof as null)."""
        e = self.ours
        return {"section": self.section, "claim": self.claim, "paper": self.paper, "unit": self.unit,
                "verdict": self.verdict, "basis": self.basis, "ours": None if e is None else
                {"value": e.value, "stderr": e.stderr, "dof": None if math.isinf(e.dof) else e.dof}}

    @classmethod
    def from_json(cls, d: dict) -> "MeasuredClaim":
        e = d.get("ours")
        ours = None if e is None else Estimate(e["value"], e["stderr"], math.inf if e["dof"] is None else e["dof"])
        return cls(d["section"], d["claim"], d["paper"], ours, d["unit"], d["verdict"], d["basis"])


@dataclass
class ModelRuns:
    """The runs of one model: their folders, summaries and sector pressure tables."""

    name: str
    folders: list[Path]
    summaries: list[dict] = field(default_factory=list)
    sectors: list[pd.DataFrame] = field(default_factory=list)
    open_times: list[float] = field(default_factory=list)

    @classmethod
    def read(cls, name: str, folders: Sequence[Path]) -> "ModelRuns":
        runs = cls(name, [Path(f) for f in folders])
        if not runs.folders:
            raise ReadError(f"no run folder of the {name} model")
        for folder in runs.folders:
            run = RunFolder(folder)
            try:
                summary = read_json(run.summary_file, "a summary of results", allow_nan=True)
                # the frame analyses' numbers (bulk density, porosity regions) sit in their own section
                runs.summaries.append({**summary, **(summary.get("frame_analyses") or {})})
                runs.sectors.append(pd.read_csv(run.results / RESULT_TABLES["wall_pressure_sectors"]))
            except (OSError, ValueError, ReadError) as exc:
                raise ReadError(f"{folder}: no post-processed results ({exc}); run 'siloflow post' on it") from None
            runs.open_times.append(open_time(run))
        return runs


def open_time(run: RunFolder) -> float:
    """The time (s) the outlet opened in a run: its record's step of the ``open`` stage times dt."""
    steps = run.record.stage_steps
    if "open" not in steps:
        raise ReadError(f"{run.path}: its run record has no step for the opening")
    return int(steps["open"]) * run.plan.timestep.dt


# ---------------------------------------------------------------------------- estimates
def estimate(samples: Sequence[float], what: str) -> Estimate:
    """The mean of ``samples`` with its standard error (dof n - 1); ``ReadError`` with fewer than two."""
    x = [float(v) for v in samples if v is not None and math.isfinite(float(v))]
    if len(x) < 2:
        raise ReadError(f"{what}: {len(x)} finite sample(s); an uncertainty needs two or more")
    return Estimate.of_samples(x)


def max_dynamic_pressure(runs: ModelRuns, point: int) -> Estimate:
    """The maximum normal pressure (Pa) at monitoring point ``point`` (band ``point - 1`` from the
    bottom) after the outlet opened, one sample per run and side wall."""
    samples = []
    for sectors, t_open in zip(runs.sectors, runs.open_times):
        band = sectors[(sectors.band == point - 1) & (sectors.time > t_open)]
        samples += [float(g.pressure.max()) for _, g in band.groupby("sector")]
    return estimate(samples, f"{runs.name}: maximum dynamic pressure at point {point}")


def steady_window(summary: dict) -> tuple[float, float]:
    """The flow rate's steady window (s) of a run's summary."""
    rate = summary.get("flow_rate") or {}
    t0, t1 = rate.get("t_start"), rate.get("t_end")
    if t0 is None or t1 is None:
        raise ReadError("the run's summary has no steady flow window (flow_rate t_start, t_end)")
    return float(t0), float(t1)


def pressure_variation(runs: ModelRuns, points: Sequence[int] = FIGURE_POINTS) -> Estimate:
    """The coefficient of variation (standard deviation over mean) of the normal pressure over the
    steady discharge at ``points``, one sample per run, point and side wall."""
    samples = []
    for summary, sectors in zip(runs.summaries, runs.sectors):
        t0, t1 = steady_window(summary)
        window = sectors[(sectors.time >= t0) & (sectors.time <= t1)]
        for point in points:
            for _, g in window[window.band == point - 1].groupby("sector"):
                if len(g) > 2 and g.pressure.mean() > 0:
                    samples.append(float(g.pressure.std(ddof=1) / g.pressure.mean()))
    return estimate(samples, f"{runs.name}: pressure variation over the steady discharge")


def volumetric_flow_rate(runs: ModelRuns) -> Estimate:
    """The bed volume discharged per second (m3/s): the steady mass flow rate over the settled bed's
    cross-section bulk density; over seeds, or the flow rate's own batch-means error for one run."""
    rates = []
    for s in runs.summaries:
        rate, rho = s.get("flow_rate") or {}, s.get("cross_section_bulk_density_kg_m3")
        if not rate.get("rate") or not rho:
            raise ReadError(f"{runs.name}: the summary has no flow rate or bulk density")
        rates.append(Estimate(rate["rate"] / rho, (rate.get("stderr") or 0.0) / rho,
                              rate.get("dof", math.inf) or math.inf))
    if len(rates) > 1:
        return Estimate.of_samples([r.value for r in rates])
    return rates[0]


def porosity_3d(runs: ModelRuns) -> Estimate:
    """The settled bed's porosity in the case's measuring regions, converted 2D -> 3D as the case's
    ``analysis.porosity_conversion`` reads Eq. 36-37; one sample per run and region."""
    samples = [r.get("porosity_3d") for s in runs.summaries for r in (s.get("porosity_regions") or {}).values()]
    return estimate(samples, f"{runs.name}: 3D-converted porosity of the measuring regions")


# ---------------------------------------------------------------------------- frames
def _frames_at(run: RunFolder, times: Sequence[float]) -> list[tuple[Frame, Frame]]:
    """(atoms, contacts) frames of a run nearest each of ``times`` (s), those with contacts."""
    atoms_files, contact_files = run.dump_files("particles"), run.dump_files("contacts")
    columns = run.dump_layout.contact_columns or None
    if not atoms_files or not contact_files or not columns:
        raise ReadError(f"{run.path}: no particle and contact dumps (outputs.dump_interval, contacts)")
    dt = run.plan.timestep.dt
    steps = sorted({int(p.name.split(".")[1]) for p in contact_files})
    wanted = sorted({min(steps, key=lambda s: abs(s * dt - t)) for t in times})
    atoms = {f.timestep: f for f in read_frames(atoms_files, steps=wanted)}
    return [(atoms[c.timestep], c) for c in read_frames(contact_files, columns=columns, steps=wanted)
            if c.timestep in atoms]


def grain_pairs(atoms: Frame, contacts: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Atom rows (i, j) of the contacts between distinct grains (a clump's own spheres excluded;
    contacts naming an atom not in the frame dropped) and their normal force magnitudes (N)."""
    ids = atoms.column("id")
    i, found_i = rows_of(ids, contacts.column("id1"))
    j, found_j = rows_of(ids, contacts.column("id2"))
    keep = found_i & found_j
    fn = normal_force(contacts.data, atoms)
    if "mol" in atoms.data:
        body = atoms.column("mol").astype(int)
        keep &= body[i] != body[j]
    return i[keep], j[keep], fn[keep]


def frames_near(runs: ModelRuns, t_after_open: float, spread: float):
    """(run, atoms, contacts) of every run's contact frames within ``spread`` s of ``t_after_open``
    s after its outlet opened (the nearest frame to each of 5 times across that span)."""
    for folder, t_open in zip(runs.folders, runs.open_times):
        run = RunFolder(folder)
        for atoms, contacts in _frames_at(run, t_open + t_after_open + np.linspace(-spread, spread, 5)):
            yield run, atoms, contacts


def contacts_per_grain(runs: ModelRuns, t_after_open: float, spread: float) -> Estimate:
    """Contacts between grains (dust included) per grain (clumps or balls; dust not counted as
    grains), one sample per frame of :func:`frames_near`."""
    samples = [len(grain_pairs(atoms, contacts)[0]) / grain_count(atoms)
               for _, atoms, contacts in frames_near(runs, t_after_open, spread)]
    return estimate(samples, f"{runs.name}: contacts per grain near {t_after_open:g} s of discharge")


def grain_count(atoms: Frame) -> int:
    """Grains in a frame: clumps (distinct ``mol``) or the spheres of the largest type (the dust,
    a smaller type, not counted)."""
    if "mol" in atoms.data:
        body = atoms.column("mol").astype(int)
        return int(len(np.unique(body[body > 0])))
    radii = atoms.radii()
    return int((radii > 0.5 * radii.max()).sum())


def coordination_by_layer(runs: ModelRuns, layers: int = 4) -> Estimate:
    """The settled bed's coordination number (contacts between distinct grains per grain, rattlers
    kept) in the core away from the walls, one sample per run and horizontal layer of the core."""
    samples = []
    for folder, t_open in zip(runs.folders, runs.open_times):
        run = RunFolder(folder)
        g = run.plan.geometry
        pairs = _frames_at(run, [t_open])
        if not pairs:
            raise ReadError(f"{folder}: no contact frame at the opening")
        atoms, contacts = pairs[0]
        p = atoms.positions()
        d = 2.0 * float(np.median(atoms.radii()))
        top = float(p[:, 2].max())
        lo, hi = g.hopper_height + 2 * d, top - 2 * d
        edges = np.linspace(lo, hi, layers + 1)
        for a, b in zip(edges, edges[1:]):
            def select(frame, a=a, b=b):
                q = frame.positions()
                return (np.abs(q[:, 0]) < g.half_width - 2 * d) & (q[:, 2] >= a) & (q[:, 2] < b)
            table = Coordination(select=select).run([atoms], [contacts]).table
            row = table[table.species == "all"]
            if not row.empty and row.grains.iloc[0] > 0:
                samples.append(float(row.z_mean.iloc[0]))
    return estimate(samples, f"{runs.name}: coordination number of the settled core")


def transverse_share(positions: np.ndarray, i: np.ndarray, j: np.ndarray, fn: np.ndarray, z_max: float) -> float | None:
    """Of the strong contacts (normal force above the mean of those considered) whose midpoint lies
    below ``z_max`` (m: the hopper), the fraction whose branch vector is within
    :data:`ARCH_ANGLE_DEG` of the horizontal; None with fewer than 5 strong contacts."""
    mid = 0.5 * (positions[i] + positions[j])
    low = mid[:, 2] < z_max
    if not low.any():
        return None
    strong = low & (fn > fn[low].mean())
    if strong.sum() < 5:
        return None
    branch = positions[j[strong]] - positions[i[strong]]
    angle = np.degrees(np.arctan2(np.abs(branch[:, 2]), np.hypot(branch[:, 0], branch[:, 1])))
    return float((angle < ARCH_ANGLE_DEG).mean())


def arching_fraction(runs: ModelRuns, t_after_open: float, spread: float) -> Estimate:
    """:func:`transverse_share` in the hopper, one sample per frame of :func:`frames_near`:
    transverse, arch-like strong chains."""
    samples = []
    for run, atoms, contacts in frames_near(runs, t_after_open, spread):
        share = transverse_share(atoms.positions(), *grain_pairs(atoms, contacts), run.plan.geometry.hopper_height)
        if share is not None:
            samples.append(share)
    return estimate(samples, f"{runs.name}: transverse share of the strong contacts in the hopper")


# ---------------------------------------------------------------------------- claims
def _fmt(e: Estimate | None, unit: str = "", scale: float = 1.0) -> str:
    if e is None:
        return "not measured"
    lo, hi = e.scaled(scale).interval()
    return f"{e.value * scale:.4g} [{lo:.4g}, {hi:.4g}]{(' ' + unit) if unit else ''}"


def _triple(e: Estimate) -> list:
    """[value, stderr, dof] for JSON (an infinite dof as None)."""
    return [e.value, e.stderr, None if math.isinf(e.dof) else e.dof]


def table_3(models: dict[str, ModelRuns], pressure_scale: float) -> tuple[pd.DataFrame, dict[str, Estimate], dict]:
    """Table 3's layout: per monitoring point the test, the paper's two models and ours (scaled by
    ``pressure_scale`` to the paper's silo), each with its deviation from the test; each of our
    models' W (Eq. 34) on these maxima; and the maxima themselves, {(point, model): Estimate}."""
    rows, w_parts, maxima = [], {m: ([], []) for m in MODELS}, {}
    for point, (test, paper_s, paper_c) in TABLE_3.items():
        row = {"point": point, "test_Pa": test, "paper_spheres_Pa": paper_s,
               "paper_spheres_deviation": abs(paper_s - test) / test, "paper_clumps_Pa": paper_c,
               "paper_clumps_deviation": abs(paper_c - test) / test}
        for m in MODELS:
            e = maxima[point, m] = max_dynamic_pressure(models[m], point).scaled(pressure_scale)
            lo, hi = e.interval()
            row.update({f"ours_{m}_Pa": e.value, f"ours_{m}_low_Pa": lo, f"ours_{m}_high_Pa": hi,
                        f"ours_{m}_deviation": abs(e.value - test) / test})
            # W = (1/n) sum |p - test| / test: linear in p with slope sign(p - test) / (n test)
            w_parts[m][0].append(e)
            w_parts[m][1].append(math.copysign(1.0, e.value - test) / (len(TABLE_3) * test))
        rows.append(row)
    w = {}
    for m, (estimates, weights) in w_parts.items():
        constant = -sum(math.copysign(1.0, e.value - t[0]) / len(TABLE_3) for e, t in zip(estimates, TABLE_3.values()))
        w[m] = weighted_sum(estimates, weights, constant)
    return pd.DataFrame(rows), w, maxima


def paper_a_claims(spheres: Sequence[Path], clumps: Sequence[Path], length_scale: float,
                   time_scale: float | None = None) -> tuple[list[MeasuredClaim], dict]:
    """Paper A's claims on the runs of its sphere model and its multi-element model.

    ``length_scale``: the runs' silo over the paper's (1/4 at quick scale). Pressures scale to
    the paper's silo by 1 / length_scale (Janssen: p ~ rho g D at the same bulk properties),
    times by sqrt(length_scale) (Froude: t ~ sqrt(L / g)) unless ``time_scale`` is given.
    Returns the rows and the tables behind them (``table_3``, ``numbers``)."""
    if not 0 < length_scale <= 1:
        raise ValueError("length_scale is the runs' silo over the paper's: 0 < length_scale <= 1")
    models = {"spheres": ModelRuns.read("spheres", spheres), "clumps": ModelRuns.read("clumps", clumps)}
    p_scale = 1.0 / length_scale
    t_scale = math.sqrt(length_scale) if time_scale is None else time_scale
    seeds = {m: len(r.folders) for m, r in models.items()}
    per = "seed" if min(seeds.values()) > 1 else "side wall of one run"
    rows: list[MeasuredClaim] = []

    t3, w, maxima = table_3(models, p_scale)
    for _, r in t3.iterrows():
        for m in MODELS:
            e = maxima[int(r.point), m]
            paper_value = r[f"paper_{m}_Pa"]
            rows.append(MeasuredClaim(
                "Table 3: maximum dynamic wall pressure", f"point {int(r.point)}, {m} model",
                f"test {r.test_Pa:.1f} Pa; paper's model {paper_value:.1f} Pa ({100 * (paper_value / r.test_Pa - 1):+.1f} %)",
                e, "Pa", "shown",
                (f"ours {100 * (e.value / r.test_Pa - 1):+.1f} % from the test" if e.value > 0 else
                 "no pressure at this section: the run's bed does not reach it")
                + f"; the maximum after opening per {per}, x {p_scale:g} to the paper's silo"))
    rows.append(MeasuredClaim(
        "Eq. 34: error against the test", "the clump model's W is lower than the sphere model's",
        f"W: clumps {100 * PAPER_W['clumps']:.2f} %, spheres {100 * PAPER_W['spheres']:.3f} % (on the full series)",
        w["spheres"].minus(w["clumps"]), "", greater(w["spheres"], w["clumps"]),
        f"W = (1/n) sum |p - p_test| / p_test over Table 3's maxima (points 1, 3, 5, 7: the only test values "
        f"published); ours: spheres {_fmt(w['spheres'])}, clumps {_fmt(w['clumps'])}; the row's number is "
        "W_spheres - W_clumps"))

    numbers: dict = {"seeds": seeds, "pressure_scale": p_scale, "time_scale": t_scale,
                     "W": {m: _triple(w[m]) for m in MODELS}}

    def measured(key: str, measure) -> dict[str, Estimate]:
        """``measure`` of each model, recorded in ``numbers[key]`` as [value, stderr, dof]."""
        est = {m: measure(models[m]) for m in MODELS}
        numbers[key] = {m: _triple(est[m]) for m in MODELS}
        return est

    # discharge: longer for clumps <=> less bed volume per second through the same outlet
    q = measured("volumetric_flow_rate_m3_s", volumetric_flow_rate)
    rows.append(MeasuredClaim(
        "Trends", "the clump model discharges longer",
        f"{PAPER_DISCHARGE_TIME['clumps']} s against {PAPER_DISCHARGE_TIME['spheres']} s",
        q["spheres"].over(q["clumps"]), "", greater(q["spheres"], q["clumps"]),
        "the same bed volume empties later when less of it leaves per second: the row's number is the sphere "
        f"model's volumetric flow rate over the clump model's (> 1: clumps longer); spheres {_fmt(q['spheres'], 'm3/s')}, "
        f"clumps {_fmt(q['clumps'], 'm3/s')}; steady mass flow rate over the bed's bulk density"))
    cv = measured("pressure_variation", pressure_variation)
    rows.append(MeasuredClaim(
        "Trends", "the clump model's wall pressure fluctuates less",
        "Fig. 11-12: the multi-element model's pressure fluctuates less and more gently",
        cv["spheres"].minus(cv["clumps"]), "", greater(cv["spheres"], cv["clumps"]),
        f"coefficient of variation (sd / mean) of the pressure over the steady discharge at points "
        f"{', '.join(map(str, FIGURE_POINTS))}, per {per} and point: spheres {_fmt(cv['spheres'])}, clumps "
        f"{_fmt(cv['clumps'])}; the row's number is the difference"))
    por = measured("porosity_3d", porosity_3d)
    for m in MODELS:
        rows.append(MeasuredClaim(
            "Meso-structure", f"porosity of the {m} model (3D-converted)",
            f"{100 * PAPER_POROSITY[m]:.2f} % (test {100 * PAPER_POROSITY['test']:.2f} %)",
            por[m].scaled(100.0), "%", "shown",
            f"settled bed, the case's measuring circles converted by Eq. 36-37 as docs/papers.md reads them; "
            f"{100 * (por[m].value - PAPER_POROSITY['test']):+.2f} points from the test"))
    rows.append(MeasuredClaim(
        "Trends", "the clump model packs denser (lower porosity)",
        f"{100 * PAPER_POROSITY['clumps']:.2f} % against {100 * PAPER_POROSITY['spheres']:.2f} %",
        por["spheres"].minus(por["clumps"]).scaled(100.0), "points", greater(por["spheres"], por["clumps"]),
        "sphere model's porosity minus the clump model's, per measuring region"))
    z = measured("coordination", coordination_by_layer)
    for m in MODELS:
        rows.append(MeasuredClaim(
            "Meso-structure", f"coordination number of the {m} model", f"{PAPER_COORDINATION[m]} (2D model)",
            z[m], "", "shown",
            "contacts between distinct grains per grain (dust contacts counted, rattlers kept) in the settled "
            "core, per horizontal layer; ours is a slab one grain thick, the paper's a 2D model"))
    rows.append(MeasuredClaim(
        "Trends", "the clump model has a higher coordination number",
        f"{PAPER_COORDINATION['clumps']} against {PAPER_COORDINATION['spheres']}",
        z["clumps"].minus(z["spheres"]), "", greater(z["clumps"], z["spheres"]),
        "the clump model's coordination number minus the sphere model's"))

    # contacts at the paper's 2.4 s of discharge, scaled in time, within the runs' discharge
    ends = [float(s["flow_rate"]["t_end"]) - t for r in models.values() for s, t in zip(r.summaries, r.open_times)]
    # five frames around it: two dump intervals either side, all inside every run's steady discharge
    plans = [RunFolder(f).plan for r in models.values() for f in r.folders]
    dump_dt = max(plan.outputs.dump_every * plan.timestep.dt for plan in plans)
    spread = 2.0 * dump_dt
    t_contacts = min(PAPER_CONTACT_TIME * t_scale, min(ends) - spread)
    if t_contacts - spread <= 0:
        raise ReadError(f"the runs' steady discharge ({min(ends):.3g} s) is too short for five contact frames "
                        f"{dump_dt:.3g} s apart: discharge longer, or dump more often")
    c = measured("contacts_per_grain", lambda r: contacts_per_grain(r, t_contacts, spread))
    numbers["contacts_time_after_open_s"] = t_contacts
    capped = ", capped within the runs' discharge" if t_contacts < PAPER_CONTACT_TIME * t_scale else ""
    for m in MODELS:
        rows.append(MeasuredClaim(
            "Meso-structure", f"contacts per grain of the {m} model at {t_contacts:.3g} s of discharge",
            f"{PAPER_CONTACTS[m]:,} contacts at {PAPER_CONTACT_TIME} s among {PAPER_GRAINS[m]:,} grains "
            f"({PAPER_CONTACTS[m] / PAPER_GRAINS[m]:.3g} per grain)",
            c[m], "", "shown",
            f"contacts between distinct grains (dust included) per grain, the frames within {spread:.2g} s of "
            f"{t_contacts:.3g} s after opening (the paper's {PAPER_CONTACT_TIME} s x {t_scale:.3g}"
            f"{capped})"))
    paper_ratio = (PAPER_CONTACTS["clumps"] / PAPER_GRAINS["clumps"]) / (PAPER_CONTACTS["spheres"] / PAPER_GRAINS["spheres"])
    rows.append(MeasuredClaim(
        "Trends", "the clump model has about twice the contacts",
        f"{PAPER_CONTACTS['clumps']:,} against {PAPER_CONTACTS['spheres']:,} (x{PAPER_CONTACTS['clumps'] / PAPER_CONTACTS['spheres']:.2f}; "
        f"x{paper_ratio:.2f} per grain)",
        c["clumps"].over(c["spheres"]), "", ratio_about(c["clumps"], c["spheres"], paper_ratio, ABOUT),
        f"the ratio of contacts per grain, clumps over spheres, against the paper's per grain, within "
        f"{100 * ABOUT:.0f} %"))
    arch = measured("transverse_strong_contacts", lambda r: arching_fraction(r, t_contacts, spread))
    rows.append(MeasuredClaim(
        "Trends", "the clump model shows arching force chains",
        "Fig. 14-15: several transverse arching chains in the multi-element model",
        arch["clumps"].minus(arch["spheres"]), "", greater(arch["clumps"], arch["spheres"]),
        f"share of the hopper's strong contacts (normal force above the mean) within {ARCH_ANGLE_DEG:g} deg of "
        f"the horizontal, clumps minus spheres, frames near {t_contacts:.3g} s of discharge: spheres "
        f"{_fmt(arch['spheres'])}, clumps {_fmt(arch['clumps'])}; the force-chain figures show both"))
    numbers["table_3"] = t3.to_dict(orient="records")
    return rows, numbers


def pressure_series(spheres: Sequence[Path], clumps: Sequence[Path], length_scale: float,
                    points: Sequence[int] = FIGURE_POINTS) -> pd.DataFrame:
    """Fig. 11-12's data: the normal pressure at ``points`` against the time since the outlet
    opened (negative: the static bed), both models, mean of the two side walls, first run of each
    model, scaled to the paper's silo (pressure x 1 / length_scale, time x 1 / sqrt(length_scale)).
    Columns model, point, time_s, pressure_Pa."""
    parts = []
    for m, folders in (("spheres", spheres), ("clumps", clumps)):
        runs = ModelRuns.read(m, folders[:1])
        sectors, t_open = runs.sectors[0], runs.open_times[0]
        for point in points:
            band = sectors[sectors.band == point - 1].groupby("time", as_index=False).pressure.mean()
            parts.append(pd.DataFrame({"model": m, "point": point,
                                       "time_s": (band.time - t_open) / math.sqrt(length_scale),
                                       "pressure_Pa": band.pressure / length_scale}))
    return pd.concat(parts, ignore_index=True)


def chains_at(folder: Path, t_after_open: float) -> ForceChains:
    """The force chains (mid-plane slice one grain thick) of a run's frame nearest ``t_after_open``
    s after the outlet opened."""
    run = RunFolder(folder)
    pairs = _frames_at(run, [open_time(run) + t_after_open])
    if not pairs:
        raise ReadError(f"{folder}: no contact frame near {t_after_open:g} s of discharge")
    atoms, contacts = pairs[0]
    return force_chains(atoms, contacts, axis=1, center=0.0, thickness=2.0 * float(np.median(atoms.radii())))


def chains_table(chains: ForceChains) -> pd.DataFrame:
    """A slice's contacts as a table: segment ends (x0, z0, x1, z1, m) and normal force fn (N)."""
    seg = chains.segments
    return pd.DataFrame({"x0": seg[:, 0, 0], "z0": seg[:, 0, 1], "x1": seg[:, 1, 0], "z1": seg[:, 1, 1],
                         "fn": chains.forces})


def chains_from_table(table: pd.DataFrame, step: int = 0) -> ForceChains:
    """:func:`chains_table` back as ``ForceChains`` (the mid-plane slice, ``thickness`` unknown: 0)."""
    seg = table[["x0", "z0", "x1", "z1"]].to_numpy(float).reshape(-1, 2, 2)
    return ForceChains(step, 1, seg, table.fn.to_numpy(float), 0.0, 0.0)
