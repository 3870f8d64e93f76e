"""Issue 55 (round 4), run folders: an engine's outputs of any name are recorded as the run writes
them, so that ``--force`` replaces a finished folder a second time and still refuses a user's file;
one siloflow command at a time writes a folder (its lock); ``open_run(unfinished=True)`` reads a run
that left no run record yet."""
from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

import siloflow
from siloflow.case_file import case_from_dict
from siloflow.engine import LiggghtsEngine
from siloflow.engine.base import engine_writes
from siloflow.errors import ReadError, SetupError
from siloflow.run_folder import (
    MANIFEST_NAME,
    RunFolder,
    folder_lock,
    foreign_entries,
    lock_path,
    read_manifest,
    write_status,
)
from siloflow.runs import UnfinishedRunWarning, prepare_resume, prepare_run

from conftest import ROOT
from test_engine_base import FakeEngine


def _cli(*args, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "siloflow.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, "COLUMNS": "400", **(env or {})})


def _tree(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- item 1: the engine's outputs
class NewNamesEngine(FakeEngine):
    """The fake engine, whose run also leaves files under names no list of siloflow's knows: one in a
    folder siloflow makes, one in a folder of its own (as LIGGGHTS 3.8's particles_boundingBox_*.vtk
    beside its VTK dumps); with ``interrupt``, Ctrl-C arrives once they are written."""

    def __init__(self, interrupt: bool = False):
        super().__init__("ok")
        self.interrupt = interrupt

    def launch(self, folder, plan, progress, resume):
        launched = super().launch(folder, plan, progress, resume)
        (folder / "output" / "vtk").mkdir(exist_ok=True)
        (folder / "output" / "vtk" / "particles_mystery_300.vtk").write_text("# vtk DataFile\n")
        (folder / "output" / "own").mkdir()
        (folder / "output" / "own" / "state.bin").write_bytes(b"\x00\x01")
        if self.interrupt:
            write_status(folder, "interrupted", stage="discharge")
            raise KeyboardInterrupt
        return launched


#: what the fake engine's run leaves under names siloflow has no list of (its screen and state too)
NEW_NAMES = ["output/fake_state.json", "output/own/state.bin", "output/vtk/particles_mystery_300.vtk",
             "screen.fake.txt"]


def _finished(tmp_path, quick_dict) -> tuple[NewNamesEngine, Path]:
    engine = NewNamesEngine()
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    engine.execute(folder)
    engine.collect(folder)
    return engine, folder


def test_an_engine_output_of_a_new_name_is_recorded_and_replaced_by_force(tmp_path, quick_dict):
    engine, folder = _finished(tmp_path, quick_dict)
    products = read_manifest(folder)["products"]
    assert sorted(products) == NEW_NAMES                 # the fixed names (tables, record, status) need no record
    assert products["output/own/state.bin"] == hashlib.sha256(b"\x00\x01").hexdigest()
    assert foreign_entries(folder) == []
    engine.prepare(case_from_dict(quick_dict), folder, force=True)        # the second `make demo`
    assert not (folder / "output" / "own").exists() and not (folder / "output" / "vtk").exists()
    assert foreign_entries(folder) == [] and "products" not in read_manifest(folder)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fake_engine.py", "run"]     # nothing left aside


@pytest.mark.parametrize("change", ["added", "edited", "added_in_engine_folder"])
def test_a_users_file_after_the_run_is_still_refused(tmp_path, quick_dict, change):
    engine, folder = _finished(tmp_path, quick_dict)
    if change == "added":
        (folder / "output" / "vtk" / "my_view.pvsm").write_text("mine")
    elif change == "edited":
        with open(folder / "output" / "vtk" / "particles_mystery_300.vtk", "a") as fh:
            fh.write("# my note\n")
    else:
        (folder / "output" / "own" / "notes.txt").write_text("mine")
    before = _tree(folder)
    with pytest.raises(SetupError, match="did not write|edited since siloflow wrote it"):
        engine.prepare(case_from_dict(quick_dict), folder, force=True)
    assert _tree(folder) == before


def test_a_users_file_there_before_the_run_stays_the_users(tmp_path, quick_dict):
    engine = NewNamesEngine()
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    (folder / "output" / "notes.txt").write_text("mine, written before the run")
    engine.execute(folder)
    assert "output/notes.txt" not in read_manifest(folder).get("products", {})
    assert foreign_entries(folder) == ["output/notes.txt"]


def test_an_interrupted_run_records_what_it_wrote(tmp_path, quick_dict):
    engine = NewNamesEngine(interrupt=True)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(KeyboardInterrupt):
        engine.execute(folder)
    assert sorted(read_manifest(folder)["products"]) == NEW_NAMES
    assert foreign_entries(folder) == []
    engine.prepare(case_from_dict(quick_dict), folder, force=True)
    assert not (folder / "output" / "own").exists()


def test_a_folder_of_an_older_siloflow_falls_back_to_the_engines_names(tmp_path, quick_dict):
    """LIGGGHTS 3.8's dump custom/vtk writes particles_boundingBox_<step>.vtk beside each frame; a
    folder whose manifest recorded no engine output is judged by the names."""
    folder = LiggghtsEngine().prepare(case_from_dict(quick_dict), tmp_path / "run")
    (folder / "output" / "vtk").mkdir(exist_ok=True)
    for step in (0, 12699):
        (folder / "output" / "vtk" / f"particles_{step}.vtk").write_text("x")
        (folder / "output" / "vtk" / f"particles_boundingBox_{step}.vtk").write_text("x")
    assert foreign_entries(folder) == []
    (folder / "output" / "vtk" / "particles_notes.vtk").write_text("x")
    assert foreign_entries(folder) == ["output/vtk/particles_notes.vtk"]


# ----------------------------------------------------------------------------- item 4: one command per folder
SLOW_LIGGGHTS = """#!/bin/sh
# stands in for LIGGGHTS: says so, and takes its time
echo "LIGGGHTS (fake)"
sleep 4
"""


@pytest.fixture
def one_rank_case(tmp_path, quick_dict):
    quick_dict["engine"] = {**quick_dict.get("engine", {}), "ranks": 1}
    path = tmp_path / "t1.yaml"
    path.write_text(yaml.safe_dump(quick_dict))
    return path


@pytest.fixture
def slow_liggghts(tmp_path):
    exe = tmp_path / "slow_liggghts.sh"
    exe.write_text(SLOW_LIGGGHTS)
    exe.chmod(0o755)
    return {"SILOFLOW_LIGGGHTS": str(exe)}


def _refused(done, folder) -> bool:
    return (done.returncode == 1 and "in use by another siloflow command" in done.stderr
            and Path(folder).name in done.stderr and "Traceback" not in done.stderr)


def test_two_renders_into_one_new_folder_one_is_refused(tmp_path, quick_dict):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(yaml.safe_dump(quick_dict))
    quick_dict["fill"]["count"] -= 10
    b.write_text(yaml.safe_dump(quick_dict))
    folder = tmp_path / "R"
    for attempt in range(2):
        procs = [subprocess.Popen([sys.executable, "-m", "siloflow.cli", "render", str(case), "-o", str(folder)],
                                  cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env={**os.environ, "COLUMNS": "400"}) for case in (a, b)]
        results = [p.communicate(timeout=300) + (p.returncode,) for p in procs]
        assert sorted(rc for *_, rc in results) == [0, 1], results
        loser = next(err for _, err, rc in results if rc == 1)
        assert ("in use by another siloflow command" in loser or "already exists and is not empty" in loser), loser
        assert "Traceback" not in loser
        assert sorted(p.name for p in tmp_path.iterdir()) == ["R", "a.yaml", "b.yaml"]    # no lock, no .partial
        assert foreign_entries(folder) == []
        shutil.rmtree(folder)


def test_two_runs_into_one_new_folder_one_is_refused(tmp_path, one_rank_case, slow_liggghts):
    """``siloflow run t1.yaml -o R & sleep 0.3; siloflow run t1.yaml -o R``: the second is refused,
    and the first's engine runs in the folder it rendered."""
    folder = tmp_path / "R"
    cmd = [sys.executable, "-m", "siloflow.cli", "run", str(one_rank_case), "-o", str(folder), "--no-post"]
    env = {**os.environ, "COLUMNS": "400", **slow_liggghts}
    first = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    time.sleep(0.3)
    second = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    done = []
    for p in (first, second):
        out, err = p.communicate(timeout=300)
        done.append(subprocess.CompletedProcess(cmd, p.returncode, out, err))
    refused = [d for d in done if _refused(d, folder)]
    assert len(refused) == 1, [(d.returncode, d.stderr[-800:]) for d in done]
    winner = done[1 - done.index(refused[0])]
    assert "LIGGGHTS (fake)" in (folder / "screen.txt").read_text()         # its engine ran in its folder
    assert "Cannot open mesh file" not in winner.stdout + winner.stderr
    assert not lock_path(folder).exists()


def _hold(folder, ready, release):
    with folder_lock(folder):
        ready.set()
        release.wait(60)


@pytest.fixture
def held():
    """Hold a folder's lock in another process, as another siloflow command does."""
    ctx = multiprocessing.get_context("fork")
    holders = []

    def _held(folder):
        ready, release = ctx.Event(), ctx.Event()
        proc = ctx.Process(target=_hold, args=(folder, ready, release))
        proc.start()
        assert ready.wait(30)
        holders.append((proc, release))
    yield _held
    for proc, release in holders:
        release.set()
        proc.join(30)


def test_a_held_lock_refuses_render_run_force_and_resume(tmp_path, quick_dict, one_rank_case, slow_liggghts,
                                                         held):
    new = tmp_path / "new" / "R"
    held(new)
    done = _cli("render", one_rank_case, "-o", new)
    assert _refused(done, new), done.stderr
    done = _cli("run", one_rank_case, "-o", new, env=slow_liggghts)
    assert _refused(done, new), done.stderr
    assert not new.exists()
    with pytest.raises(SetupError, match="in use by another siloflow command"):
        prepare_run(quick_dict, new)
    assert not new.exists()

    old = LiggghtsEngine().prepare(case_from_dict(quick_dict), tmp_path / "old")
    before = _tree(old)
    held(old)
    done = _cli("render", one_rank_case, "-o", old, "--force")
    assert _refused(done, old), done.stderr
    done = _cli("run", "--resume", old, env=slow_liggghts)
    assert _refused(done, old), done.stderr
    with pytest.raises(SetupError, match="in use by another siloflow command"):
        prepare_resume(old)
    with pytest.raises(SetupError, match="in use by another siloflow command"):
        LiggghtsEngine(executable=slow_liggghts["SILOFLOW_LIGGGHTS"]).execute(old)
    assert _tree(old) == before


def test_the_lock_is_held_through_the_run_and_then_released(tmp_path, quick_dict):
    prepared = prepare_run(quick_dict, tmp_path / "R")
    path = lock_path(tmp_path / "R")
    assert path.is_file() and path.read_text().split()[0] == str(os.getpid())
    with prepared:
        with folder_lock(tmp_path / "R"):            # the same process: it nests
            pass
        assert path.is_file()
    assert not path.exists()
    with folder_lock(tmp_path / "R"):               # free again
        pass
    with pytest.raises(SetupError, match="cannot make"):   # a file in the way: named, no lock left
        with folder_lock(tmp_path / "R" / "plan.json" / "x"):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["R"]


# ----------------------------------------------------------------------------- item 10d
#: stages of a run that got into its discharge (steps; the quick case samples every 180)
STAGES = {"fill": 0, "settle": 180, "static": 360, "open": 1800, "discharge": 1800}


def _fake_tables(folder: Path, completed: bool = False) -> None:
    """The fake engine's tables of a run sampled every 180 steps to step 3600, discharging 0.01 kg
    a sample after the opening, and its state (:data:`STAGES`, every grain inserted)."""
    plan = RunFolder(folder).plan
    walls = [w.name for w in plan.walls if w.is_wall]
    steps = range(180, 3601, 180)
    out = [max(0, (step - 1800) // 180) for step in steps]
    (folder / "output" / "flow.txt").write_text(
        "# Time-averaged data\n# step atoms mass_total mass_silo outlet_mass outlet_count deleted_mass deleted_count "
        "ke pe\n" + "".join(f"{step} {100 - k} {1.0 - 0.01 * k} {0.9 - 0.01 * k} {0.01 * k} {k} {0.01 * k} {k} "
                             "1e-6 2e-3\n" for step, k in zip(steps, out)))
    (folder / "output" / "wall_forces.txt").write_text(
        "# Time-averaged data\n# step " + " ".join(f"{w}_f{a}" for w in walls for a in "xyz") + "\n"
        + "".join(f"{step} " + " ".join("0.5 0 -0.1" for _ in walls) + "\n" for step in steps))
    (folder / "output" / "fake_state.json").write_text(json.dumps(
        {"stage_steps": STAGES, "inserted": plan.expected_atoms, "templates": plan.fill.count + plan.fill.dust_count,
         "completed": completed, "escaped": 0}))


def test_open_run_unfinished_reads_a_run_without_a_record(tmp_path, quick_dict, monkeypatch):
    """A run stopped before it wrote run_record.json: warned, and read from what the engine left."""
    import siloflow.engine
    engine = FakeEngine("ok")
    monkeypatch.setattr(siloflow.engine, "get_engine", lambda name, **profile: engine)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    _fake_tables(folder)                                        # interrupted or still running: no record yet
    write_status(folder, "interrupted", stage="discharge")
    with pytest.raises(ReadError, match="run_record.json"):
        siloflow.open_run(folder).record
    with pytest.raises(ReadError, match="is interrupted"):
        siloflow.open_run(folder).summary
    r = siloflow.open_run(folder, unfinished=True)
    with pytest.warns(UnfinishedRunWarning, match="no run_record.json yet"):
        record = r.record
    assert record.stage_steps == STAGES and record.completed is False
    before = _tree(folder)
    with pytest.warns(UnfinishedRunWarning, match="is interrupted"):
        flow = r.flow
    assert flow.outlet_mass.iloc[-1] == pytest.approx(0.1)
    with pytest.warns(UnfinishedRunWarning):
        assert r.summary["discharged_mass_kg"] == pytest.approx(0.1)
    with pytest.warns(UnfinishedRunWarning):
        assert len(r.bands) == len({w.band for w in RunFolder(folder).plan.walls if w.role == "band"}) > 0
    assert _tree(folder) == before                            # computed, not written
    # a run that left nothing readable yet: its record says so, with the warning
    fresh = engine.prepare(case_from_dict(quick_dict), tmp_path / "fresh")
    write_status(fresh, "interrupted", stage="fill")
    with pytest.warns(UnfinishedRunWarning):
        assert siloflow.open_run(fresh, unfinished=True).record.stage_steps == {}


def test_results_read_from_an_unfinished_run_are_recorded_as_siloflows(tmp_path, quick_dict):
    """Results post-processing writes for ``open_run(unfinished=True)`` do not block a later --force."""
    engine, folder = _finished(tmp_path, quick_dict)
    with engine_writes(folder):                         # a second engine run rewrites its state
        _fake_tables(folder, completed=True)
    engine.collect(folder)
    write_status(folder, "failed", reason="test")
    with pytest.warns(UnfinishedRunWarning):
        siloflow.open_run(folder, unfinished=True).summary
    assert (folder / "results" / "summary.json").is_file()
    assert foreign_entries(folder) == []
    assert MANIFEST_NAME in os.listdir(folder)
