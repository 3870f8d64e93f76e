"""The engine base class owns the run: a test engine of a few dozen lines (its deck, one launch of a
fake executable, the reading of its state) passes the engine-neutral checks through ``Engine.execute``
and ``Engine.collect``: record written, guard trips and failed exits explained, neutral tables written."""
from __future__ import annotations

import json
import sys
import textwrap
import time
from pathlib import Path

import pytest

from siloflow.case_file import case_from_dict
from siloflow.engine.base import Engine, Finished, Launched
from siloflow.errors import EngineRunError, SetupError
from siloflow.guard import GuardTrip
from siloflow.geometry import write_stl
from siloflow.run_folder import RunFolder, read_status

#: stands in for an engine: writes the tables a real engine writes (ave/time layout of
#: siloflow.engine.tables) and a state file, prints progress; argv: mode, atoms, templates, walls...
FAKE = textwrap.dedent('''
    import json, sys, time
    mode, atoms, templates, walls = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
    lost_in_fill = 1 if mode == "small_loss" else 0
    inside = atoms - lost_in_fill
    with open("output/flow.txt", "w") as f:
        f.write("# Time-averaged data\\n# step atoms mass_total mass_silo outlet_mass outlet_count "
                "deleted_mass deleted_count ke pe\\n")
        for k, step in enumerate((100, 200, 300)):
            out = 10 * k
            f.write(f"{step} {inside - out} {1.0 - 0.01 * out} {0.9 - 0.01 * out} {0.01 * out} {out} "
                    f"{0.01 * out} {out} 1e-6 2e-3\\n")
    with open("output/wall_forces.txt", "w") as f:
        f.write("# Time-averaged data\\n# step " + " ".join(f"{w}_f{a}" for w in walls for a in "xyz") + "\\n")
        for step in (100, 200, 300):
            f.write(f"{step} " + " ".join(f"{step / 100:g} 0 -{len(w)}" for w in walls) + "\\n")
    for stage, step in (("fill", 0), ("settle", 100), ("discharge", 200)):
        print(f"PROGRESS {stage} {step} 300", flush=True)
    if mode == "guard":
        print("GUARD speed 250 12.5", flush=True)
        time.sleep(60)
    if mode == "fail":
        print("ERROR: the fake engine was told to fail", flush=True)
        sys.exit(3)
    state = {"stage_steps": {"fill": 0, "settle": 100, "discharge": 200}, "inserted": inside,
             "templates": templates - (5 if mode == "short" else 0), "completed": mode != "early",
             "escaped": 4 if mode == "escape" else 0}
    json.dump(state, open("output/fake_state.json", "w"))
''')


class FakeEngine(Engine):
    """A whole engine: its deck, one launch, its state. The rest is the base class's."""

    name, title, deck_name, log_name = "fake", "FAKE", "in.fake", "screen.fake.txt"

    def __init__(self, mode: str = "ok", **profile):
        super().__init__(**profile)
        self.mode = mode

    def version(self) -> str:
        return "fake 1.0"

    def write_deck(self, plan, folder: Path) -> None:
        (folder / "meshes").mkdir()
        (folder / "output").mkdir()
        for w in plan.meshes:
            write_stl(w, folder / "meshes" / f"{w.name}.stl")
        (folder / self.deck_name).write_text(f"run {plan.total_planned_steps}\n")

    def check_deck_files(self, folder: Path, resume: bool = False) -> None:
        if not (folder / self.deck_name).read_text().startswith("run "):
            raise SetupError("not a fake deck")

    def launch(self, folder, plan, progress, resume) -> Launched:
        script = folder.parent / "fake_engine.py"
        script.write_text(FAKE)
        walls = [w.name for w in plan.walls if w.is_wall]
        cmd = [sys.executable, str(script), self.mode, str(plan.expected_atoms),
               str(plan.fill.count + plan.fill.dust_count), *walls]
        errors, trips = [], []

        def on_line(line: str) -> bool:
            word, *rest = line.split()
            if word == "PROGRESS" and progress is not None:
                progress(rest[0], int(rest[1]), int(rest[2]))
            elif word == "ERROR:":
                errors.append(line.strip())
            elif word == "GUARD":
                trips.append(GuardTrip(rest[0], "discharge", int(rest[1]), float(rest[2]), 5.0,
                                       f"a grain moves at {rest[2]} m/s", "the contacts blew up",
                                       "lower engine.timestep_fraction"))
                return True                      # stop the engine
            return False

        run = self.stream(cmd, folder, self.log_name, on_line)
        failure = None
        if run.returncode != 0 or errors:
            failure = (f"the fake engine stopped: {errors[0] if errors else run.returncode}",
                       "it was told to", "run it in mode ok")
        state = self._state(folder)
        return Launched(cmd, run.returncode, {"stage_steps": state.get("stage_steps", {}),
                                              "inserted": state.get("inserted"), "completed": bool(state.get("completed"))},
                        guard_trip=trips[0] if trips else None, failure=failure, tail="\n".join(run.tail))

    def finished(self, folder, plan) -> Finished:
        s = json.loads((folder / "output" / "fake_state.json").read_text())
        return Finished(stage_steps=s["stage_steps"], completed=s["completed"], inserted=s["inserted"],
                        templates_inserted=s["templates"], escaped=s["escaped"])

    @staticmethod
    def _state(folder) -> dict:
        path = folder / "output" / "fake_state.json"
        return json.loads(path.read_text()) if path.is_file() else {}


@pytest.fixture
def prepared(tmp_path, quick_dict):
    def _prepare(mode: str):
        engine = FakeEngine(mode)
        return engine, engine.prepare(case_from_dict(quick_dict), tmp_path / f"run-{mode}")
    return _prepare


def test_a_fake_engine_runs_through_the_base_class(prepared):
    engine, folder = prepared("ok")
    told = []
    record = engine.execute(folder, progress=lambda *a: told.append(a))
    assert told == [("fill", 0, 300), ("settle", 100, 300), ("discharge", 200, 300)]
    assert read_status(folder)["state"] == "running"            # complete only once collect checked it
    run = RunFolder(folder)
    written = json.loads((folder / "run_record.json").read_text())
    assert written["engine"] == "fake" and written["returncode"] == 0 and written["command"] == record.command
    assert written["wall_time"] > 0
    collected = engine.collect(folder)
    assert read_status(folder)["state"] == "complete" and collected.completed
    plan = run.plan
    flow = RunFolder(folder).flow()
    assert flow.step.tolist() == [100, 200, 300]
    assert flow.time.tolist() == pytest.approx([s * plan.dt for s in (100, 200, 300)])
    assert flow.discharged_count.tolist() == [0, 10, 20]
    forces = RunFolder(folder).wall_forces()
    walls = [w.name for w in plan.walls if w.is_wall]
    assert forces.wall.tolist() == [w for w in walls for _ in range(3)]
    assert forces.fx.tolist() == [1, 2, 3] * len(walls)
    assert forces.fz.tolist() == [-len(w) for w in walls for _ in range(3)]


def test_a_guard_trip_stops_the_engine_and_is_explained(prepared):
    engine, folder = prepared("guard")
    start = time.perf_counter()
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    assert time.perf_counter() - start < 30                  # stopped, not waited for (it sleeps 60 s)
    msg = str(info.value)
    assert "stopped by siloflow's guard (speed)" in msg and "12.5 m/s" in msg and "timestep_fraction" in msg
    status = read_status(folder)
    assert status["state"] == "failed" and "guard" in status["reason"]
    assert (folder / "run_record.json").is_file()            # the record is kept for the post-mortem


def test_a_failed_exit_is_an_explained_engine_error(prepared):
    engine, folder = prepared("fail")
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    err = info.value
    assert err.returncode == 3 and "told to fail" in str(err) and err.cause == "it was told to"
    assert "ERROR: the fake engine was told to fail" in err.log_tail
    assert read_status(folder)["state"] == "failed"
    assert "told to fail" in (folder / "screen.fake.txt").read_text()


@pytest.mark.parametrize("mode, expected", [
    ("short", "insertion fell short: .* grains and dust spheres inserted"),
    ("early", "the run ended before the discharge stage finished"),
    ("escape", "4 particles left the silo without passing the outlet"),
])
def test_collect_refuses_what_a_finished_run_did_wrong(prepared, mode, expected):
    engine, folder = prepared(mode)
    engine.execute(folder)
    with pytest.raises(EngineRunError, match=expected):
        engine.collect(folder)
    assert read_status(folder)["state"] == "failed"
    assert not (folder / "output" / "flow.csv").exists()


def test_a_small_fill_loss_is_recorded_not_failed(prepared):
    engine, folder = prepared("small_loss")
    engine.execute(folder)
    record = engine.collect(folder)
    assert record.fill_losses == 1 and any("left the box during the fill" in w for w in record.warnings)
    assert json.loads((folder / "run_record.json").read_text())["fill_losses"] == 1


def test_a_folder_without_its_deck_is_refused_before_the_engine_starts(prepared):
    engine, folder = prepared("ok")
    (folder / "in.fake").unlink()
    with pytest.raises(SetupError, match="incomplete: missing in.fake"):
        engine.execute(folder)
    assert not (folder / "screen.fake.txt").exists()


def test_an_engine_without_a_fill_cache_says_so(prepared):
    engine, folder = prepared("ok")
    with pytest.raises(SetupError, match="no fill cache"):
        engine.fill_key_parts(RunFolder(folder).plan)
    with pytest.raises(SetupError, match="no fill cache"):
        engine.fill_files(folder)
