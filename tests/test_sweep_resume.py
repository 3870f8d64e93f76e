"""Sweeps (issue 34, items 2, 5, 6): the files a sweep wrote are replaced only while unchanged
(sweep.json records them), an interrupted sweep resumes, a folder of another sweep is refused,
large Slurm sweeps are split into arrays of at most --max-array-size tasks, and the plans are made
once per distinct case and silo. A fake run (and resumption) stands in for the engine."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from siloflow import sweep, sweep_folder, sweep_plan
from siloflow.cli import app
from siloflow.errors import SetupError
from siloflow.run_folder import MANIFEST_NAME, RESULTS, SUMMARY_NAME, run_state, write_status
from siloflow.study_case import read_study_case
from siloflow.sweep import expand, group_by_fill, parse_set, run_sweep, write_slurm

from conftest import QUICK
from test_sweep import FakeEngine, fake_engine  # noqa: F401  (the sweep tests' fake engine and its fixture)

runner = CliRunner(env={"COLUMNS": "400"})


def files_of(folder: Path) -> dict:
    return {f.name: f.read_bytes() for f in folder.iterdir() if f.is_file()}


SLURM_ARGS = ["--set", "geometry.orifice_radius=0.006,0.008", "--set", "particles.radius=0.0015,0.0014", "--seeds", "2"]


# ------------------------------------------------------------------ item 2: files siloflow wrote
def test_an_edited_sbatch_is_refused_and_nothing_is_written(tmp_path, fake_engine):
    out = tmp_path / "sweep"
    args = ["sweep", str(QUICK), *SLURM_ARGS, "-o", str(out), "--slurm"]
    assert runner.invoke(app, args).exit_code == 0
    runs = out / "runs.sbatch"
    runs.write_text(runs.read_text().replace("#SBATCH --nodes=1", "#SBATCH --account=myproj\n#SBATCH --nodes=1"))
    (out / "submit.sh").write_text((out / "submit.sh").read_text() + "# mine\n")
    before = files_of(out)
    cases = {f.name: f.read_bytes() for f in (out / "cases").iterdir()}
    for force in ([], ["--force"]):         # another cache: every script would change
        result = runner.invoke(app, [*args, "--cache", str(tmp_path / "elsewhere"), *force])
        assert result.exit_code == 1, result.output
        assert "runs.sbatch (edited since siloflow wrote it)" in result.output
        assert "submit.sh (edited since siloflow wrote it)" in result.output
        assert "fills.sbatch" not in result.output and "move the file(s) out" in result.output.lower()
        assert files_of(out) == before                     # nothing written, fills.sbatch included
        assert {f.name: f.read_bytes() for f in (out / "cases").iterdir()} == cases
    assert "#SBATCH --account=myproj" in runs.read_text()
    # moved away: written anew
    runs.rename(tmp_path / "my_runs.sbatch")
    (out / "submit.sh").unlink()
    result = runner.invoke(app, [*args, "--cache", str(tmp_path / "elsewhere")])
    assert result.exit_code == 0, result.output
    assert f"--cache {tmp_path / 'elsewhere'}" in runs.read_text() and "myproj" not in runs.read_text()


def test_unchanged_files_are_replaced_and_identical_runs_are_harmless(tmp_path, fake_engine):
    out = tmp_path / "sweep"
    args = ["sweep", str(QUICK), *SLURM_ARGS, "-o", str(out), "--slurm"]
    assert runner.invoke(app, args).exit_code == 0
    first = files_of(out)
    assert runner.invoke(app, args).exit_code == 0 and files_of(out) == first
    result = runner.invoke(app, [*args, "--cache", str(tmp_path / "elsewhere")])
    assert result.exit_code == 0, result.output
    assert f"--cache {tmp_path / 'elsewhere'}" in (out / "fills.sbatch").read_text()
    record = json.loads((out / "sweep.json").read_text())
    for name in ("fills.sbatch", "runs.sbatch", "fills.txt", "runs.txt", "submit.sh"):
        assert record["files"][name] == [sweep_folder._sha256_text((out / name).read_text())]
    assert os.access(out / "submit.sh", os.X_OK)


def test_a_file_siloflow_did_not_write_is_refused(tmp_path, quick_dict):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014")])
    groups = group_by_fill(variants, FakeEngine())
    out = tmp_path / "s"
    out.mkdir()
    (out / "submit.sh").write_text("#!/bin/bash\necho mine\n")
    with pytest.raises(SetupError, match=r"submit\.sh \(not written by siloflow\)"):
        write_slurm(variants, groups, out, out / "cache")
    assert sorted(p.name for p in out.iterdir()) == ["submit.sh"]          # nothing written
    # the same text siloflow would write is harmless
    write_slurm(variants, groups, tmp_path / "ref", out / "cache")
    (out / "submit.sh").write_bytes((tmp_path / "ref" / "submit.sh").read_bytes())
    write_slurm(variants, groups, out, out / "cache")
    (out / "sweep.json").write_text("{}")
    with pytest.raises(SetupError, match="not a sweep record siloflow wrote"):
        write_slurm(variants, groups, out, out / "cache")


def test_a_write_cut_short_leaves_files_siloflow_still_owns(tmp_path, quick_dict, monkeypatch):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"), parse_set("geometry.orifice_radius=0.006,0.008")])
    groups = group_by_fill(variants, FakeEngine())
    out = tmp_path / "s"
    write_slurm(variants, groups, out, tmp_path / "c1")
    real, calls = sweep_folder.write_text, []

    def failing(path, text):
        calls.append(path)
        if Path(path).name == "runs.sbatch":
            raise OSError("disk full")
        real(path, text)
    monkeypatch.setattr(sweep_folder, "write_text", failing)
    with pytest.raises(OSError):
        write_slurm(variants, groups, out, tmp_path / "c2")       # fills.sbatch new, runs.sbatch old
    assert len(json.loads((out / "sweep.json").read_text())["files"]["runs.sbatch"]) == 2    # old and new
    monkeypatch.setattr(sweep_folder, "write_text", real)
    write_slurm(variants, groups, out, tmp_path / "c1")         # either way: every file is still siloflow's
    assert f"--cache {tmp_path / 'c1'}" in (out / "fills.sbatch").read_text()
    write_slurm(variants, groups, out, tmp_path / "c2")
    assert f"--cache {tmp_path / 'c2'}" in (out / "runs.sbatch").read_text()


# ------------------------------------------------------------------ item 5: resuming
def fake_runner(case_file, folder, cache, resuming):
    """A fake run of a variant (and its resumption) that keeps a status like siloflow's; Ctrl-C
    (SIGTERM in its worker) marks it interrupted, as the engine does."""
    folder = Path(folder)
    if resuming:
        state = json.loads((folder / "status.json").read_text())["state"]
        assert state not in ("complete", "running"), state
        case = yaml.safe_load((folder / "case.yaml").read_text())
    else:
        assert not folder.exists(), "siloflow run refuses an existing folder"
        case = yaml.safe_load(open(case_file))
        folder.mkdir(parents=True)
        (folder / MANIFEST_NAME).write_text(json.dumps({"files": {}}))
        (folder / "case.yaml").write_text(yaml.safe_dump(case))
    name = case["name"]
    write_status(folder, "running")
    with open(os.environ["FAKE_STARTED"], "a") as fh:
        fh.write(name + "\n")
    start = time.time()
    try:
        time.sleep(60 if name in os.environ.get("FAKE_SLOW", "").split(",") else 0.1)
    except KeyboardInterrupt:
        write_status(folder, "interrupted")
        raise
    if name in os.environ.get("FAKE_FAIL", "").split(","):
        write_status(folder, "failed", reason="fake")
        sys.exit(1)
    (folder / RESULTS).mkdir(exist_ok=True)
    record = {"folder": str(folder), "engine": "fake", "command": ["fake"], "returncode": 0,
              "wall_time": time.time() - start, "stage_steps": {}, "inserted": 10, "settled_ke_pe": 1e-6,
              "completed": True, "fill_cache": {"key": "k", "hit": resuming}}
    (folder / "run_record.json").write_text(json.dumps(record))
    summary = {"flow_rate": {"rate": 1000 * case["geometry"]["orifice_radius"], "stderr": 0.001}}
    (folder / RESULTS / SUMMARY_NAME).write_text(json.dumps(summary))
    write_status(folder, "complete")
    with open(os.environ["FAKE_DONE"], "a") as fh:
        fh.write(json.dumps({"name": name, "resumed": resuming}) + "\n")


@pytest.fixture
def fake_run(tmp_path, monkeypatch):
    """A fake run of a variant (and its resumption) that keeps a status like siloflow's: the
    runner, and readers of the runs it started and finished."""
    started, done = tmp_path / "started.txt", tmp_path / "done.jsonl"
    monkeypatch.setenv("FAKE_STARTED", str(started))
    monkeypatch.setenv("FAKE_DONE", str(done))

    def starts() -> list:
        return started.read_text().split() if started.exists() else []

    def finished() -> list:
        return [json.loads(line) for line in done.read_text().splitlines()] if done.exists() else []
    return fake_runner, starts, finished


def interrupt_when(starts, name: str):
    """A progress callback raising Ctrl-C once ``name`` runs (and has started, its handler set)."""
    def progress(done, total, running):
        if name in running:
            deadline = time.monotonic() + 20
            while name not in starts() and time.monotonic() < deadline:
                time.sleep(0.02)
            raise KeyboardInterrupt
    return progress


def four_runs():
    data, _ = read_study_case(QUICK)
    variants = expand(data, [parse_set("geometry.orifice_radius=0.005,0.006,0.007,0.008"), parse_set("engine.ranks=1")])
    return variants, group_by_fill(variants, FakeEngine())


def test_an_interrupted_sweep_resumes_to_a_complete_table(tmp_path, fake_run, monkeypatch):
    command, starts, finished = fake_run
    variants, groups = four_runs()
    out, cache = tmp_path / "sweep", tmp_path / "cache"
    monkeypatch.setenv("FAKE_SLOW", "quick-002")
    with pytest.raises(KeyboardInterrupt):
        run_sweep(variants, out, cores=1, cache=cache, runner=command, groups=groups,
                  progress=interrupt_when(starts, "quick-002"))
    assert [r["name"] for r in finished()] == ["quick-000", "quick-001"]
    assert run_state(out / "runs" / "quick-002")["state"] == "interrupted"
    assert not (out / "runs" / "quick-003").exists()
    partial = pd.read_csv(out / "sweep.csv")              # the runs finished so far
    assert partial.status.tolist() == ["complete", "complete", "unfinished", "unfinished"]
    assert partial.flow_rate_kg_s[:2].tolist() == pytest.approx([5.0, 6.0])
    # the same call again resumes it
    monkeypatch.delenv("FAKE_SLOW")
    calls = []
    table = run_sweep(variants, out, cores=1, cache=cache, runner=command, groups=groups,
                      progress=lambda done, total, running: calls.append((done, total)))
    assert calls[0] == (2, 4) and calls[-1] == (4, 4)
    assert finished()[2:] == [{"name": "quick-002", "resumed": True}, {"name": "quick-003", "resumed": False}]
    assert starts() == ["quick-000", "quick-001", "quick-002", "quick-002", "quick-003"]   # none run twice
    assert table.status.tolist() == ["complete"] * 4 and table.returncode.tolist() == [0] * 4
    assert table.flow_rate_kg_s.tolist() == pytest.approx([5.0, 6.0, 7.0, 8.0])
    saved = pd.read_csv(out / "sweep.csv")
    assert saved.status.tolist() == ["complete"] * 4
    assert "--resume" in (out / "logs" / "quick-002.log").read_text()
    # once more: nothing left to run, the same table
    again = run_sweep(variants, out, cores=1, cache=cache, runner=command, groups=groups)
    assert len(starts()) == 5 and again.status.tolist() == ["complete"] * 4


def test_a_failed_run_is_kept_with_its_exit_code(tmp_path, fake_run, monkeypatch):
    command, starts, finished = fake_run
    variants, groups = four_runs()
    out = tmp_path / "sweep"
    monkeypatch.setenv("FAKE_FAIL", "quick-001")
    monkeypatch.setenv("FAKE_SLOW", "quick-002")
    with pytest.raises(KeyboardInterrupt):
        run_sweep(variants, out, cores=1, cache=tmp_path / "c", runner=command, groups=groups,
                  progress=interrupt_when(starts, "quick-002"))
    monkeypatch.delenv("FAKE_FAIL")
    monkeypatch.delenv("FAKE_SLOW")
    table = run_sweep(variants, out, cores=1, cache=tmp_path / "c", runner=command, groups=groups)
    assert starts().count("quick-001") == 1                    # a failure is a result: not run again
    assert table.status.tolist() == ["complete", "failed", "complete", "complete"]
    assert table.returncode.tolist() == [0, 1, 0, 0]


def test_run_folders_a_sweep_cannot_resume_are_refused(tmp_path, fake_run):
    command, starts, finished = fake_run
    variants, groups = four_runs()
    out = tmp_path / "sweep"
    (out / "runs" / "quick-001").mkdir(parents=True)          # not a run
    live = out / "runs" / "quick-002"
    live.mkdir()
    (live / MANIFEST_NAME).write_text("{}")
    write_status(live, "running")                             # this process: alive
    with pytest.raises(SetupError) as info:
        run_sweep(variants, out, cores=1, cache=tmp_path / "c", runner=command, groups=groups)
    assert "quick-001 (no siloflow run" in str(info.value) and "quick-002 (still running" in str(info.value)
    assert starts() == [] and not (out / "cases").exists() and not (out / "sweep.json").exists()


def test_another_sweep_in_the_folder_is_refused(tmp_path, fake_run):
    command, starts, finished = fake_run
    variants, groups = four_runs()
    out = tmp_path / "sweep"
    run_sweep(variants[:2], out, cores=1, cache=tmp_path / "c", runner=command,
              groups={k: [v for v in g if v.index < 2] for k, g in groups.items()})
    with pytest.raises(SetupError, match="holds another sweep"):
        run_sweep(variants, out, cores=1, cache=tmp_path / "c", runner=command, groups=groups)
    with pytest.raises(SetupError, match="holds another sweep"):
        sweep.check_sweep_folder(out, variants, force=True)
    assert len(starts()) == 2


def test_an_edited_table_is_refused_before_anything_runs(tmp_path, fake_run):
    command, starts, finished = fake_run
    variants, groups = four_runs()
    out = tmp_path / "sweep"
    run_sweep(variants[:1], out, cores=1, cache=tmp_path / "c", runner=command,
              groups={next(iter(groups)): variants[:1]})
    (out / "sweep.csv").write_text("my notes\n")
    with pytest.raises(SetupError, match=r"sweep\.csv \(edited since siloflow wrote it\)"):
        run_sweep(variants[:1], out, cores=1, cache=tmp_path / "c", runner=command,
                  groups={next(iter(groups)): variants[:1]})
    assert (out / "sweep.csv").read_text() == "my notes\n"


def test_cli_says_how_to_resume_and_the_same_command_resumes(tmp_path, fake_engine, fake_run, monkeypatch):
    command, starts, finished = fake_run
    monkeypatch.setattr(sweep, "run_variant", command)
    monkeypatch.setenv("FAKE_SLOW", "quick-002")
    real = sweep.run_sweep

    def interrupted(*args, **kwargs):
        return real(*args, **{**kwargs, "progress": interrupt_when(starts, "quick-002")})
    monkeypatch.setattr(sweep, "run_sweep", interrupted)
    out = tmp_path / "sweep"
    args = ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.005,0.006,0.007,0.008", "--set", "engine.ranks=1",
            "--cores", "1", "-o", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 130, result.output
    text = " ".join(result.output.split())
    assert "Resume the sweep with the same command" in text
    assert ("siloflow sweep " + str(QUICK) + " --set geometry.orifice_radius=0.005,0.006,0.007,0.008 --set "
            "engine.ranks=1 --cores 1 -o " + str(out)) in text
    assert pd.read_csv(out / "sweep.csv").status.tolist() == ["complete", "complete", "unfinished", "unfinished"]
    monkeypatch.setattr(sweep, "run_sweep", real)
    monkeypatch.delenv("FAKE_SLOW")
    result = runner.invoke(app, args)                      # the same command, no --force
    assert result.exit_code == 0, result.output
    assert "4 runs complete, 0 failed" in result.output
    assert pd.read_csv(out / "sweep.csv").status.tolist() == ["complete"] * 4
    assert starts() == ["quick-000", "quick-001", "quick-002", "quick-002", "quick-003"]
    other = runner.invoke(app, [*args[:3], "geometry.orifice_radius=0.005,0.006", *args[4:], "--force"])
    assert other.exit_code == 1 and "holds another sweep" in other.output


# ------------------------------------------------------------------ item 6: large sweeps
def fake_bin(folder: Path, name: str, body: str) -> Path:
    folder.mkdir(exist_ok=True)
    path = folder / name
    path.write_text("#!/bin/bash\n" + textwrap.dedent(body))
    path.chmod(0o755)
    return path


def submitted(tmp_path: Path, out: Path) -> list[dict]:
    """Run submit.sh with a fake sbatch: each submission's script, array indices, offset and
    the jobs it waits for (job ids 1, 2, ... in order)."""
    bin_dir, calls = tmp_path / "bin", tmp_path / "sbatch_calls"
    calls.unlink(missing_ok=True)
    fake_bin(bin_dir, "sbatch", f"""
        echo "$*" >> {calls}
        n=$(wc -l < {calls})
        echo "$n;cluster"
        """)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}"}
    subprocess.run([str(out / "submit.sh")], cwd=tmp_path, env=env, check=True, capture_output=True)
    jobs = []
    for k, line in enumerate(calls.read_text().splitlines(), 1):
        array = re.search(r"--array=(\d+)-(\d+)", line)
        after = re.search(r"--dependency=afterok:(\S+)", line)
        script, offset = line.split()[-2:]
        jobs.append({"job": k, "script": script, "offset": int(offset),
                     "tasks": range(int(array[1]), int(array[2]) + 1),
                     "after": [int(j) for j in after[1].split(":")] if after else []})
    return jobs


def run_task(tmp_path: Path, out: Path, script: str, offset: int, task: int) -> str:
    """The siloflow command a task of ``script`` submitted with ``offset`` runs (fake siloflow)."""
    bin_dir = tmp_path / "bin"
    fake_bin(bin_dir, "siloflow", 'echo "$*"\n')
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "SLURM_ARRAY_TASK_ID": str(task)}
    return subprocess.run(["bash", script, str(offset)], cwd=out, env=env, check=True, capture_output=True,
                          text=True).stdout


def test_2500_fills_are_three_arrays_covering_every_line_once(tmp_path, quick_dict):
    variants = expand(quick_dict, [parse_set("fill.count=" + ",".join(str(4000 + k) for k in range(250)))], seeds=10)
    groups = {f"key{v.index}": [v] for v in variants}                  # every run its own fill
    out = tmp_path / "s"
    write_slurm(variants, groups, out, out / "cache")
    lines = (out / "fills.txt").read_text().splitlines()
    assert len(lines) == 2500 and not (out / "runs.sbatch").exists()
    jobs = submitted(tmp_path, out)
    assert [(j["script"], j["offset"], len(j["tasks"])) for j in jobs] == [
        ("fills.sbatch", 0, 1000), ("fills.sbatch", 1000, 1000), ("fills.sbatch", 2000, 500)]
    assert all(j["tasks"].start == 0 and j["tasks"].stop <= 1000 for j in jobs)   # within MaxArraySize 1001
    covered = sorted(j["offset"] + k for j in jobs for k in j["tasks"])
    assert covered == list(range(2500))
    for j in jobs:                                   # the first and last task of each array: their lines
        for k in (j["tasks"][0], j["tasks"][-1]):
            line = lines[j["offset"] + k]
            assert run_task(tmp_path, out, "fills.sbatch", j["offset"], k).split()[:4] == [
                "run", line, "-o", f"runs/{Path(line).stem}"]
    assert re.search(r"^#SBATCH --array=0-999$", (out / "fills.sbatch").read_text(), re.M)


def test_split_runs_wait_for_the_fills_they_need(tmp_path, quick_dict):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"),
                                   parse_set("geometry.orifice_radius=0.006,0.007,0.008")], seeds=2)
    groups = group_by_fill(variants, FakeEngine())                 # 4 fills of 3 runs
    out = tmp_path / "s"
    write_slurm(variants, groups, out, out / "cache", max_array_size=3)
    fills, runs = ((out / f"{kind}.txt").read_text().splitlines() for kind in ("fills", "runs"))
    jobs = submitted(tmp_path, out)
    fill_jobs = [j for j in jobs if j["script"] == "fills.sbatch"]
    run_jobs = [j for j in jobs if j["script"] == "runs.sbatch"]
    assert [len(j["tasks"]) for j in fill_jobs] == [3, 1] and [len(j["tasks"]) for j in run_jobs] == [3, 3, 2]
    assert all(not j["after"] for j in fill_jobs)
    fill_of = {v.name: members[0].name for members in groups.values() for v in members}
    job_of_fill = {Path(fills[j["offset"] + k]).stem: j["job"] for j in fill_jobs for k in j["tasks"]}
    seen = []
    for j in run_jobs:
        assert all(a < j["job"] for a in j["after"])
        needed = set()
        for k in j["tasks"]:
            name = Path(runs[j["offset"] + k]).stem
            seen.append(name)
            needed.add(job_of_fill[fill_of[name]])
            assert run_task(tmp_path, out, "runs.sbatch", j["offset"], k).split()[1] == runs[j["offset"] + k]
        assert sorted(needed) == j["after"]                 # exactly the fills arrays it needs
    assert sorted(seen) == sorted(Path(r).stem for r in runs)
    assert subprocess.run(["bash", "-n", str(out / "submit.sh")]).returncode == 0
    with pytest.raises(SetupError, match="--max-array-size"):
        write_slurm(variants, groups, out, out / "cache", max_array_size=0)


def test_cli_max_array_size(tmp_path, fake_engine):
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", str(QUICK), *SLURM_ARGS, "-o", str(out), "--slurm", "--max-array-size", "3"])
    assert result.exit_code == 0, result.output
    assert "4 job array(s)" in result.output
    text = (out / "submit.sh").read_text()
    assert text.count("fills.sbatch") == 2 and text.count("runs.sbatch") == 2
    assert "--array=0-2 fills.sbatch 0" in text and "--array=0-0 fills.sbatch 3" in text


def test_plans_are_made_once_per_case_and_silo_and_group_as_before(quick_dict, monkeypatch):
    from siloflow import derived
    from siloflow import geometry as meshes
    from siloflow.fill_cache import fill_key
    variants = expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.008"), parse_set("fill.count=4000,4500"),
                                   parse_set("materials.particle_particle.friction=0.4,0.5")], seeds=3)
    expected: dict = {}
    for v in variants:                                    # one plan per variant, as without the sharing
        expected.setdefault(fill_key(derived.derive(v.case), FakeEngine()), []).append(v.name)
    counts = {"derive": 0, "meshes": 0}
    real_derive, real_meshes = derived.derive, meshes.silo_meshes

    def counted_derive(case):
        counts["derive"] += 1
        return real_derive(case)

    def counted_meshes(*args, **kwargs):
        counts["meshes"] += 1
        return real_meshes(*args, **kwargs)
    monkeypatch.setattr(derived, "derive", counted_derive)
    monkeypatch.setattr(meshes, "silo_meshes", counted_meshes)
    stages = []
    groups = group_by_fill(variants, FakeEngine(), progress=lambda *a: stages.append(a))
    assert {k: [v.name for v in g] for k, g in groups.items()} == expected
    assert counts == {"derive": 8, "meshes": 2}           # 24 variants: 8 cases but the seed, 2 silos
    assert meshes.silo_meshes is counted_meshes           # put back
    assert stages[-1] == ("planning", 24, 24) and len(stages) == 24
    with sweep_plan._shared_meshes():                          # the shared meshes make the same plan
        for v in variants[:2]:
            assert real_derive(v.case).model_dump_json() == real_derive(v.case).model_dump_json()
        shared = real_derive(variants[5].case)
    assert shared.model_dump_json() == real_derive(variants[5].case).model_dump_json()


# ------------------------------------------------------------------ issue 55 item 10e: a fill resumed
class ResumingEngine:
    """The parts of an engine a run through the fill cache asks for, without the engine. A run fills
    (its bed: ``bed.restart``; a name in FAKE_SLOW sleeps in its fill, SIGTERM marking the folder
    interrupted as the engine does) and discharges; a resumed run fills again when it was stopped
    before its bed settled, else goes on from it; a run from the cache copies the bed. Each fill
    computed is appended to FAKE_FILLS, each start to FAKE_STARTED."""

    name = "fake"

    def fill_key_parts(self, plan):
        return {"name": "fake", "version": "1"}

    def restart_step(self, folder):
        return 100 if (Path(folder) / "bed.restart").is_file() else None

    def _started(self, folder, how):
        write_status(folder, "running")
        with open(os.environ["FAKE_STARTED"], "a") as fh:
            fh.write(Path(folder).name + "\n")

    def execute(self, folder, progress=None):
        self._started(folder, "run")
        try:
            time.sleep(60 if Path(folder).name in os.environ.get("FAKE_SLOW", "").split(",") else 0.05)
        except KeyboardInterrupt:
            write_status(folder, "interrupted")
            raise
        (Path(folder) / "bed.restart").write_bytes(b"settled bed")
        with open(os.environ["FAKE_FILLS"], "a") as fh:
            fh.write(Path(folder).name + "\n")

    def collect(self, folder):
        from siloflow.run_folder import RunRecord
        write_status(folder, "complete")
        return RunRecord(folder=str(folder), engine="fake", command=["fake"], returncode=0, wall_time=0.05,
                         stage_steps={"fill": 0, "static": 100}, inserted=10, settled_ke_pe=1e-7, completed=True)

    def resume(self, folder, progress=None):
        assert run_state(folder)["state"] not in ("running", "complete")
        if self.restart_step(folder) is None:          # stopped before its bed settled: the fill again
            self.execute(folder, progress)
        else:
            self._started(folder, "resume")
        return self.collect(folder)

    def fill_files(self, folder):
        return {"bed.restart": (Path(folder) / "bed.restart").read_bytes()}

    def fill_bed(self, files, plan):
        """The cached bed read back: the plan's own grains (one sphere species)."""
        import numpy as np

        from siloflow.engine.base import SettledBed
        (sp,) = plan.species
        n = plan.expected_atoms
        return SettledBed(np.ones(n, int), np.full(n, sp.radius), np.full(n, sp.mass), {})

    def start_from_fill(self, folder, files, progress=None):
        self._started(folder, "cache")
        (Path(folder) / "bed.restart").write_bytes(Path(files["bed.restart"]).read_bytes())
        return self.collect(folder)


@pytest.fixture
def resuming_engine(tmp_path, monkeypatch, fake_run):
    """The run API (siloflow.runs) with :class:`ResumingEngine` in place of the case's engine, as the
    sweep's own runner (sweep.run_variant) calls it; returns a reader of the fills computed."""
    from siloflow import runs
    from siloflow.case_file import load_case
    from siloflow.derived import derive
    from siloflow.run_folder import RunFolder
    fills = tmp_path / "fills.txt"
    monkeypatch.setenv("FAKE_FILLS", str(fills))
    engine = ResumingEngine()

    def prepare_run(case_file, folder):
        case = load_case(case_file)
        plan = derive(case)
        Path(folder).mkdir(parents=True)
        RunFolder(folder).write_plan(plan)
        RunFolder(folder).case_file.write_bytes(Path(case_file).read_bytes())
        write_status(folder, "rendered")
        return runs.PreparedRun(Path(folder), case, plan, engine)

    def prepare_resume(folder):                   # as siloflow.runs': the folder's case, its plan.json
        run = RunFolder(folder)
        return runs.PreparedRun(Path(folder), load_case(run.case_file), run.plan, engine, resuming=True,
                                state_before=run_state(folder)["state"])

    def post_process(folder):
        write_json_file(Path(folder) / RESULTS / SUMMARY_NAME, {"flow_rate": {"rate": 0.05, "stderr": 0.001}})

    monkeypatch.setattr(runs, "prepare_run", prepare_run)
    monkeypatch.setattr(runs, "prepare_resume", prepare_resume)
    monkeypatch.setattr(runs, "post_process", post_process)
    return lambda: fills.read_text().split() if fills.exists() else []


def write_json_file(path: Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))


def test_a_fill_resumed_is_published_and_its_group_takes_it_from_the_cache(tmp_path, fake_run, resuming_engine,
                                                                           monkeypatch):
    """Issue 55 item 10e: the sweep stopped during its group's fill; resumed, the fill's run computes
    the bed again and publishes it (before: a resumed run bypassed the cache, so the group's next
    run filled again, beside it on a second core), and the group's other runs start from it."""
    from siloflow.fill_cache import FillCache
    command, starts, finished = fake_run
    fills = resuming_engine
    variants, groups = four_runs()
    assert len(groups) == 1
    out, cache = tmp_path / "sweep", tmp_path / "cache"
    monkeypatch.setenv("FAKE_SLOW", "quick-000")
    with pytest.raises(KeyboardInterrupt):
        run_sweep(variants, out, cores=2, cache=cache, groups=groups, progress=interrupt_when(starts, "quick-000"))
    assert run_state(out / "runs" / "quick-000")["state"] == "interrupted" and fills() == []
    assert starts() == ["quick-000"] and FillCache(cache).entries() == []
    monkeypatch.delenv("FAKE_SLOW")
    table = run_sweep(variants, out, cores=2, cache=cache, groups=groups)
    assert table.status.tolist() == ["complete"] * 4
    assert fills() == ["quick-000"]                                  # one fill, computed by the resumed run
    assert table.fill_from_cache.tolist() == [False, True, True, True]
    entries = FillCache(cache).entries()
    assert len(entries) == 1 and entries[0].info["source"] == str(out / "runs" / "quick-000")
    record = json.loads((out / "runs" / "quick-000" / "run_record.json").read_text())
    assert record["fill_cache"]["published"] is True and record["fill_cache"]["resumed"] is True
    assert starts()[:2] == ["quick-000", "quick-000"]                # resumed before the rest of its group


def test_a_resumed_run_never_starts_from_the_cache_and_publishes_only_a_missing_bed(tmp_path, quick_dict,
                                                                                      monkeypatch):
    """run_with_cache(resume=True): the folder's own bed (or its fill again), under the key's lock;
    published when the cache has none of the key, else the entry there is kept."""
    from siloflow.case_file import case_from_dict
    from siloflow.derived import derive
    from siloflow.fill_cache import FillCache, fill_key_inputs, key_of, run_with_cache
    plan = derive(case_from_dict(quick_dict))
    engine, cache = ResumingEngine(), FillCache(tmp_path / "cache")
    monkeypatch.setenv("FAKE_STARTED", str(tmp_path / "started.txt"))
    monkeypatch.setenv("FAKE_FILLS", str(tmp_path / "fills.txt"))
    went_on = tmp_path / "went_on"                    # stopped after its bed settled: goes on from it
    went_on.mkdir()
    (went_on / "bed.restart").write_bytes(b"its own bed")
    write_status(went_on, "interrupted")
    record = run_with_cache(engine, went_on, plan, cache, resume=True)
    assert record.fill_cache["hit"] is None and record.fill_cache["published"] is True
    key = key_of(fill_key_inputs(plan, engine))
    assert (cache.get(key).folder / "bed.restart").read_bytes() == b"its own bed"
    again = tmp_path / "again"                        # stopped in its fill, the cache holding the bed
    again.mkdir()
    write_status(again, "interrupted")
    hits = []
    record = run_with_cache(engine, again, plan, cache, on_hit=hits.append, resume=True)
    assert hits == [] and record.fill_cache["hit"] is False and record.fill_cache["published"] is False
    assert (again / "bed.restart").read_bytes() == b"settled bed"       # filled again, not copied
    assert (cache.get(key).folder / "bed.restart").read_bytes() == b"its own bed"


def test_a_resumed_run_of_a_group_not_yet_filled_is_its_fill():
    """The rest of the group waits for the resumed run as for a fill (before: the next one started its
    own fill beside it), and takes the cache once it completed; a failed one hands the fill on."""
    from siloflow.scheduler import Job, Outcome
    variants, groups = four_runs()
    jobs = {v.name: Job(v.name, lambda: None) for v in variants}
    order = sweep.FillOrder(groups, jobs, finished={}, resuming={"quick-000"})
    assert [j.name for j in order.ready()] == ["quick-000"]
    order.started(jobs["quick-000"])
    assert order.ready() == []
    order.finished(jobs["quick-000"], Outcome(0))
    assert [j.name for j in order.ready()] == ["quick-001", "quick-002", "quick-003"]
    failed = sweep.FillOrder(groups, jobs, finished={}, resuming={"quick-000"})
    failed.started(jobs["quick-000"])
    failed.finished(jobs["quick-000"], Outcome(1))
    assert [j.name for j in failed.ready()] == ["quick-001"]              # the next one computes the fill
    filled = sweep.FillOrder(groups, jobs, finished={"quick-001": 0}, resuming={"quick-000"})
    assert [j.name for j in filled.ready()] == ["quick-000", "quick-002", "quick-003"]   # as before
