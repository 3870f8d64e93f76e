"""The side walls as LIGGGHTS primitives, their pieces' forces binned in the engine, and the wall
pressure re-binned after the run (issue 56; siloflow.engine.liggghts.side_walls, postprocess.rebin)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from conftest import ROOT, needs_liggghts
from postprocess.dumps import Frame, frames_by_step, primitive_wall_contacts
from postprocess.rebin import rebin_run
import yaml

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine.liggghts.deck import render_deck_text
from siloflow.engine.liggghts.side_walls import binned_pieces, primitive_sides, sampled_walls
from siloflow.engine.tables import wall_force_columns
from siloflow.errors import ReadError


def plan_of(name: str, side_walls: str = "primitive"):
    """The example case ``name``'s plan, its side walls as ``side_walls`` (``engine.side_walls``)."""
    data = yaml.safe_load((ROOT / "decks" / f"{name}.yaml").read_text())
    data.setdefault("engine", {})["side_walls"] = side_walls
    if name == "mesh_quick":                              # its STL beside the copy's new home
        data["geometry"]["files"] = [str(ROOT / "decks" / f) for f in data["geometry"]["files"]]
    return derive(case_from_dict(data))


def test_the_side_walls_are_primitives_unless_the_case_asks_for_sensor_meshes():
    assert primitive_sides(plan_of("quick", "meshes")) == []
    assert "band00_s00.stl" in render_deck_text(plan_of("quick", "meshes"))
    assert "band00_s00.stl" not in render_deck_text(plan_of("quick"))


@pytest.mark.parametrize("name, sides", [("demo", 1), ("eccentric_quick", 1), ("slab_flat_offset", 2),
                                         ("box_quick", 4), ("mesh_quick", 0)])
def test_each_side_piece_is_binned_once_and_the_pieces_tile_each_side(name, sides):
    plan = plan_of(name)
    prims = primitive_sides(plan)
    assert len(prims) == sides
    pieces = binned_pieces(plan)
    side_walls = [w for w in plan.walls if w.role in ("band", "wall")]
    if not sides:                                   # a user's STL silo keeps its sensor meshes
        assert pieces == []
        return
    assert [p["name"] for p in pieces] == [w.name for w in side_walls]
    walls = {w.name: w for w in side_walls}
    for fid in {part["fid"] for p in pieces for part in p["parts"]}:
        on = [p for p in pieces if fid in {part["fid"] for part in p["parts"]}]
        assert all(len(p["parts"]) == 1 for p in on)        # a sensed wall's piece lies on one side
        # the lowest pieces reach down and the highest up without bound; the rest keep their edges
        assert any(p["zlo"] is None for p in on) and any(p["zhi"] is None for p in on)
        for p in on:
            w = walls[p["name"]]
            assert p["zlo"] is None or p["zlo"] == w.z0
            assert p["zhi"] is None or p["zhi"] == w.z1
            assert p["zlo"] is None or p["zlo"] > min(walls[q["name"]].z0 for q in on)


def test_a_cylinder_sector_is_bounded_by_the_half_planes_through_its_edges():
    plan = plan_of("eccentric_quick")
    pieces = {p["name"]: p for p in binned_pieces(plan)}
    for w in plan.walls:
        if w.role != "band":
            continue
        planes = pieces[w.name]["planes"]
        assert len(planes) == 2
        for theta, inside in ((0.5 * (w.theta0 + w.theta1), True), (w.theta1 + 0.3, False), (w.theta0 - 0.3, False)):
            point = (math.cos(theta), math.sin(theta))
            assert all(n[0] * point[0] + n[1] * point[1] >= 0 for n in planes) == inside


def test_the_sampled_quantities_follow_the_wall_force_columns():
    for name in ("demo", "box_quick", "mesh_quick"):
        plan = plan_of(name)
        sampled = sampled_walls(plan, lambda w: w.name)
        assert ["step"] + [f"{s['name']}_{k}" for s in sampled for k in ("fx", "fy", "fz")] == \
            wall_force_columns(plan.walls)
        text = render_deck_text(plan)
        line = next(l for l in text.splitlines() if l.startswith("fix             wall_forces"))
        assert line.count(" v_") + line.count(" f_") == 3 * len(sampled)


def test_the_demo_deck_has_one_primitive_side_wall_and_no_sensor_mesh():
    text = render_deck_text(plan_of("demo"))
    assert "primitive type 2 zcylinder 0.03 0 0 store_force yes" in text
    assert "band00_s00.stl" not in text and "mesh n_meshes 2 meshes bottom plate" in text
    assert text.count("reduce/region") == 13 * 4


def frame(data: dict, step: int = 10) -> Frame:
    return Frame(step, np.zeros((3, 2)), pd.DataFrame(data), kind="atoms", source="test")


def test_a_primitive_contact_is_placed_on_its_wall():
    grains = {"id": [1, 2], "x": [0.009, 0.0], "y": [0.0, -0.0095], "z": [0.05, 0.07], "radius": [0.001] * 2,
              "fx": [-1.0, 0.0], "fy": [0.0, 2.0], "fz": [0.1, 0.2]}
    c = primitive_wall_contacts(frame(grains), "zcylinder", [0.01, 0.0, 0.0]).data
    assert np.allclose(c[["xw", "yw", "zw"]].to_numpy(), [[0.01, 0.0, 0.05], [0.0, -0.01, 0.07]])
    assert np.allclose(c[["x1", "y1"]].to_numpy(), [[0.009, 0.0], [0.0, -0.0095]])
    assert list(c.id1) == [1, 2] and list(c.mesh) == [-1, -1]
    p = primitive_wall_contacts(frame(grains), "yplane", [-0.01]).data
    assert np.allclose(p.yw, -0.01) and np.allclose(p.xw, grains["x"])
    with pytest.raises(ReadError):
        primitive_wall_contacts(frame(grains), "zcone", [0.01])


def test_contact_streams_join_per_step():
    a = [Frame(s, np.zeros((3, 2)), pd.DataFrame({"fx": [float(s)]}), kind="entries") for s in (20, 10)]
    b = [Frame(s, np.zeros((3, 2)), pd.DataFrame({"fx": [1.0, 2.0]}), kind="entries") for s in (10, 30)]
    joined = list(frames_by_step(a, b))
    assert [f.timestep for f in joined] == [10, 20, 30]
    assert list(joined[0].data.fx) == [10.0, 1.0, 2.0]


@needs_liggghts
def test_a_finished_run_rebinned_two_ways_sums_to_the_same_wall_force(tmp_path):
    """A short run with primitive side walls: its binned pieces carry the bed (force balance), and its
    side-wall contacts re-binned two ways sum to the same force in every frame."""
    import siloflow
    from conftest import TINY
    data = {**TINY, "engine": {**TINY["engine"], "side_walls": "primitive"},
            "fill": {**TINY["fill"], "settle": {**TINY["fill"]["settle"], "static_window": 0.03}}}
    case = tmp_path / "tiny.yaml"
    case.write_text(yaml.safe_dump(data))
    run = siloflow.run(case, tmp_path / "run")
    folder, summary = run.folder, run.summary
    text = (folder / "in.liggghts").read_text()
    assert "primitive type 2 zcylinder" in text and "band00_s00.stl" not in text
    assert abs(summary["force_balance"]["ratio"] - 1.0) < 0.02
    coarse = rebin_run(folder, [0.0, 0.02, 0.08], sectors=3)
    fine = rebin_run(folder, [0.0, 0.005, 0.01, 0.02, 0.04, 0.08], sectors=8)
    assert len(coarse.totals) == len(fine.totals) > 10
    for r in (coarse, fine):
        sums = r.pieces.groupby("step")[["fx", "fy", "fz"]].sum()
        assert np.allclose(sums.to_numpy(), r.totals.set_index("step").loc[sums.index].to_numpy(), rtol=1e-9, atol=1e-12)
    assert np.allclose(coarse.totals.fz, fine.totals.fz)
    assert (coarse.table.static_frames >= 3).all()
    # the bed presses on the wall: the lowest band's re-binned static pressure is positive
    assert coarse.table[coarse.table.band == 0].static_pressure.mean() > 0


@pytest.mark.parametrize("name", ["quick", "box_quick"])
def test_without_wall_pressure_the_side_wall_is_one_sum_over_every_side(name):
    data = yaml.safe_load((ROOT / "decks" / f"{name}.yaml").read_text())
    data.setdefault("outputs", {})["results"] = ["flow_rate", "force_balance"]
    data.setdefault("engine", {})["side_walls"] = "primitive"
    plan = derive(case_from_dict(data))
    pieces = binned_pieces(plan)
    assert [p["name"] for p in pieces] == ["wall"]
    assert len(pieces[0]["parts"]) == len(primitive_sides(plan)) and pieces[0]["zlo"] is None is pieces[0]["zhi"]
    text = render_deck_text(plan)
    assert "variable        wall_fz equal -(" in text and "band00" not in text
