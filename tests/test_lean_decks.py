"""Outputs decide the deck (issue 15): each result asked for adds exactly the deck lines it needs;
asking for the flow rate alone gives the leanest deck."""
from __future__ import annotations

import copy

import pytest

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine.liggghts.deck import render_deck_text


def deck(quick_dict, results, side_walls="primitive", **outputs):
    data = copy.deepcopy(quick_dict)
    data.setdefault("engine", {})["side_walls"] = side_walls
    data["outputs"] = {**{k: v for k, v in data["outputs"].items() if k not in ("dump_interval", "vtk")},
                       "results": results, **outputs}
    case = case_from_dict(data)
    plan = derive(case)
    return plan, render_deck_text(plan)


def commands(text: str) -> set[str]:
    """Each deck line reduced to its command and the style or kind it sets up (names stripped)."""
    out = set()
    for line in text.splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "fix" and len(words) > 3 and words[3] == "ave/time":       # flow and wall forces
            out.add(f"fix ave/time {words[1]}")
        elif words[0] in ("fix", "compute", "dump") and len(words) > 3:
            out.add(f"{words[0]} {words[3]}")
        elif words[0] in ("fix", "compute", "dump"):
            out.add(words[0])
    return out


#: what each result adds to the flow-rate deck, as (command, style) pairs; the one pair/gran/local
#: compute is in every deck with the guard (its overlaps), and the contact results widen its keywords
CONTACT_RESULTS = ("coordination", "force_chains", "coarse_graining")
GUARD_PAIRS = "compute         contacts all pair/gran/local delta"
ADDS = {
    "force_balance": {"fix mesh/surface/stress", "fix ave/time wall_forces"},
    "wall_pressure": {"fix mesh/surface/stress", "fix ave/time wall_forces"},
    "porosity": {"dump custom"},
    "free_surface": {"dump custom"},
    "coordination": {"dump custom", "dump local", "compute wall/gran/local"},
    "force_chains": {"dump custom", "dump local", "compute wall/gran/local"},
    "coarse_graining": {"dump custom", "dump local", "compute wall/gran/local"},
    "vtk": {"dump custom", "dump custom/vtk"},
}


def test_flow_rate_alone_is_the_leanest_deck(quick_dict):
    plan, text = deck(quick_dict, ["flow_rate"])
    assert [w.name for w in plan.walls] == ["wall", "bottom", "plate", "outlet"]      # one plain side wall
    assert "mesh/surface/stress" not in text and "ave/time 1" not in text.replace("flow all ave/time", "")
    assert "wall_forces" not in text and not any(ln.startswith("dump ") for ln in text.splitlines())
    assert [ln for ln in text.splitlines() if "pair/gran/local" in ln and not ln.startswith("#")] == [GUARD_PAIRS]     # the guard's only
    assert "fix             flow all ave/time" in text and "massflow/mesh" in text      # the flow rate itself
    full_plan, full = deck(quick_dict, None, dump_interval=0.1, vtk=True)
    assert len(text.splitlines()) < len(full.splitlines())
    lean_meshes = sum(1 for w in plan.walls if w.is_wall)
    assert lean_meshes < sum(1 for w in full_plan.walls if w.is_wall) / 5


#: the primitive side walls' forces are summed per band sector by one region reduction each
PRIMITIVE_ADDS = {"force_balance": {"compute reduce/region"}, "wall_pressure": {"compute reduce/region"}}


@pytest.mark.parametrize("side_walls", ["primitive", "meshes"])
@pytest.mark.parametrize("result", sorted(ADDS))
def test_each_result_adds_the_lines_it_needs(quick_dict, result, side_walls):
    _, lean = deck(quick_dict, ["flow_rate"], side_walls)
    plan, text = deck(quick_dict, ["flow_rate", result], side_walls)
    added = commands(text) - commands(lean)
    wanted = ADDS[result] | (PRIMITIVE_ADDS.get(result, set()) if side_walls == "primitive" else set())
    assert added == wanted, f"{result} adds {sorted(added)}"
    pairs = [ln for ln in text.splitlines() if "pair/gran/local" in ln and not ln.startswith("#")]
    if result in CONTACT_RESULTS:      # the dumped contacts' keywords, and the guard's delta last
        assert pairs == ["compute         contacts all pair/gran/local pos id force force_normal delta"]
    else:
        assert pairs == [GUARD_PAIRS]
    if result == "wall_pressure":
        assert sum(1 for w in plan.walls if w.role == "band") == 6 * 4           # bands x sectors
    else:
        assert not any(w.role == "band" for w in plan.walls)


def test_dump_interval_follows_the_analyses(quick_dict):
    """Without outputs.dump_interval: as often as the most demanding analysis needs over the
    discharge (coarse-graining's time average 50 frames, the free surface 20), at most the static
    window; with it, the case's."""
    plan, _ = deck(quick_dict, ["flow_rate", "free_surface"])
    dis = quick_dict["discharge"]["duration"]
    static = quick_dict["fill"]["settle"]["static_window"]
    assert plan.outputs.dump_every * plan.dt == pytest.approx(min(static, dis / 20), rel=1e-3)
    plan, _ = deck(quick_dict, ["flow_rate", "coarse_graining"])
    assert plan.outputs.dump_every * plan.dt == pytest.approx(min(static, dis / 50), rel=1e-3)
    plan, _ = deck(quick_dict, ["flow_rate", "porosity"], dump_interval=0.05)
    assert plan.outputs.dump_every * plan.dt == pytest.approx(0.05, rel=1e-3)


def test_a_result_listed_twice_or_unknown_is_refused(quick_dict):
    from siloflow.errors import CaseError
    for bad in (["flow_rate", "flow_rate"], ["flow_rates"]):
        data = copy.deepcopy(quick_dict)
        data["outputs"]["results"] = bad
        with pytest.raises(CaseError, match="outputs.results"):
            case_from_dict(data)


def test_without_the_guard_the_leanest_deck_has_no_contact_compute(quick_dict):
    data = copy.deepcopy(quick_dict)
    data.setdefault("engine", {})["guard"] = {"enabled": False}
    _, text = deck(data, ["flow_rate"])
    assert "pair/gran/local" not in text and "guard_" not in text
    assert "thermo_style    custom step time atoms c_ke c_pe c_mass_silo f_massflow[1] f_massflow[2]\n" in text
