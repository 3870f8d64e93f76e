"""Sweeps (issue 15, item 4; siloflow.sweep): --set parsing, the variants, fill groups, the local
runner with a fake `siloflow run` (its order, the core budget, failures, Ctrl-C, the table), the
Slurm job arrays read back, and the CLI. No engine runs here."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from siloflow import sweep
from siloflow.case import SAFE_NAME_PATTERN
from siloflow.case_file import load_case
from siloflow.cli import app
from siloflow.errors import CaseError, SetupError
from siloflow.run_folder import RECORD_NAME, RESULTS, SUMMARY_NAME, RunFolder
from siloflow.study_case import read_study_case
from siloflow.sweep import expand, group_by_fill, parse_set, run_sweep, write_slurm

from conftest import QUICK

runner = CliRunner(env={"COLUMNS": "400"})


class FakeEngine:
    """The parts of an engine a sweep asks for, without the engine."""

    name = "fake"

    def fill_key_parts(self, plan):
        return {"name": "fake", "version": "1"}

    def check(self, case, plan=None):
        return []


# ------------------------------------------------------------------ parse_set
@pytest.mark.parametrize("spec,expected", [
    ("geometry.orifice_radius=0.006,0.008,0.010", ("geometry.orifice_radius", [0.006, 0.008, 0.010])),
    ("fill.count=4000,5000", ("fill.count", [4000, 5000])),
    ("fill.frictionless=true,false", ("fill.frictionless", [True, False])),
    ("outputs.dump_interval=null,0.05", ("outputs.dump_interval", [None, 0.05])),
    ("particles.radius=1.5e-3, 1e-3", ("particles.radius", [0.0015, 0.001])),   # YAML 1.2 floats
    ("materials.particle.youngs_modulus=5.0e6", ("materials.particle.youngs_modulus", [5.0e6])),
    ("description=a,'0.5'", ("description", ["a", "0.5"])),
    (" seed = 1,2 ", ("seed", [1, 2])),
])
def test_parse_set_reads_yaml_scalars(spec, expected):
    path, values = parse_set(spec)
    assert (path, values) == expected
    assert [type(v) for v in values] == [type(v) for v in expected[1]]


@pytest.mark.parametrize("spec,words", [
    ("geometry.orifice_radius", "PATH=V1,V2"),
    ("=0.1,0.2", "no field path"),
    ("geometry.orifice_radius=", "empty value"),
    ("geometry.orifice_radius=0.1,,0.2", "empty value"),
    ("geometry..radius=0.1", "not a field name"),
    ("geometry.1radius=0.1", "not a field name"),
    ("inserts[0].scale=2", "not a field name"),
    ("geometry.radius; rm -rf=0.1", "not a field name"),
    ("geometry.radius=0.1,0.1", "given twice"),
    ("description=[a", "not a YAML value"),
    ("description=2020-01-01", "a number, true/false, null or a string"),
    ("seed=" + ",".join(str(k) for k in range(1001)), "at most 1000"),
])
def test_parse_set_refuses_naming_the_set(spec, words):
    with pytest.raises(SetupError) as info:
        parse_set(spec)
    assert "--set" in str(info.value) and words in str(info.value)


def test_parse_set_takes_1000_values():
    assert len(parse_set("seed=" + ",".join(str(k) for k in range(1000)))[1]) == 1000


# ------------------------------------------------------------------ expand
def test_expand_is_the_product_times_the_seeds(quick_dict):
    sets = [parse_set("geometry.orifice_radius=0.006,0.008"), parse_set("fill.count=4000,5000,6000")]
    variants = expand(quick_dict, sets, seeds=2)
    assert len(variants) == 12
    assert [v.index for v in variants] == list(range(12))
    combos = [(v.values["geometry.orifice_radius"], v.values["fill.count"], v.seed) for v in variants]
    assert combos[:4] == [(0.006, 4000, 12345), (0.006, 4000, 12346), (0.006, 5000, 12345), (0.006, 5000, 12346)]
    assert combos[-1] == (0.008, 6000, 12346)
    for v in variants:
        assert v.case.geometry.orifice_radius == v.values["geometry.orifice_radius"] == v.data["geometry"]["orifice_radius"]
        assert v.case.fill.count == v.values["fill.count"]
        assert v.case.seed == v.seed == v.data["seed"]
        assert v.case.name == v.name == v.data["name"]
    assert quick_dict["geometry"]["orifice_radius"] == 0.008 and quick_dict["name"] == "quick"   # not changed
    assert variants[0].data["geometry"] is not variants[1].data["geometry"]                      # deep copies


def test_seeds_count_from_the_schema_default_when_the_case_has_none(quick_dict):
    from siloflow.case import Case
    del quick_dict["seed"]
    variants = expand(quick_dict, [], seeds=3)
    default = Case.model_fields["seed"].default
    assert [v.seed for v in variants] == [default, default + 1, default + 2]


def test_names_are_safe_unique_and_fit_64_characters(quick_dict):
    quick_dict["name"] = "a" * 64
    variants = expand(quick_dict, [parse_set("fill.count=" + ",".join(str(4000 + k) for k in range(120)))], seeds=10)
    names = [v.name for v in variants]
    assert len(set(names)) == len(names) == 1200
    assert all(re.fullmatch(SAFE_NAME_PATTERN, n) and len(n) <= 64 for n in names)
    assert names[0] == "a" * 60 + "-000" and names[-1] == "a" * 59 + "-1199"


def test_a_missing_section_is_made(quick_dict):
    quick_dict.pop("engine")
    variants = expand(quick_dict, [parse_set("engine.ranks=1,2")])
    assert [v.case.engine.ranks for v in variants] == [1, 2]


def test_a_bad_value_is_refused_naming_the_field_and_the_set(quick_dict):
    with pytest.raises(CaseError) as info:
        expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.02"), parse_set("fill.count=4000")])
    problems = dict(info.value.problems)
    assert "geometry" in problems
    assert "orifice_radius" in problems["geometry"] and "--set geometry.orifice_radius=0.02" in problems["geometry"]
    assert "quick-001" in str(info.value)
    with pytest.raises(CaseError) as info:
        expand(quick_dict, [parse_set("fill.count=4000,true")])
    path, message = info.value.problems[0]
    assert path == "fill.count" and "--set fill.count=true" in message
    with pytest.raises(CaseError) as info:
        expand(quick_dict, [parse_set("fill.colour=1")])
    assert info.value.problems[0][0] == "fill.colour" and "unknown key" in info.value.problems[0][1]
    with pytest.raises(CaseError) as info:
        expand(quick_dict, [parse_set("gravity.x=1")])
    assert info.value.problems[0][0] == "gravity" and "not a section" in info.value.problems[0][1]


@pytest.mark.parametrize("sets,seeds,words", [
    (["fill.count=4000", "fill.count=5000"], 1, "given twice"),
    (["fill=1", "fill.count=5000"], 1, "inside the other"),
    (["name=a,b"], 1, "names its variants"),
    (["seed=1,2"], 2, "--seeds"),
    (["fill.count=" + ",".join(str(4000 + k) for k in range(1000)), "seed=" + ",".join(map(str, range(11)))],
     1, "at most 10000"),
    ([], 0, "--seeds"),
])
def test_expand_refuses(quick_dict, sets, seeds, words):
    with pytest.raises(SetupError, match=re.escape(words)):
        expand(quick_dict, [parse_set(s) for s in sets], seeds)


def test_set_seed_gives_the_seeds(quick_dict):
    assert [v.seed for v in expand(quick_dict, [parse_set("seed=7,9")])] == [7, 9]


def test_the_study_case_reader_makes_insert_paths_absolute(tmp_path, quick_dict):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "baffle.stl").write_text("solid baffle\nendsolid baffle\n")   # read only with the walls
    quick_dict["inserts"] = [{"name": "baffle", "file": "m/baffle.stl"}]
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(quick_dict))
    data, case = read_study_case(tmp_path / "case.yaml")
    assert data["inserts"][0]["file"] == str((tmp_path / "m" / "baffle.stl").resolve()) == case.inserts[0].file
    assert data["name"] == case.name == quick_dict["name"]


# ------------------------------------------------------------------ fill groups
def test_orifice_radii_of_a_flat_bottom_share_one_fill(quick_dict):
    variants = expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.007,0.008")])
    groups = group_by_fill(variants, FakeEngine())
    assert [[v.name for v in g] for g in groups.values()] == [["quick-000", "quick-001", "quick-002"]]


def test_particle_radii_and_seeds_do_not(quick_dict):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"),
                                   parse_set("geometry.orifice_radius=0.006,0.008")], seeds=2)
    groups = group_by_fill(variants, FakeEngine())
    assert len(groups) == 4                                       # 2 radii x 2 seeds
    for members in groups.values():
        assert len({(v.values["particles.radius"], v.seed) for v in members}) == 1
        assert sorted(v.values["geometry.orifice_radius"] for v in members) == [0.006, 0.008]
    assert list(groups.values())[0][0].index == 0                 # insertion-ordered


# ------------------------------------------------------------------ the local runner, with a fake run
def fake_runner(case_file, folder, cache, resuming):
    """A fake run of a variant (in its worker process, as ``sweep.run_variant`` would run it): sleeps,
    records itself in FAKE_TIMES, fails (exit code 1) when named in FAKE_FAIL, else leaves a record
    and a summary. Its bed depends on the radius and the seed: a marker in the cache."""
    assert not resuming
    case = yaml.safe_load(open(case_file))
    name, ranks = case["name"], case.get("engine", {}).get("ranks", 1)
    folder, cache = Path(folder), Path(cache)
    assert not folder.exists(), "siloflow run refuses an existing folder"
    marker = cache / "fills" / f"{case['particles']['radius']}-{case['seed']}"   # what the bed depends on here
    hit = marker.exists()
    pid_file = os.environ.get("FAKE_PIDS")
    if pid_file:
        with open(pid_file, "a") as fh:
            fh.write(f"{os.getpid()}\n")
    start = time.time()
    time.sleep(float(os.environ.get("FAKE_SLEEP", "0.2")))
    end = time.time()
    with open(os.environ["FAKE_TIMES"], "a") as fh:
        fh.write(json.dumps({"name": name, "ranks": ranks, "start": start, "end": end, "hit": hit,
                             "columns": os.environ.get("COLUMNS"), "pid": os.getpid()}) + "\n")
    print(f"fake run of {name}")
    if name in os.environ.get("FAKE_FAIL", "").split(","):
        print("fake failure", file=sys.stderr)
        sys.exit(1)
    (folder / RESULTS).mkdir(parents=True)
    record = {"folder": str(folder), "engine": "fake", "command": ["fake"], "returncode": 0, "wall_time": end - start,
              "stage_steps": {}, "inserted": 10, "settled_ke_pe": 1e-6, "completed": True,
              "fill_cache": {"key": "k", "hit": hit}}
    (folder / RECORD_NAME).write_text(json.dumps(record))
    summary = {"flow_rate": {"rate": 1000 * case["geometry"]["orifice_radius"], "stderr": 0.001},
               "force_balance": {"ratio": 0.99}, "frame_analyses": {"bulk_solid_fraction": 0.6}}
    (folder / RESULTS / SUMMARY_NAME).write_text(json.dumps(summary))
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()


@pytest.fixture
def fake_run(tmp_path, monkeypatch):
    """A fake run of a variant: the runner, and a reader of the runs it recorded (name -> record)."""
    times = tmp_path / "times.jsonl"
    monkeypatch.setenv("FAKE_TIMES", str(times))

    def runs() -> dict:
        lines = times.read_text().splitlines() if times.exists() else []
        return {r["name"]: r for r in map(json.loads, lines)}
    return fake_runner, runs


def most_ranks_at_once(records) -> int:
    events = sorted([(r["start"], r["ranks"]) for r in records] + [(r["end"], -r["ranks"]) for r in records],
                    key=lambda e: (e[0], e[1]))
    now = most = 0
    for _, change in events:
        now += change
        most = max(most, now)
    return most


def test_fills_first_within_the_cores_and_a_failure_recorded(quick_dict, tmp_path, fake_run, monkeypatch):
    command, runs = fake_run
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"),
                                   parse_set("geometry.orifice_radius=0.006,0.007,0.008"), parse_set("engine.ranks=1")])
    groups = group_by_fill(variants, FakeEngine())
    assert [[v.index for v in g] for g in groups.values()] == [[0, 1, 2], [3, 4, 5]]
    monkeypatch.setenv("FAKE_FAIL", "quick-004")
    calls = []
    out = tmp_path / "sweep"
    table = run_sweep(variants, out, cores=2, cache=tmp_path / "cache", runner=command,
                      progress=lambda done, total, names: calls.append((done, total, list(names))), groups=groups)
    done = runs()
    assert set(done) == {v.name for v in variants}
    for members in groups.values():
        first, others = members[0].name, [v.name for v in members[1:]]
        assert not done[first]["hit"]
        for name in others:
            assert done[first]["end"] <= done[name]["start"], "a group's runs start after its fill"
            assert done[name]["hit"]
    assert most_ranks_at_once(done.values()) == 2                  # the two fills ran side by side, never more
    assert all(r["columns"] == "200" for r in done.values())
    # progress: counted up to the total, with the running names
    assert calls[0][:2] == (0, 6) and calls[-1] == (6, 6, [])
    assert any(len(names) == 2 for _, _, names in calls)
    # the table
    assert list(table.columns) == ["run", "name", "particles.radius", "geometry.orifice_radius", "engine.ranks", "seed",
                                   "fill_key", "fill_from_cache", "status", "returncode", "wall_s", "flow_rate_kg_s",
                                   "flow_rate_stderr_kg_s", "clogged", "steady_t_start_s", "steady_t_end_s",
                                   "force_balance_ratio", "bulk_solid_fraction", "log"]
    assert list(table.name) == [v.name for v in variants]
    assert list(table.status) == ["complete"] * 4 + ["failed", "complete"]
    assert list(table.returncode) == [0, 0, 0, 0, 1, 0]
    failed = table.set_index("name").loc["quick-004"]
    assert pd.isna(failed.flow_rate_kg_s) and pd.isna(failed.fill_from_cache)
    assert "fake failure" in Path(failed.log).read_text()
    ok = table[table.status == "complete"]
    assert list(ok.fill_from_cache) == [False, True, True, False, True]
    assert ok.flow_rate_kg_s.tolist() == pytest.approx([1000 * r for r in ok["geometry.orifice_radius"]])
    assert (ok.force_balance_ratio == 0.99).all() and (ok.bulk_solid_fraction == 0.6).all()
    assert (ok.wall_s > 0.15).all()
    assert table.fill_key.tolist() == [k[:12] for k, g in groups.items() for _ in g]
    assert table.run.tolist() == [str(out.absolute() / "runs" / v.name) for v in variants]
    for v in variants:
        assert load_case(out / "cases" / f"{v.name}.yaml").geometry.orifice_radius == v.values["geometry.orifice_radius"]
    saved = pd.read_csv(out / "sweep.csv")
    assert saved.name.tolist() == table.name.tolist() and saved.status.tolist() == table.status.tolist()
    assert sweep.table_summary(table) == {"complete": 5, "failed": 1, "unfinished": 0, "computed": 2, "reused": 3}


def test_a_failed_fill_hands_the_fill_to_the_next_of_its_group(quick_dict, tmp_path, fake_run, monkeypatch):
    command, runs = fake_run
    variants = expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.007,0.008"), parse_set("engine.ranks=1")])
    groups = group_by_fill(variants, FakeEngine())
    monkeypatch.setenv("FAKE_FAIL", "quick-000")
    table = run_sweep(variants, tmp_path / "s", cores=2, cache=tmp_path / "c", runner=command, groups=groups)
    done = runs()
    assert done["quick-000"]["end"] <= done["quick-001"]["start"]           # one fill at a time
    assert not done["quick-001"]["hit"] and done["quick-002"]["hit"]
    assert done["quick-001"]["end"] <= done["quick-002"]["start"]
    assert table.status.tolist() == ["failed", "complete", "complete"]


def test_ranks_add_up_to_at_most_the_cores(quick_dict, tmp_path, fake_run):
    command, runs = fake_run
    variants = expand(quick_dict, [parse_set("engine.ranks=1,2"), parse_set("seed=1,2,3")])
    groups = group_by_fill(variants, FakeEngine())
    assert len(groups) == 3                                       # by seed: ranks are the engine's part of the key
    table = run_sweep(variants, tmp_path / "s", cores=3, cache=tmp_path / "c", runner=command, groups=groups)
    assert (table.status == "complete").all()
    assert most_ranks_at_once(runs().values()) <= 3


def test_a_run_wider_than_the_cores_is_refused_up_front(quick_dict, tmp_path, fake_run):
    command, runs = fake_run
    variants = expand(quick_dict, [parse_set("engine.ranks=1,2")])
    with pytest.raises(SetupError, match=r"engine.ranks = 2 but --cores is 1"):
        run_sweep(variants, tmp_path / "s", cores=1, cache=tmp_path / "c", runner=command,
                  groups=group_by_fill(variants, FakeEngine()))
    assert not (tmp_path / "s").exists() and runs() == {}


def test_ctrl_c_stops_the_running_runs(quick_dict, tmp_path, fake_run, monkeypatch):
    command, runs = fake_run
    pids = tmp_path / "pids"
    monkeypatch.setenv("FAKE_PIDS", str(pids))
    monkeypatch.setenv("FAKE_SLEEP", "60")
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"), parse_set("engine.ranks=1")])

    def progress(done, total, names):
        if len(names) == 2:
            deadline = time.monotonic() + 20
            while (not pids.exists() or len(pids.read_text().split()) < 2) and time.monotonic() < deadline:
                time.sleep(0.05)
            raise KeyboardInterrupt
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        run_sweep(variants, tmp_path / "s", cores=2, cache=tmp_path / "c", runner=command, progress=progress,
                  groups=group_by_fill(variants, FakeEngine()))
    assert time.monotonic() - began < 30
    for pid in map(int, pids.read_text().split()):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    assert runs() == {}                         # none got past its sleep


def test_a_log_that_cannot_be_written_is_a_setup_error(quick_dict, tmp_path, fake_run):
    command, runs = fake_run
    variants = expand(quick_dict, [])
    (tmp_path / "s" / "logs" / f"{variants[0].name}.log").mkdir(parents=True)     # a folder where the log goes
    with pytest.raises(SetupError, match="cannot write the log"):
        run_sweep(variants, tmp_path / "s", cores=2, cache=tmp_path / "c", runner=command,
                  groups=group_by_fill(variants, FakeEngine()))
    assert runs() == {}


def test_each_run_is_its_own_worker_process_of_this_python(quick_dict, tmp_path, fake_run):
    command, runs = fake_run
    variants = expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.007"), parse_set("engine.ranks=1")])
    run_sweep(variants, tmp_path / "s", cores=2, cache=tmp_path / "c", runner=command,
              groups=group_by_fill(variants, FakeEngine()))
    pids = {r["pid"] for r in runs().values()}
    assert len(pids) == 2 and os.getpid() not in pids


class _Prepared:
    """What ``siloflow.runs.prepare_run`` returns, for a run that writes its record and nothing else."""

    def __init__(self, case_file, folder):
        self.case = load_case(case_file)
        self.folder = Path(folder)
        self.folder.mkdir(parents=True)

    def execute(self, progress=None, cache=None, on_cache_hit=None, on_warning=None):
        from siloflow.run_folder import RunRecord
        record = RunRecord(folder=str(self.folder), engine="fake", command=["fake"], returncode=0, wall_time=0.5,
                           stage_steps={}, inserted=10, settled_ke_pe=1e-6, completed=True,
                           fill_cache={"key": "k", "hit": False})
        (self.folder / RECORD_NAME).write_text(json.dumps(record.to_json()))
        return record


def test_the_sweep_runs_the_api_and_starts_no_siloflow_command(quick_dict, tmp_path, monkeypatch):
    """Issue 37: the sweep calls siloflow.runs, in worker processes, and starts no ``siloflow`` subprocess."""
    import siloflow.runs
    tried = tmp_path / "siloflow_commands.txt"

    def refuse(real):
        def guarded(*args, **kwargs):
            argv = args[0] if args else kwargs.get("args", [])
            text = " ".join(map(str, argv)) if isinstance(argv, (list, tuple)) else str(argv)
            if "siloflow" in text:
                with open(tried, "a") as fh:         # the worker's memory is its own: say it in a file
                    fh.write(text + "\n")
                raise AssertionError(f"a siloflow subprocess: {text}")
            return real(*args, **kwargs)
        return guarded
    monkeypatch.setattr(subprocess, "Popen", refuse(subprocess.Popen))
    for name in ("system", "execv", "execve", "execvp", "posix_spawn", "posix_spawnp"):
        if hasattr(os, name):
            monkeypatch.setattr(os, name, refuse(getattr(os, name)))
    monkeypatch.setattr(siloflow.runs, "prepare_run", lambda case_file, folder, **kw: _Prepared(case_file, folder))

    def post(folder, measured=None):
        summary = {"flow_rate": {"rate": 0.25, "stderr": 0.01}}
        (Path(folder) / RESULTS).mkdir(exist_ok=True)
        (Path(folder) / RESULTS / SUMMARY_NAME).write_text(json.dumps(summary))
        return summary
    monkeypatch.setattr(siloflow.runs, "post_process", post)
    variants = expand(quick_dict, [parse_set("geometry.orifice_radius=0.006,0.007,0.008"), parse_set("engine.ranks=1")])
    out = tmp_path / "s"
    table = run_sweep(variants, out, cores=2, cache=tmp_path / "c", groups=group_by_fill(variants, FakeEngine()))
    assert not tried.exists(), tried.read_text()
    assert table.status.tolist() == ["complete"] * 3, [Path(p).read_text() for p in table.log]
    assert table.flow_rate_kg_s.tolist() == [0.25] * 3 and table.wall_s.tolist() == [0.5] * 3
    log = (out / "logs" / "quick-000.log").read_text()
    assert "siloflow.runs in a worker process" in log and "engine finished in 0.5 s" in log
    # the guard works: a siloflow command line in a worker is caught, and the run fails
    monkeypatch.setattr(siloflow.runs, "post_process", lambda folder, measured=None: subprocess.run(["siloflow", "post"]))
    table = run_sweep(variants[:1], tmp_path / "t", cores=1, cache=tmp_path / "c",
                      groups=group_by_fill(variants[:1], FakeEngine()))
    assert table.status.tolist() == ["failed"] and "siloflow post" in tried.read_text()


# ------------------------------------------------------------------ Slurm
def sbatch_options(script: str) -> dict:
    return dict(re.findall(r"^#SBATCH --([a-z-]+)=(\S+)$", script, re.M))


def slurm_sweep(quick_dict, out: Path):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014"),
                                   parse_set("geometry.orifice_radius=0.006,0.007,0.008")], seeds=2)
    variants_by_name = {v.name: v for v in variants}
    groups = group_by_fill(variants, FakeEngine())
    return variants_by_name, groups, write_slurm(variants, groups, out, out / "cache")


def test_slurm_scripts_read_back(quick_dict, tmp_path):
    out = tmp_path / "sweep"
    variants, groups, submit = slurm_sweep(quick_dict, out)
    assert submit == out.absolute() / "submit.sh" and os.access(submit, os.X_OK)
    lines = {kind: (out / f"{kind}.txt").read_text().splitlines() for kind in ("fills", "runs")}
    assert len(lines["fills"]) == len(groups) == 4 and len(lines["runs"]) == 8
    assert sorted(lines["fills"] + lines["runs"]) == sorted(f"cases/{name}.yaml" for name in variants)
    group_of = {v.name: key for key, members in groups.items() for v in members}
    fills = {Path(line).stem for line in lines["fills"]}
    assert fills == {members[0].name for members in groups.values()}
    for kind in ("fills", "runs"):
        script = (out / f"{kind}.sbatch").read_text()
        options = sbatch_options(script)
        assert options["array"] == f"0-{len(lines[kind]) - 1}"
        assert options["job-name"] == f"quick-{kind}"
        assert options["ntasks"] == options["ntasks-per-node"] == "2" and options["cpus-per-task"] == "1"
        assert options["nodes"] == "1" and options["output"] == "logs/%x-%A_%a.out"
        assert 'line=$((offset + SLURM_ARRAY_TASK_ID + 1))' in script and f'sed -n "${{line}}p" {kind}.txt' in script
        assert re.search(r'^exec siloflow run "\$case_file" -o "runs/\$name" --cache cache$', script, re.M)
        assert subprocess.run(["bash", "-n", str(out / f"{kind}.sbatch")]).returncode == 0
        for line in lines[kind]:
            case = load_case(out / line)
            assert case.name == Path(line).stem and case.name in variants
    for line in lines["runs"]:              # each run's group has its fill in fills.txt
        key = group_of[Path(line).stem]
        assert groups[key][0].name in fills and groups[key][0].name != Path(line).stem
    text = submit.read_text()
    assert "sbatch --parsable --array=0-3 fills.sbatch 0" in text
    assert 'sbatch --parsable --array=0-7 --dependency=afterok:"$fills_0" runs.sbatch 0' in text
    assert subprocess.run(["bash", "-n", str(submit)]).returncode == 0
    assert (out / "logs").is_dir() and (out / "runs").is_dir()


def fake_bin(folder: Path, name: str, body: str) -> Path:
    folder.mkdir(exist_ok=True)
    path = folder / name
    path.write_text("#!/bin/bash\n" + textwrap.dedent(body))
    path.chmod(0o755)
    return path


def test_slurm_tasks_and_submission_with_fake_sbatch_and_siloflow(quick_dict, tmp_path):
    """The scripts run as Slurm would run them: a task picks its line; submit.sh chains the jobs."""
    out = tmp_path / "sweep"
    bin_dir = tmp_path / "bin"
    calls = tmp_path / "calls"
    fake_bin(bin_dir, "siloflow", f'echo "siloflow $*" >> {calls}\n')
    fake_bin(bin_dir, "sbatch", f"""
        echo "sbatch $*" >> {calls}
        case "$*" in *fills.sbatch*) echo "101;cluster" ;; *) echo 102 ;; esac
        """)
    variants, groups, submit = slurm_sweep(quick_dict, out)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}"}
    subprocess.run(["bash", str(out / "runs.sbatch")], cwd=out, env={**env, "SLURM_ARRAY_TASK_ID": "1"}, check=True)
    second = (out / "runs.txt").read_text().splitlines()[1]
    assert calls.read_text() == f"siloflow run {second} -o runs/{Path(second).stem} --cache cache\n"
    beyond = subprocess.run(["bash", str(out / "fills.sbatch")], cwd=out, capture_output=True, text=True,
                            env={**env, "SLURM_ARRAY_TASK_ID": "4"})
    assert beyond.returncode == 1 and "no case file on line 5" in beyond.stderr
    calls.unlink()
    shown = subprocess.run([str(submit)], cwd=tmp_path, env=env, capture_output=True, text=True, check=True)
    assert calls.read_text().splitlines() == ["sbatch --parsable --array=0-3 fills.sbatch 0",
                                              "sbatch --parsable --array=0-7 --dependency=afterok:101 runs.sbatch 0"]
    assert "fills 1/1: job 101 (4 tasks, lines 1-4 of fills.txt)" in shown.stdout
    assert "runs 1/1: job 102 (8 tasks, lines 1-8 of runs.txt, after job(s) 101)" in shown.stdout


def test_slurm_without_runs_submits_only_the_fills(quick_dict, tmp_path):
    variants = expand(quick_dict, [parse_set("particles.radius=0.0015,0.0014")])
    groups = group_by_fill(variants, FakeEngine())
    submit = write_slurm(variants, groups, tmp_path / "s", tmp_path / "elsewhere" / "cache", siloflow="/opt/my tools/siloflow")
    assert not (tmp_path / "s" / "runs.sbatch").exists() and "runs.sbatch" not in submit.read_text()
    script = (tmp_path / "s" / "fills.sbatch").read_text()
    assert "exec '/opt/my tools/siloflow' run" in script                       # quoted
    assert f"--cache {tmp_path / 'elsewhere' / 'cache'}" in script              # outside the folder: absolute


# ------------------------------------------------------------------ the CLI
@pytest.fixture
def fake_engine(monkeypatch):
    monkeypatch.setattr(sweep, "sweep_engine", lambda variants, need_binary=True: FakeEngine())


def test_cli_sweep_slurm(tmp_path, fake_engine):
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.006,0.008",
                                 "--set", "particles.radius=0.0015,0.0014", "--seeds", "2", "-o", str(out), "--slurm"])
    assert result.exit_code == 0, result.output
    assert "8 runs, 4 fill(s)" in result.output and "submit.sh" in result.output
    assert len((out / "fills.txt").read_text().splitlines()) == 4
    assert len((out / "runs.txt").read_text().splitlines()) == 4
    assert "--cache cache" in (out / "fills.sbatch").read_text()                 # default OUT/cache, relative
    written = {f.name: f.read_bytes() for f in out.iterdir() if f.is_file()}
    assert set(written) == {"sweep.json", "fills.txt", "runs.txt", "fills.sbatch", "runs.sbatch", "submit.sh"}
    # another sweep in its folder: refused, with or without --force
    for force in ([], ["--force"]):
        again = runner.invoke(app, ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.006", "-o", str(out),
                                    "--slurm", *force])
        assert again.exit_code == 1 and "holds another sweep" in again.output, again.output
    # the same sweep again: harmless, with or without --force
    for force in ([], ["--force"]):
        same = runner.invoke(app, ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.006,0.008",
                                   "--set", "particles.radius=0.0015,0.0014", "--seeds", "2", "-o", str(out), "--slurm",
                                   *force])
        assert same.exit_code == 0, same.output
        assert {f.name: f.read_bytes() for f in out.iterdir() if f.is_file()} == written
    # a folder holding no sweep: refused, used with --force, but never its runs nor another case
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    args = ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.006,0.008,0.010", "-o", str(other), "--slurm"]
    again = runner.invoke(app, args)
    assert again.exit_code == 1 and "holds no sweep" in again.output
    (other / "runs" / "quick-000").mkdir(parents=True)
    again = runner.invoke(app, [*args, "--force"])
    assert again.exit_code == 1 and "never replaces a run" in again.output and "quick-000" in again.output
    (other / "runs" / "quick-000").rmdir()
    (other / "cases").mkdir()
    (other / "cases" / "quick-000.yaml").write_text("name: mine\n")
    again = runner.invoke(app, [*args, "--force"])
    assert again.exit_code == 1 and "holds another case" in again.output
    (other / "cases" / "quick-000.yaml").unlink()
    again = runner.invoke(app, [*args, "--force"])
    assert again.exit_code == 0, again.output
    assert (other / "notes.txt").read_text() == "mine" and (other / "submit.sh").is_file()


@pytest.mark.parametrize("args,words", [
    (["--set", "geometry.orifice_radius=0.006,0.02"], "--set geometry.orifice_radius=0.02"),
    (["--set", "geometry.orifice radius=1"], "not a field name"),
    (["--set", "engine.ranks=1,2", "--cores", "1"], "--cores is 1"),
])
def test_cli_sweep_refusals(tmp_path, fake_engine, args, words):
    result = runner.invoke(app, ["sweep", str(QUICK), *args, "-o", str(tmp_path / "s")])
    assert result.exit_code == 1 and words in result.output, result.output
    assert "Traceback" not in result.output


def test_cli_sweep_runs_and_beverloo_reads_its_table(tmp_path, fake_engine, fake_run, monkeypatch):
    command, runs = fake_run
    monkeypatch.setattr(sweep, "run_variant", command)
    monkeypatch.setenv("FAKE_FAIL", "quick-003")
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", str(QUICK), "--set", "geometry.orifice_radius=0.005,0.006,0.007,0.008",
                                 "--set", "engine.ranks=1", "--cores", "2", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "3 runs complete, 1 failed; fills: 1 computed, 2 reused from the cache" in result.output
    assert "failed: quick-003 (exit code 1)" in result.output and str(out / "sweep.csv") in result.output
    assert (out / "cache" / "fills").is_dir()                                   # default OUT/cache
    # beverloo on the table: the complete runs, given a plan and a Beverloo flow rate
    from postprocess.flow_rate import beverloo
    from siloflow.atomic_files import write_json
    from siloflow.derived import derive
    table = pd.read_csv(out / "sweep.csv")
    for row in table[table.status == "complete"].itertuples():
        folder = RunFolder(row.run)
        plan = derive(load_case(out / "cases" / f"{row.name}.yaml"))
        folder.write_plan(plan)
        W = float(beverloo(2 * plan.geometry.outlet_radius, 0.003, 0.58, 1.5, 1500.0, plan.gravity))
        write_json(folder.summary_file, {"flow_rate": {"rate": W, "stderr": 0.01 * W},
                                         "frame_analyses": {"bulk_density_kg_m3": 1500.0}})
    result = runner.invoke(app, ["beverloo", str(out / "sweep.csv"), "-o", str(tmp_path / "bev.csv")])
    assert result.exit_code == 0, result.output
    fit = json.loads((tmp_path / "bev.json").read_text())
    assert fit["runs"] == 3 and fit["C"] == pytest.approx(0.58, rel=1e-6) and fit["k"] == pytest.approx(1.5, rel=1e-6)
    # a relative run column is read from the table's folder; a table without one is refused
    moved = tmp_path / "moved"
    shutil.copytree(out, moved)
    relative = table.assign(run=[f"runs/{n}" for n in table.name])
    relative.to_csv(moved / "sweep.csv", index=False)
    result = runner.invoke(app, ["beverloo", str(moved / "sweep.csv"), "-o", str(tmp_path / "bev2.csv")])
    assert result.exit_code == 0, result.output
    assert pd.read_csv(tmp_path / "bev2.csv").run.str.startswith(str(moved)).all()
    table[["name"]].to_csv(tmp_path / "no_runs.csv", index=False)
    result = runner.invoke(app, ["beverloo", str(tmp_path / "no_runs.csv")])
    assert result.exit_code == 1 and "no 'run' column" in result.output


def test_no_benchmark_starts_a_siloflow_command():
    """Issue 37: the benchmarks run cases through the API (siloflow.runs.run, siloflow.sweep.sweep),
    never a ``siloflow`` command line (``python -m siloflow.cli``, or ``siloflow`` as a program)."""
    root = Path(__file__).resolve().parents[1] / "benchmarks"
    found = []
    for path in sorted(root.glob("*.py")):
        text = path.read_text()
        if "siloflow.cli" in text or re.search(r"""\[\s*["']siloflow["']\s*,""", text):
            found.append(path.name)
    assert found == []
