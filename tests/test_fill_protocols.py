"""Fill protocols (issue 18): a slow continuous pour from a thin layer at the top, and a
mobilising step (the floor lowered after settling, then a second settling)."""
from __future__ import annotations

import copy

import pytest

from siloflow.case_file import case_from_dict
from siloflow.derived import POUR_LAYER, derive
from siloflow.engine.liggghts.deck import render_deck_text
from siloflow.errors import CaseError


def variant(quick_dict, **fill):
    data = copy.deepcopy(quick_dict)
    data["fill"].update(fill)
    case = case_from_dict(data)
    return case, derive(case)


def test_pour_comes_from_a_thin_layer_in_small_batches_over_the_pour_time(quick_dict):
    _, rain = variant(quick_dict)
    _, pour = variant(quick_dict, protocol="pour", pour_time=3.0)
    d = 2 * pour.particle_radius
    r = pour.fill.region
    assert r.z_max == rain.fill.region.z_max and r.z_max - r.z_min == pytest.approx(POUR_LAYER * d)
    assert pour.fill.batch < rain.fill.batch
    batches = -(-pour.fill.count // pour.fill.batch)
    assert batches * pour.fill.insert_every * pour.dt == pytest.approx(3.0, rel=0.05)   # lasts the pour time
    assert pour.fill.protocol == "pour"


def test_a_pour_too_fast_for_its_layer_is_refused_naming_the_field(quick_dict):
    with pytest.raises(CaseError, match="fill.pour_time"):
        variant(quick_dict, protocol="pour", pour_time=0.05)


def test_mobilise_lowers_the_floor_and_settles_again(quick_dict):
    case, plan = variant(quick_dict, mobilise={"floor_drop": 0.1, "time": 0.05})
    m = plan.fill.mobilise
    d = 2 * plan.particle_radius
    assert m.drop == pytest.approx(0.1 * d) and m.speed * m.steps * plan.dt == pytest.approx(m.drop, rel=1e-12)
    assert m.meshes == ["bottom", "plate"]
    text = render_deck_text(plan)
    assert text.count("move/mesh mesh bottom linear 0.0 0.0 -") == 1 and "move/mesh mesh plate linear 0.0 0.0 -" in text
    assert text.index("SILOFLOW_STAGE mobilise") < text.index("SILOFLOW_STAGE resettle") < text.index("write_restart")
    assert {"mobilise", "resettle"} <= set(plan.planned_steps())
    resumed = render_deck_text(plan, resume=True)          # the restart holds the lowered floor
    assert "mobilise" not in resumed.split("stage 3")[1] and "SILOFLOW_STAGE mobilise" not in resumed
    _, plain = variant(quick_dict)
    assert "move/mesh mesh bottom" not in render_deck_text(plain)


def test_mobilise_needs_a_flat_floor_and_a_small_drop(quick_dict):
    data = copy.deepcopy(quick_dict)
    g = {k: v for k, v in data["geometry"].items() if k != "orifice_radius"}
    data["geometry"] = {**g, "kind": "hopper", "outlet_radius": 0.008, "half_angle_deg": 30.0}
    data["fill"]["mobilise"] = {"floor_drop": 0.1}
    with pytest.raises(CaseError, match="fill.mobilise"):
        case_from_dict(data)
    with pytest.raises(CaseError, match="floor_drop"):
        variant(quick_dict, mobilise={"floor_drop": 0.5})


def test_protocols_are_different_fills_for_the_cache(quick_dict):
    from siloflow.fill_cache import fill_key

    class Engine:
        def fill_key_parts(self, plan):
            return {"name": "fake"}
    keys = {fill_key(variant(quick_dict, **fill)[1], Engine()) for fill in
            ({}, {"protocol": "pour"}, {"mobilise": {"floor_drop": 0.1}}, {"frictionless": True})}
    assert len(keys) == 4
