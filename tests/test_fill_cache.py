"""The fill cache (siloflow.fill_cache): what defines a fill misses the cache, what comes after
it hits; entries are published whole, checked, listed and cleared; two runs of one key wait."""
from __future__ import annotations

import copy
import json
import shutil
import threading
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.errors import SetupError
from siloflow.fill_cache import FillCache, fill_key, fill_key_inputs, key_of


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


def put(cache, inputs, files, source="run"):
    """Publish ``files`` under the key of ``inputs`` (as run_with_cache does)."""
    return cache.put(key_of(inputs), files, inputs, source=source)


def test_entries_are_published_whole_checked_listed_and_cleared(tmp_path, quick_dict):
    cache = FillCache(tmp_path / "cache")
    inputs = fill_key_inputs(derive(case_from_dict(quick_dict)), FakeEngine())
    k = key_of(inputs)
    assert cache.get(k) is None and cache.entries() == []
    entry = cache.put(k, {"settled.restart": b"\x00bed", "log.liggghts": b"log\n"}, inputs, source="run1")
    assert entry.files["settled.restart"].read_bytes() == b"\x00bed"
    again = cache.put(k, {"settled.restart": b"other"}, inputs, source="run2")        # first one stays
    assert again.info["source"] == "run1" and [e.key for e in cache.entries()] == [k]
    (entry.folder / "settled.restart").write_bytes(b"tampered")
    assert cache.get(k) is None                                   # a changed file is no entry
    cleared = cache.clear(k[:10])                                 # ... and is not cleared either
    assert cleared.removed == [] and "changed since siloflow wrote it" in cleared.left[k]
    (entry.folder / "settled.restart").write_bytes(b"\x00bed")
    assert cache.clear(k[:10]).removed == [k] and cache.entries() == []
    assert not (tmp_path / "cache" / "fills" / k).exists()
    assert not list((tmp_path / "cache" / "fills").glob(".*.tmp"))
    with pytest.raises(SetupError, match="not the hash of its inputs"):
        cache.put("ab" * 32, {"bed": b"1"}, inputs, source="x")


def test_a_second_run_of_the_same_key_waits_for_the_first(tmp_path):
    cache = FillCache(tmp_path)
    order = []
    k = key_of({"bed": 1})

    def first():
        with cache.lock(k):
            order.append("first in")
            time.sleep(0.3)
            put(cache, {"bed": 1}, {"bed": b"1"}, source="first")
            order.append("first out")

    t = threading.Thread(target=first)
    t.start()
    time.sleep(0.05)
    with cache.lock(k):
        order.append("second in")
        assert cache.get(k) is not None           # the first one's bed is there for it
    t.join()
    assert order == ["first in", "first out", "second in"]


def test_cache_commands_list_and_clear(tmp_path, quick_dict):
    from typer.testing import CliRunner
    from siloflow.cli import app
    cache = FillCache(tmp_path)
    k = put(cache, {"bed": 1}, {"bed": b"12345"}, source="/runs/x").key
    runner = CliRunner()
    listed = runner.invoke(app, ["cache", "list", "--cache", str(tmp_path)], env={"COLUMNS": "400"})
    assert listed.exit_code == 0 and k[:16] in listed.output and "/runs/x" in listed.output
    cleared = runner.invoke(app, ["cache", "clear", "--cache", str(tmp_path)])
    assert cleared.exit_code == 0 and "removed 1" in cleared.output and cache.entries() == []
    missing = runner.invoke(app, ["cache", "clear", "0123", "--cache", str(tmp_path)])
    assert missing.exit_code == 1 and "no fill '0123' was removed" in missing.output


@pytest.mark.parametrize("via_env", [False, True], ids=["--cache", "SILOFLOW_CACHE"])
def test_cache_clear_leaves_a_users_folder_and_a_link(tmp_path, via_env):
    """Issue 34.1: a folder siloflow never wrote under fills/ (and a symbolic link there, and the
    folder it points to) survives ``cache clear``, listed with the reason; the real entry goes."""
    from typer.testing import CliRunner
    from siloflow.cli import app
    proj = tmp_path / "proj"
    thesis = proj / "fills" / "important_data" / "chapter1.tex"
    thesis.parent.mkdir(parents=True)
    thesis.write_text("thesis")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "data.csv").write_text("1,2\n")
    (proj / "fills" / ("cd" * 32)).symlink_to(elsewhere, target_is_directory=True)
    k = put(FillCache(proj), {"bed": 2}, {"bed": b"bytes"}).key
    args, env = (["--cache", str(proj)], {}) if not via_env else ([], {"SILOFLOW_CACHE": str(proj)})
    runner = CliRunner()
    listed = runner.invoke(app, ["cache", "list", *args], env={"COLUMNS": "400", **env})
    assert listed.exit_code == 0 and "1 fill(s)" in listed.output and "important_data" in listed.output
    cleared = runner.invoke(app, ["cache", "clear", *args], env={"COLUMNS": "400", **env})
    assert cleared.exit_code == 0, cleared.output
    assert "removed 1 fill(s)" in cleared.output and "2 other item(s)" in cleared.output
    assert "important_data: its name is not a fill key" in cleared.output
    assert "symbolic link" in cleared.output
    assert thesis.read_text() == "thesis" and (elsewhere / "data.csv").read_text() == "1,2\n"
    assert (proj / "fills" / ("cd" * 32)).is_symlink()
    assert not (proj / "fills" / k).exists()


def test_a_fill_stored_under_another_key_is_no_entry(tmp_path, quick_dict):
    """Issue 34.3: the density-1500 bed copied over the density-2500 bed's key is not used for
    the 2500 case (nor listed, nor cleared); the true entry of another key is still found."""
    cache = FillCache(tmp_path)
    dense = fill_key_inputs(derive(case_from_dict(quick_dict)), FakeEngine())
    light = fill_key_inputs(derive(case_from_dict(changed(quick_dict, "materials.particle.density", 1500.0))),
                            FakeEngine())
    a = put(cache, dense, {"bed": b"dense bed"})
    b = put(cache, light, {"bed": b"light bed"})
    shutil.rmtree(a.folder)
    shutil.copytree(b.folder, a.folder)
    assert cache.get(a.key) is None and cache.get(b.key) is not None
    assert "another key" in cache.check(a.key)[1]
    assert [e.key for e in cache.entries()] == [b.key]
    done = cache.clear()
    assert done.removed == [b.key] and a.folder.is_dir() and "another key" in done.left[a.key]


def test_an_entry_with_a_foreign_file_or_a_missing_one_is_left(tmp_path):
    cache = FillCache(tmp_path)
    a = put(cache, {"bed": 1}, {"bed": b"1", "log": b"2"})
    (a.folder / "notes.txt").write_text("mine")
    assert cache.get(a.key) is None and "notes.txt" in cache.check(a.key)[1]
    assert cache.clear().removed == [] and (a.folder / "notes.txt").read_text() == "mine"
    (a.folder / "notes.txt").unlink()
    (a.folder / "log").unlink()
    assert "missing: log" in cache.check(a.key)[1] and cache.clear().removed == []
    # a folder in a key's place is never replaced by a publication: it is left, and said
    with pytest.raises(SetupError, match="in its way"):
        put(cache, {"bed": 1}, {"bed": b"1", "log": b"2"})
    assert sorted(p.name for p in a.folder.iterdir()) == ["bed", "entry.json", "key.json"]


def test_an_entry_in_use_is_not_cleared(tmp_path):
    cache = FillCache(tmp_path)
    a = put(cache, {"bed": 1}, {"bed": b"1"})
    held = threading.Event()
    release = threading.Event()

    def run():
        with cache.lock(a.key):
            held.set()
            release.wait(5)

    t = threading.Thread(target=run)
    t.start()
    held.wait(5)
    try:
        done = cache.clear()
    finally:
        release.set()
        t.join()
    assert done.removed == [] and done.left == {a.key: "in use by a running run"} and cache.get(a.key)


class FillEngine(FakeEngine):
    """A fake engine that 'runs' a fill: it writes a record and hands the bed to the cache."""

    def execute(self, folder, progress=None):
        (folder / "bed.restart").write_bytes(b"settled bed")

    def collect(self, folder):
        from siloflow.run_folder import RunRecord
        return RunRecord(folder=str(folder), engine=self.name, command=["fake"], returncode=0, wall_time=1.0,
                         stage_steps={"fill": 0}, inserted=10, settled_ke_pe=1e-7, completed=True)

    def fill_files(self, folder):
        return {"bed.restart": (folder / "bed.restart").read_bytes()}

    def start_from_fill(self, folder, files, progress=None):
        return self.collect(folder)


def test_a_full_cache_disk_costs_the_reuse_not_the_run(tmp_path, quick_dict, monkeypatch):
    """Issue 34.4: the engine finished, then the cache cannot take its bed (the disk is full):
    a warning naming the cache, the run's record is written, and the run says it published nothing."""
    import errno
    import json
    from siloflow.fill_cache import run_with_cache
    plan = derive(case_from_dict(quick_dict))
    cache = FillCache(tmp_path / "cache")
    folder = tmp_path / "run"
    folder.mkdir()

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(cache.fills / "x"))

    # the engine writes its bed before the disk fills: only the cache's writes fail
    warnings = []
    engine = FillEngine()
    real_put = FillCache.put

    def put_on_full_disk(self, key, files, inputs, source):
        with monkeypatch.context() as m:
            m.setattr("pathlib.Path.write_bytes", full)
            return real_put(self, key, files, inputs, source)

    monkeypatch.setattr(FillCache, "put", put_on_full_disk)
    record = run_with_cache(engine, folder, plan, cache, on_warning=warnings.append)
    assert record.completed and record.fill_cache["published"] is False and record.fill_cache["hit"] is False
    assert len(warnings) == 1 and str(cache.fills) in warnings[0] and "the disk is full" in warnings[0]
    assert "results are not affected" in warnings[0]
    written = json.loads((folder / "run_record.json").read_text())
    assert written["fill_cache"]["warning"] == warnings[0]
    assert cache.entries() == [] and not list(cache.fills.glob(".*.tmp"))
    # a cache that cannot even be made (a file where its folder should be): the run runs uncached
    blocked = tmp_path / "blocked"
    blocked.write_text("a file")
    warnings.clear()
    record = run_with_cache(engine, folder, plan, FillCache(blocked), on_warning=warnings.append)
    assert record.completed and "cannot be used" in warnings[0] and blocked.read_text() == "a file"


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
    from postprocess.report import post_process as analyse
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
    setup = (run_folder / "in.liggghts").read_text().split("# ---------------------------------------------------------------- stage 1")[0]
    assert not [ln for ln in setup.splitlines() if ln.split()[:1] == ["dump"]]
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


KINDS = ("intact", "foreign_folder", "foreign_keyed_folder", "foreign_file", "link", "swapped", "truncated",
         "edited", "extra_file", "bad_record")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kinds=st.lists(st.sampled_from(KINDS), min_size=1, max_size=8), data=st.data())
def test_cache_folders_of_any_make_end_in_a_refusal_or_a_right_answer(tmp_path_factory, kinds, data):
    """Whatever is under fills/ (foreign files and folders, links, swapped, truncated and edited
    entries), get() answers only with an intact entry of its own key, and clear() removes exactly
    the intact entries: every byte of everything else, and of what links point to, survives."""
    root = tmp_path_factory.mktemp("cache")
    outside = tmp_path_factory.mktemp("outside")
    (outside / "keep.txt").write_bytes(b"outside")
    cache = FillCache(root)
    intact = set()
    for n, kind in enumerate(kinds):
        blob = data.draw(st.binary(min_size=1, max_size=64), label=f"bytes {n}")
        entry = put(cache, {"n": n, "kind": kind}, {"bed": blob, "log": b"log %d" % n}, source=f"run{n}")
        if kind == "intact":
            intact.add(entry.key)
        elif kind in ("foreign_folder", "foreign_keyed_folder", "foreign_file", "link"):
            shutil.rmtree(entry.folder)
            name = entry.key if kind == "foreign_keyed_folder" else f"user_{n}"
            if kind == "foreign_file":
                (cache.fills / name).write_bytes(blob)
            elif kind == "link":
                (cache.fills / entry.key).symlink_to(outside, target_is_directory=True)
            else:
                (cache.fills / name).mkdir()
                (cache.fills / name / "thesis.tex").write_bytes(blob)
        elif kind == "swapped":
            other = put(cache, {"n": n, "other": True}, {"bed": blob + b"x"})
            shutil.rmtree(entry.folder)
            shutil.copytree(other.folder, entry.folder)
            intact.add(other.key)
        elif kind == "truncated":
            (entry.folder / "bed").write_bytes(blob[:-1])
        elif kind == "edited":
            (entry.folder / "log").write_bytes(b"LOG %d" % n)
        elif kind == "extra_file":
            (entry.folder / "mine.txt").write_bytes(blob)
        elif kind == "bad_record":
            (entry.folder / "entry.json").write_bytes(blob)

    def snapshot():
        files = {}
        for base in (root, outside):
            for p in base.rglob("*"):
                if p.is_file() and not p.is_symlink():
                    files[str(p)] = p.read_bytes()
        return files

    for p in cache.fills.iterdir():
        got = cache.get(p.name)
        assert (got is not None) == (p.name in intact)
        if got is not None:
            assert got.key == p.name and key_of(json.loads((got.folder / "key.json").read_text())) == p.name
    before = snapshot()
    done = cache.clear()
    assert set(done.removed) == intact
    after = snapshot()
    kept = {path: b for path, b in before.items() if not any(f"/fills/{k}/" in path for k in intact)}
    assert {path: after.get(path) for path in kept} == kept
    assert cache.entries() == []


# ---------------------------------------------------------------- issue 55.3: the cached bed is read back and checked
def _bed_of(plan, **changes):
    """The settled bed ``plan`` fills, as an engine reads it back (``SettledBed``), with ``changes``."""
    import numpy as np
    from siloflow.engine.base import SettledBed
    n = plan.expected_atoms
    sp = plan.species[0]
    fields = {"types": np.ones(n, int), "radius": np.full(n, sp.radius), "mass": np.full(n, sp.mass),
              "box": {"xlo": -0.02, "xhi": 0.02, "ylo": -0.02, "yhi": 0.02, "zlo": -0.03, "zhi": 0.31}}
    return SettledBed(**{**fields, **changes})


def test_a_bed_read_back_is_compared_with_the_plan(quick_dict):
    """Atom count, atom types, radii, grain masses (the density they give), a size class's share
    and the box: each one that differs is named; the plan's own bed passes."""
    import numpy as np
    from siloflow.fill_cache import bed_problems
    plan = derive(case_from_dict(quick_dict))
    bed = _bed_of(plan)
    box = dict(bed.box)
    assert bed_problems(plan, bed, box) == []
    n, sp = plan.expected_atoms, plan.species[0]
    assert bed_problems(plan, _bed_of(plan, types=np.ones(n - 10, int), radius=np.full(n - 10, sp.radius),
                                      mass=np.full(n - 10, sp.mass)), box) == []     # lost in the fill: within 1 %
    short = bed_problems(plan, _bed_of(plan, types=np.ones(n // 2, int), radius=np.full(n // 2, sp.radius),
                                       mass=np.full(n // 2, sp.mass)), box)
    assert any(f"holds {n // 2} atoms where this case's bed holds {n}" in p for p in short)
    light = bed_problems(plan, _bed_of(plan, mass=np.full(n, sp.mass * 0.6)), box)
    assert len(light) == 1 and "density of 1500 kg/m3" in light[0] and "(2500 kg/m3)" in light[0]
    assert "radius of 0.002 m" in bed_problems(plan, _bed_of(plan, radius=np.full(n, 0.002)), box)[0]
    types = np.ones(n, int)
    types[:3] = 2
    assert any("atom type 2 is no species" in p for p in bed_problems(plan, _bed_of(plan, types=types), box))
    nan = np.full(n, sp.mass)
    nan[7] = np.nan
    assert "1 of 5000 grains weigh nan kg" in bed_problems(plan, _bed_of(plan, mass=nan), box)[0]
    wide = bed_problems(plan, bed, {**box, "xlo": -0.03})
    assert wide == ["its simulation box is not this case's (xlo -0.02 m, not -0.03)"]


def test_a_size_class_far_from_its_share_is_named(quick_dict):
    """Two sizes in equal numbers: a bed of 30 % small grains is not this case's (a share drawn at
    random strays a few per cent at most); one of 48 % is."""
    import numpy as np
    from siloflow.fill_cache import bed_problems
    quick_dict["particles"] = {"kind": "polydisperse_spheres", "radii": [0.0015, 0.0012], "fractions": [0.5, 0.5],
                               "basis": "number"}
    plan = derive(case_from_dict(quick_dict))
    n = plan.expected_atoms
    big, small = plan.species

    def bed(share):
        k = round(share * n)
        types = np.array([1] * (n - k) + [2] * k)
        return _bed_of(plan, types=types, radius=np.where(types == 1, big.radius, small.radius),
                       mass=np.where(types == 1, big.mass, small.mass))
    assert bed_problems(plan, bed(0.48)) == []
    problems = bed_problems(plan, bed(0.3))
    assert len(problems) == 2 and f"species '{small.name}' (atom type 2): {round(0.3 * n)} grains" in problems[1]


@pytest.mark.engine
@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS is not installed")
def test_a_forged_entry_is_refused_and_the_run_fills_its_own_bed(tmp_path):
    """Issue 55.3: the density-1500 bed copied under the density-2500 case's key, with key.json
    and entry.json written for that key, passes the entry's hashes; the run reads the bed back,
    refuses it with a warning naming the density, fills its own bed (its mass, not the forged
    one's) and publishes nothing over the forged entry. A cache hit of the true bed still runs."""
    import subprocess
    import sys

    import yaml

    from siloflow.engine import get_engine

    from conftest import TINY
    data = changed(TINY, "outputs.dump_interval", 0.1)
    dense_case, light_case = tmp_path / "dense.yaml", tmp_path / "light.yaml"
    dense_case.write_text(yaml.safe_dump(data))
    light_case.write_text(yaml.safe_dump(changed(data, "materials.particle.density", 1500.0)))
    cache = FillCache(tmp_path / "cache")

    def run(case, out):
        proc = subprocess.run([sys.executable, "-m", "siloflow.cli", "run", str(case), "-o", str(tmp_path / out),
                               "--cache", str(cache.root)], capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        assert "Traceback" not in proc.stderr
        summary = json.loads((tmp_path / out / "results" / "summary.json").read_text())
        return proc, json.loads((tmp_path / out / "run_record.json").read_text())["fill_cache"], summary

    _, light_fill, light = run(light_case, "light")
    engine = get_engine("liggghts")
    inputs = fill_key_inputs(derive(case_from_dict(data)), engine)
    dense_key = key_of(inputs)
    forged = cache.fills / dense_key
    shutil.copytree(cache.fills / light_fill["key"], forged)
    (forged / "key.json").write_text(json.dumps(inputs, indent=1, sort_keys=True))
    info = json.loads((forged / "entry.json").read_text())
    (forged / "entry.json").write_text(json.dumps({**info, "key": dense_key}, indent=1))
    assert cache.get(dense_key) is not None                   # the hashes cannot tell
    before = {p.name: p.read_bytes() for p in forged.iterdir()}

    proc, fill, dense = run(dense_case, "dense")
    assert fill["hit"] is False and fill["published"] is False
    assert "does not hold this case's settled bed" in fill["warning"] and "density of 1500 kg/m3" in fill["warning"]
    said = " ".join(proc.stderr.split())                     # the console wraps its lines
    assert "does not hold this case's settled bed" in said and "density of 1500 kg/m3" in said
    assert "fill from the cache" not in proc.stdout
    mass = 400 * 2500.0 * 4 / 3 * 3.141592653589793 * 0.00125 ** 3
    assert dense["initial_mass_kg"] == pytest.approx(mass, rel=1e-6)
    assert light["initial_mass_kg"] == pytest.approx(mass * 0.6, rel=1e-6)
    assert {p.name: p.read_bytes() for p in forged.iterdir()} == before       # the forged entry is left as it was
    # the true bed passes its check: a second light run starts from it
    _, again, light2 = run(light_case, "light2")
    assert again["hit"] is True and "warning" not in again
    assert light2["initial_mass_kg"] == pytest.approx(light["initial_mass_kg"], rel=1e-12)
