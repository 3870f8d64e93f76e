"""The fill cache (siloflow.fill_cache): what defines a fill misses the cache, what comes after
it hits; entries are published whole, checked, listed and cleared; two runs of one key wait."""
from __future__ import annotations

import copy
import shutil
import threading
import time

import pytest

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.fill_cache import FillCache, fill_key, fill_key_inputs


class FakeEngine:
    """An engine's fill-key parts without the engine: name and version."""

    name = "fake"

    def __init__(self, version="1.0", box=1.0):
        self._version, self._box = version, box

    def fill_key_parts(self, plan):
        return {"name": self.name, "version": self._version, "ranks": plan.engine.ranks, "box": self._box}


def key(data, engine=None):
    return fill_key(derive(case_from_dict(data)), engine or FakeEngine())


def changed(data, path, value):
    out = copy.deepcopy(data)
    node = out
    *parents, last = path.split(".")
    for p in parents:
        node = node.setdefault(p, {})
    node[last] = value
    return out


#: every field that defines the fill, with another valid value
FILL_FIELDS = [
    ("particles.radius", 0.0014), ("materials.particle.density", 2400.0),
    ("materials.particle.youngs_modulus", 6.0e6), ("materials.particle.poisson_ratio", 0.25),
    ("materials.wall.youngs_modulus", 7.0e6), ("materials.particle_particle.friction", 0.4),
    ("materials.particle_particle.restitution", 0.6), ("materials.particle_wall.friction", 0.3),
    ("materials.particle_wall.restitution", 0.4), ("materials.particle_particle.rolling_friction", 0.05),
    ("fill.count", 4000), ("fill.batch_volume_fraction", 0.2), ("fill.frictionless", True),
    ("fill.pour_radius", 0.008), ("fill.settle.ke_pe_ratio", 1.0e-6), ("fill.settle.check_interval", 0.03),
    ("fill.settle.max_time", 2.0), ("geometry.radius", 0.016), ("geometry.height", 0.32),
    ("geometry.mesh_segments", 64), ("gravity", 9.0), ("seed", 777), ("engine.timestep_fraction", 0.1),
    ("engine.ranks", 1),
]
#: fields that come after the fill
AFTER_FIELDS = [
    ("geometry.orifice_radius", 0.006), ("discharge.duration", 0.5), ("outputs.dump_interval", 0.05),
    ("outputs.sample_interval", 0.004), ("outputs.vtk", False), ("fill.settle.static_window", 0.03),
    ("discharge.opening", {"speed": 2.0}), ("name", "another"), ("description", "other words"),
]


@pytest.mark.parametrize("path,value", FILL_FIELDS, ids=[p for p, _ in FILL_FIELDS])
def test_changing_what_defines_the_fill_misses(quick_dict, path, value):
    assert key(changed(quick_dict, path, value)) != key(quick_dict)


@pytest.mark.parametrize("path,value", AFTER_FIELDS, ids=[p for p, _ in AFTER_FIELDS])
def test_changing_what_comes_after_the_fill_hits(quick_dict, path, value):
    assert key(changed(quick_dict, path, value)) == key(quick_dict)


def test_sensor_meshes_are_another_fill(quick_dict):
    """The same wall split into band x sector meshes fills another bed (seams: measured in
    benchmarks/results/skip/seams.csv), so a lean deck's fill is not a sensor deck's; dumps,
    contacts and sampling do not touch the bed and share it."""
    lean = changed(quick_dict, "outputs", {"results": ["flow_rate", "force_balance"]})
    sensed = changed(quick_dict, "outputs", {"results": ["flow_rate", "wall_pressure"]})
    dumped = changed(quick_dict, "outputs", {"results": ["flow_rate", "wall_pressure", "coordination", "vtk"]})
    assert key(lean) != key(sensed) and key(sensed) == key(dumped) == key(quick_dict)


def test_engine_version_and_its_parts_are_in_the_key(quick_dict):
    assert key(quick_dict, FakeEngine("1.0")) != key(quick_dict, FakeEngine("1.1"))
    assert key(quick_dict, FakeEngine(box=1.0)) != key(quick_dict, FakeEngine(box=2.0))


def test_a_hopper_orifice_shapes_the_fill(quick_dict):
    """In a hopper the cone's lower edge is the orifice: another orifice is another silo."""
    g = {k: v for k, v in quick_dict["geometry"].items() if k != "orifice_radius"}
    hopper = changed(quick_dict, "geometry", {**g, "kind": "hopper", "outlet_radius": 0.008, "half_angle_deg": 30.0})
    assert key(changed(hopper, "geometry.outlet_radius", 0.006)) != key(hopper)
    inputs = fill_key_inputs(derive(case_from_dict(hopper)), FakeEngine())
    assert "outlet_radius" in inputs["geometry"]


def test_entries_are_published_whole_checked_listed_and_cleared(tmp_path, quick_dict):
    cache = FillCache(tmp_path / "cache")
    k = key(quick_dict)
    assert cache.get(k) is None and cache.entries() == []
    entry = cache.put(k, {"settled.restart": b"\x00bed", "log.liggghts": b"log\n"}, {"what": 1}, source="run1")
    assert entry.files["settled.restart"].read_bytes() == b"\x00bed"
    again = cache.put(k, {"settled.restart": b"other"}, {}, source="run2")        # first one stays
    assert again.info["source"] == "run1" and [e.key for e in cache.entries()] == [k]
    (entry.folder / "settled.restart").write_bytes(b"tampered")
    assert cache.get(k) is None                                   # a changed file is no entry
    assert cache.clear(k[:10]) == 1 and cache.entries() == []
    assert not list((tmp_path / "cache" / "fills").glob(".*.tmp"))


def test_a_second_run_of_the_same_key_waits_for_the_first(tmp_path):
    cache = FillCache(tmp_path)
    order = []

    def first():
        with cache.lock("k"):
            order.append("first in")
            time.sleep(0.3)
            cache.put("k", {"bed": b"1"}, {}, source="first")
            order.append("first out")

    t = threading.Thread(target=first)
    t.start()
    time.sleep(0.05)
    with cache.lock("k"):
        order.append("second in")
        assert cache.get("k") is not None           # the first one's bed is there for it
    t.join()
    assert order == ["first in", "first out", "second in"]


def test_cache_commands_list_and_clear(tmp_path, quick_dict):
    from typer.testing import CliRunner
    from siloflow.cli import app
    cache = FillCache(tmp_path)
    cache.put("ab" * 32, {"bed": b"12345"}, {}, source="/runs/x")
    runner = CliRunner()
    listed = runner.invoke(app, ["cache", "list", "--cache", str(tmp_path)], env={"COLUMNS": "400"})
    assert listed.exit_code == 0 and "abababab" in listed.output and "/runs/x" in listed.output
    cleared = runner.invoke(app, ["cache", "clear", "--cache", str(tmp_path)])
    assert cleared.exit_code == 0 and "removed 1" in cleared.output and cache.entries() == []


@pytest.mark.engine
@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")
def test_a_cached_fill_gives_the_same_bed_and_a_lean_early_stopped_discharge(small_run, tmp_path):
    """The small run's settled bed, cached, starts a run with a wider orifice (a flat bottom:
    same fill), a deck without dumps (flow rate and wall pressure only) and an until_steady discharge:
    the cache is hit, the bed is the same (particles and mass exactly, force balance within 1 %),
    and the discharge stops when its rate is known, saying why."""
    import yaml

    from siloflow.case_file import case_from_dict as from_dict
    from siloflow.engine import get_engine
    from siloflow.fill_cache import run_with_cache
    from postprocess.first_results import analyse
    from conftest import SMALL

    case, folder, record, summary = small_run
    engine = get_engine("liggghts")
    cache = FillCache(tmp_path / "cache")
    small = derive(case)
    cache.put(fill_key(small, engine), engine.fill_files(folder), fill_key_inputs(small, engine), source=str(folder))

    data = yaml.safe_load(SMALL.read_text())
    data["geometry"]["orifice_radius"] = 0.0065          # D0/d 5.2 (4.4 in the cached run): both flow
    data["outputs"] = {"sample_interval": 0.005, "results": ["flow_rate", "wall_pressure"]}   # sensors, no dumps
    data["discharge"] = {"until_steady": True, "precision": 0.04, "batch_time": 0.05, "max_time": 1.2}
    variant = from_dict(data)
    plan = derive(variant)
    assert fill_key(plan, engine) == fill_key(small, engine)
    hits = []
    run_folder = engine.prepare(variant, tmp_path / "variant", plan=plan)
    lean = run_with_cache(engine, run_folder, plan, cache, on_hit=hits.append)
    assert hits == [fill_key(plan, engine)] and lean.fill_cache["hit"] is True
    result = analyse(run_folder)
    # the same bed: the restart carries it, so particles and mass are exact
    assert result["particles_inserted"] == summary["particles_inserted"]
    assert result["initial_mass_kg"] == pytest.approx(summary["initial_mass_kg"], rel=1e-12)
    assert result["force_balance"]["ratio"] == pytest.approx(summary["force_balance"]["ratio"], abs=0.01)
    # the deck without dumps keeps the cached run's sensor meshes (another partition is another fill)
    assert any(w.role == "band" for w in plan.walls) and len(result["bands"]) > 0
    assert "dump" not in (run_folder / "in.liggghts").read_text().split("# ---------------------------------------------------------------- stage 1")[0].replace("dump_", "")
    # the early stop: said why, and it stopped before the cap when the rate was known
    stop = result["discharge_stop"]
    assert stop["reason"] in ("steady", "max_time", "empty")      # not "clogged": this orifice flows
    if stop["reason"] == "steady":
        assert stop["relative_error"] < 0.04
        assert result["flow_rate"]["t_end"] - result["time_open_s"] < 1.2 - 0.05
    # the larger orifice is the variant's own (not the cached run's, which a restart would restore):
    # Beverloo's (D0 - 1.5 d)^2.5 gives 1.84 x the 11 mm orifice's rate
    ratio = result["flow_rate"]["rate"] / summary["flow_rate"]["rate"]
    assert 1.45 < ratio < 2.3, ratio
