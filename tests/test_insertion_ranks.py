"""Where LIGGGHTS can put a fill batch, and what MPI ranks change about it (docs/accuracy.md "MPI ranks are
not neutral", docs/engine_facts.md, ``siloflow.engine.liggghts.insertion``).

LIGGGHTS' ``fix insert/rate/region`` with ``overlapcheck yes`` inserts no grain within its radius of a
processor-subdomain border (its default ``check_dist_from_subdomain_border yes``), so grains inserted
on two ranks do not rain into a slab about the border plane, and a batch that asks for more than
random insertion places in what is left comes in short. The engine tests render the accuracy
benchmark's case, run the fill stage's first insertion on 1 and 2 ranks and compare where the grains
were put and how many; the others check the estimate siloflow warns with.
"""
from __future__ import annotations

import math
import re
import subprocess

import numpy as np
import pytest
import yaml

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine import LiggghtsEngine
from siloflow.engine.liggghts.deck import before_stage_run
from siloflow.engine.liggghts.encoding import encode
from siloflow.engine.liggghts.insertion import (PLACEABLE_FRACTION, batch_solid_fraction, processor_grid,
                                                short_batch_warning, short_batches_note)
from siloflow.engine.liggghts.log import parse_log_text

from conftest import ROOT, needs_liggghts, render_deck



CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"


def _case_data(ranks: int, fraction: float | None = None) -> dict:
    data = yaml.safe_load(CASE.read_text())
    # pinned settings (not the published fast profile): dt = 0.1 t_c at 1/100 of the stiffness
    data.update(name=f"ins{ranks}", engine={"ranks": ranks, "timestep_fraction": 0.1, "stiffness_scale": 0.01})
    if fraction is not None:
        data["fill"] = {**data["fill"], "batch_volume_fraction": fraction}
    return data


def _plan(ranks: int, fraction: float | None = None):
    plan = derive(case_from_dict(_case_data(ranks, fraction), "test"))
    return plan, encode(plan).box


def _first_batch(tmp_path, ranks: int, fraction: float | None = None) -> tuple[np.ndarray, str]:
    """(id, radius, x, y, z) of the grains of the first insertion on ``ranks`` ranks, and the log."""
    folder = tmp_path / f"r{ranks}-{fraction}"
    text = render_deck(_case_data(ranks, fraction), folder)
    (folder / "first.in").write_text(before_stage_run(text, "fill")
                                     + "dump first all custom 1 first.dump id radius x y z\nrun 2\n")
    subprocess.run(LiggghtsEngine().command(ranks, deck="first.in", log="first.log"), cwd=folder, check=True,
                   capture_output=True)
    frame = (folder / "first.dump").read_text().split("ITEM: TIMESTEP")[-1].splitlines()
    start = next(i for i, line in enumerate(frame) if line.startswith("ITEM: ATOMS")) + 1
    return np.loadtxt(frame[start:], ndmin=2), (folder / "first.log").read_text()


def _batch(log: str) -> tuple[int, float, bool]:
    """(grains placed, grains asked, came in short) of the first grain batch in a LIGGGHTS log."""
    state = parse_log_text(log)
    asked = float(re.search(r"^INFO: Particle insertion ins: (\S+) particles every", log, re.M).group(1))
    return state.batches["ins"][0], asked, bool(state.short_batches.get("ins"))


@needs_liggghts
def test_two_ranks_insert_no_grain_within_its_radius_of_the_subdomain_border(tmp_path):
    (one, _), (two, log2) = _first_batch(tmp_path, 1), _first_batch(tmp_path, 2)
    near = lambda a: np.mean(np.abs(a[:, 2]) < a[:, 1])       # noqa: E731 (centre within a radius of x = 0)
    # one rank: the rain covers the plane x = 0 like any other (14 % of the grains of this batch)
    assert len(one) > 200 and near(one) > 0.08
    # two ranks (a 2 x 1 x 1 grid split at x = 0, as processor_grid says): none there, and the batch is smaller
    assert "2 by 1 by 1" in log2
    assert near(two) == 0.0
    assert len(two) < 0.9 * len(one)


@needs_liggghts
def test_an_overfull_batch_stalls_at_one_solid_fraction_of_the_usable_region_on_any_rank_count(tmp_path):
    """The case asks for 0.35 of the region: short on both rank counts, and what is placed fills the
    region's usable part (``batch_solid_fraction``) to the same solid fraction, so the rank effect on
    the batch is the subdomain border's slab and nothing else."""
    filled = {}
    for ranks in (1, 2):
        grains, log = _first_batch(tmp_path, ranks)
        placed, asked, short = _batch(log)
        plan, box = _plan(ranks)
        assert short and placed < asked == plan.fill.batch
        filled[ranks] = placed / asked * batch_solid_fraction(plan, box, ranks)
        # what is left out is the smallest grains: LIGGGHTS places the batch's list largest first
        radii = grains[:, 1]
        smallest, largest = min(plan.fill.radii), max(plan.fill.radii)
        assert np.sum(np.isclose(radii, largest)) == pytest.approx(asked / 7, abs=1)
        assert np.sum(np.isclose(radii, smallest)) < 0.5 * asked / 7
    assert filled[1] > PLACEABLE_FRACTION + 0.05            # stalled well above what siloflow allows
    assert filled[2] == pytest.approx(filled[1], rel=0.06)


def _fits(text: str) -> float:
    """The batch fraction a warning advises."""
    return float(re.search(r"use at most (\S+)$", text).group(1))


@needs_liggghts
def test_the_largest_batch_siloflow_allows_comes_in_whole_on_two_ranks(tmp_path):
    fits = _fits(short_batch_warning(*_plan(2), 2))
    assert short_batch_warning(*_plan(2, fits), 2) is None
    placed, asked, short = _batch(_first_batch(tmp_path, 2, fits)[1])
    assert not short and placed == asked == _plan(2, fits)[0].fill.batch


def test_processor_grid_follows_lammps_procmap():
    box = lambda lx, ly, lz: {"xlo": 0, "xhi": lx, "ylo": 0, "yhi": ly, "zlo": 0, "zhi": lz}   # noqa: E731
    assert processor_grid(box(1, 1, 3), 1, False) == (1, 1, 1)
    # '* * 1': never a z split; a square cross-section splits in x (a tie, broken by cull_user's reordering)
    assert processor_grid(box(1, 1, 3), 2, False) == (2, 1, 1)
    assert processor_grid(box(1, 1.2, 3), 2, False) == (1, 2, 1)
    assert processor_grid(box(1, 1, 3), 4, False) == (2, 2, 1)
    assert processor_grid(box(1, 1, 3), 3, False) == (3, 1, 1)
    # a slab ('* 1 *'): never a y split; a tall slab splits in z
    assert processor_grid(box(1, 0.1, 3), 2, True) == (1, 1, 2)
    assert processor_grid(box(3, 0.1, 1), 2, True) == (2, 1, 1)
    # the accuracy case's box is square in x and y: what LIGGGHTS printed above, 2 by 1 by 1
    plan, bench_box = _plan(2)
    assert processor_grid(bench_box, 2, plan.planar) == (2, 1, 1)


def _one_size(ranks: int, r: float = 0.0125):
    data = _case_data(ranks)
    data["particles"] = {"kind": "spheres", "radius": r}
    plan = derive(case_from_dict(data, "test"))
    return plan, encode(plan).box


def test_usable_region_matches_the_geometry():
    """One size, one rank: the region shrunk by the radius; two ranks: less the slab |x| < r."""
    r = 0.0125
    plan, box = _one_size(1, r)
    reg, f, (grain,) = plan.fill.region, plan.fill, plan.species
    asked = f.batch * grain.volume / (math.pi * reg.radius ** 2 * (reg.z_max - reg.z_min))
    a = reg.radius - r
    shrunk = a ** 2 * (reg.z_max - reg.z_min - 2 * r) / (reg.radius ** 2 * (reg.z_max - reg.z_min))
    assert batch_solid_fraction(plan, box, 1) == pytest.approx(asked / shrunk, rel=0.01)
    slab = 2 * (r * math.sqrt(a * a - r * r) + a * a * math.asin(r / a)) / (math.pi * a * a)   # |x| < r of the disc
    assert batch_solid_fraction(plan, box, 2) == pytest.approx(asked / shrunk / (1 - slab), rel=0.01)


def test_the_rank_asked_most_sets_the_estimate_on_three_ranks():
    """3 x 1 x 1: each rank gets its share of the shrunk region's volume but loses the slabs at its
    own borders, so the outer ranks (one border inside the region) and the middle one (two) differ;
    the estimate is the larger, computed here on a regular grid of the disc."""
    r = 0.0125
    plan, box = _one_size(3, r)
    reg, f, (grain,) = plan.fill.region, plan.fill, plan.species
    a = reg.radius - r
    x, y = np.meshgrid(np.linspace(-a, a, 1201), np.linspace(-a, a, 1201))
    disc = x ** 2 + y ** 2 <= a * a
    width = (box["xhi"] - box["xlo"]) / 3
    cuts = [box["xlo"] + width, box["xlo"] + 2 * width]
    rank = np.digitize(x, cuts)
    clear = np.min([np.abs(x - c) for c in cuts], axis=0) >= r
    per_rank = []
    for k in range(3):
        share = np.sum(disc & (rank == k)) / np.sum(disc)
        usable = np.sum(disc & (rank == k) & clear) / np.sum(disc)       # of the shrunk disc's area
        per_rank.append(f.batch * share * grain.volume / (math.pi * reg.radius ** 2 * (reg.z_max - reg.z_min))
                        / ((a / reg.radius) ** 2 * (1 - 2 * r / (reg.z_max - reg.z_min)) * usable))
    assert max(per_rank) > 1.1 * min(per_rank)
    assert batch_solid_fraction(plan, box, 3) == pytest.approx(max(per_rank), rel=0.02)


def test_warning_names_the_field_and_a_value_that_fits():
    plan, box = _plan(2)
    case = case_from_dict(_case_data(2), "test")
    text = short_batch_warning(plan, box, 2, case.fill)
    assert text.startswith(f"fill.batch_volume_fraction 0.35 makes batches of {plan.fill.batch} grains")
    assert "engine.ranks" in text
    fits = _fits(text)
    assert 0.1 < fits < 0.35
    assert short_batch_warning(*_plan(2, fits), 2) is None
    # the default 0.15 fits on 1 and 2 ranks of this silo
    assert short_batch_warning(*_plan(1, 0.15), 1) is None
    assert short_batch_warning(*_plan(2, 0.15), 2) is None


def test_a_pour_too_short_is_told_to_pour_longer():
    data = _case_data(2, 0.35)
    data["fill"] = {**data["fill"], "protocol": "pour", "pour_time": 0.45}
    case = case_from_dict(data, "test")
    plan = derive(case)
    text = short_batch_warning(plan, encode(plan).box, 2, case.fill)
    assert text.startswith("fill.pour_time 0.45 s makes batches")
    longer = float(re.search(r"pour for at least (\S+) s$", text).group(1))
    assert longer > 0.45
    data["fill"]["pour_time"] = longer
    plan = derive(case_from_dict(data, "test"))          # accepted, and the batch now fits
    assert short_batch_warning(plan, encode(plan).box, 2) is None


def test_slabs_and_clumps_are_not_estimated():
    for name in ("slab_silo.yaml", "clump_silo.yaml"):
        from siloflow.case_file import load_case
        case = load_case(ROOT / "tests" / "data" / name)
        plan = derive(case)
        assert short_batch_warning(plan, encode(plan).box, case.engine.ranks) is None
        with pytest.raises(ValueError):
            batch_solid_fraction(plan, encode(plan).box, 1)


def test_log_counts_short_batches_per_fix():
    log = "\n".join([
        "INFO: Particle insertion ins: 336.000000 particles every 2292 steps - particle rate 2937.041846",
        "INFO: Particle insertion ins: inserted 233 particle templates (mass 1.957485e+01) at step 1",
        "WARNING: Particle insertion: Less insertions than requested (./src/fix_insert.cpp:814)",
        "INFO: Particle insertion ins_dust: inserted 40 particle templates (mass 1e-3) at step 1",
        "INFO: Particle insertion ins: inserted 336 particle templates (mass 2.8e+01) at step 2293",
        "INFO: Particle insertion ins: inserted 229 particle templates (mass 1.940927e+01) at step 4585",
        "WARNING: Particle insertion: Less insertions than requested (./src/fix_insert.cpp:814)", ""])
    state = parse_log_text(log)
    assert state.batches == {"ins": [233, 336, 229], "ins_dust": [40]}
    assert state.short_batches == {"ins": [233, 229]}
    assert state.templates == {"ins": 798, "ins_dust": 40}
    (note,) = short_batches_note(state.batches, state.short_batches, {"ins": 336, "ins_dust": 40})
    assert note.startswith("siloflow: 2 of 3 grain batches came in short (placed 229-233, batches of 336 planned")
    assert "fill.batch_volume_fraction" in note and "engine.ranks" in note
    assert short_batches_note({"ins": [336, 336, 8]}, {}, {"ins": 336}) == []
