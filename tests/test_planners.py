"""derive() as one planner per plan section (issue 58, item 3): each answers alone for a case, and
derive() is their sum."""
from __future__ import annotations

import math

import pytest

from siloflow.case_file import case_from_dict
from siloflow.derived import (
    derive,
    plan_amount,
    plan_discharge,
    plan_fill,
    plan_insertion,
    plan_opening,
    plan_outputs,
    plan_settle,
    plan_silo,
    plan_species,
    plan_static,
    plan_timestep,
)
from siloflow.errors import CaseError


@pytest.fixture
def quick(quick_dict):
    return case_from_dict(quick_dict)


def test_species_budget_of_the_quick_case(quick):
    budget = plan_species(quick)
    assert [sp.name for sp in budget.grains] == [sp.name for sp in budget.species if sp.stream == "grains"]
    assert sum(budget.mass_fractions) == pytest.approx(1.0) and budget.dust is None and not budget.shrink
    r = quick.particles.max_radius
    assert budget.volume_per_grain == pytest.approx(4 / 3 * math.pi * r ** 3)
    assert budget.grain_mass == pytest.approx(quick.materials.particle.density * budget.poured_volume)


def test_amount_and_insertion_region(quick, quick_dict):
    budget = plan_species(quick)
    count, dust_count, h_bed = plan_amount(quick, budget)
    assert count == quick.fill.count and dust_count == 0 and 0 < h_bed < quick.geometry.height
    z_min, z_max, region, volume = plan_insertion(quick, h_bed)
    assert h_bed < z_min < z_max <= quick.geometry.height and volume > 0 and region["shape"] == "cylinder"
    with pytest.raises(CaseError, match="leaves no room to insert"):
        plan_insertion(quick, quick.geometry.height)


def test_timestep_fill_and_stages_alone(quick):
    budget = plan_species(quick)
    count, dust_count, h_bed = plan_amount(quick, budget)
    insertion = plan_insertion(quick, h_bed)
    timestep, contacts, pairs = plan_timestep(quick, budget, 1.0)
    assert timestep.dt == pytest.approx(quick.engine.timestep_fraction * timestep.critical_time)
    assert set(pairs) == {"particle_particle", "particle_wall"} and len(contacts) >= 2
    fill = plan_fill(quick, budget, count, dust_count, h_bed, insertion, timestep.dt, 1.0)
    assert fill.count == count and 1 <= fill.batch <= count and fill.steps > fill.insert_every
    settle = plan_settle(quick, timestep.dt)
    assert settle.chunk_steps * timestep.dt == pytest.approx(quick.fill.settle.check_interval, rel=0.01)
    outlet, opening = plan_opening(quick, timestep.dt)
    assert outlet.z < 0 and opening.travel == pytest.approx(3 * abs(outlet.z))
    discharge = plan_discharge(quick, timestep.dt, 2.0)
    assert discharge.empty_mass == pytest.approx(quick.discharge.empty_fraction * 2.0)
    outputs = plan_outputs(quick, timestep.dt, settle.chunk_steps)
    assert outputs.thermo_every == settle.chunk_steps and outputs.sample_steps % outputs.samples_per_average == 0
    assert plan_static(quick, timestep.dt, outputs) >= 2 * outputs.sample_steps
    with pytest.raises(CaseError, match="static_window"):
        plan_static(quick, timestep.dt, outputs.model_copy(update={"sample_steps": 10 ** 12}))


def test_derive_is_its_planners(quick):
    """derive() puts the planners' sections together unchanged (the goldens hold the rest)."""
    plan = derive(quick)
    budget = plan_species(quick)
    count, dust_count, h_bed = plan_amount(quick, budget)
    assert (plan.fill.count, plan.fill.dust_count, plan.fill.bed_height_estimate) == (count, dust_count, h_bed)
    assert plan.geometry == plan_silo(quick)
    assert plan.settle == plan_settle(quick, plan.dt)
    assert (plan.outlet, plan.opening) == plan_opening(quick, plan.dt)
    assert plan.outputs == plan_outputs(quick, plan.dt, plan.settle.chunk_steps)
