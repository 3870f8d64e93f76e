"""A failing engine is explained: message, likely cause, exit code, log kept."""
from __future__ import annotations

import math
import os
import stat
import subprocess

import pytest
import yaml

from conftest import ROOT, render
from siloflow.case_file import case_from_dict
from siloflow.engine import LiggghtsEngine
from siloflow.run_folder import read_status
from siloflow.engine.liggghts.log import LogState, diagnose
from siloflow.errors import CaseError, EngineRunError, SetupError


def _fake_engine(tmp_path, script: str) -> str:
    exe = tmp_path / "fake-liggghts"
    exe.write_text("#!/bin/sh\n" + script)
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    return str(exe)


def test_error_line_becomes_explained_failure(tmp_path, quick_dict):
    quick_dict["engine"]["ranks"] = 1
    exe = _fake_engine(tmp_path, "echo 'SILOFLOW_STAGE fill 100'\necho '   50 0.1 10 0 0 0 0 0'\n"
                                 "printf 'ERROR: Lost atoms: original 10 current 9\\n\\377\\376'\nexit 1\n")
    engine = LiggghtsEngine(executable=exe)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    msg = str(info.value)
    assert "Lost atoms" in msg and "likely cause" in msg and "timestep_fraction" in msg
    assert info.value.returncode == 1
    assert read_status(folder)["state"] == "failed"
    assert (folder / "screen.txt").read_bytes().endswith(b"\xff\xfe")


def test_segfault_is_named(tmp_path, quick_dict):
    quick_dict["engine"]["ranks"] = 1
    exe = _fake_engine(tmp_path, "kill -SEGV $$\n")
    engine = LiggghtsEngine(executable=exe)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(EngineRunError, match="SIGSEGV"):
        engine.execute(folder)


def test_missing_binary_is_a_setup_error():
    with pytest.raises(SetupError, match="make install-engine"):
        LiggghtsEngine(executable="no-such-liggghts-binary").command(1)


def test_too_many_ranks_is_refused():
    with pytest.raises(SetupError, match="engine.ranks"):
        LiggghtsEngine(executable="sh").command((os.cpu_count() or 1) + 1)


def test_log_state_tracks_stages_and_total():
    s = LogState()
    planned = {"fill": 100, "settle": 1000, "static": 10, "open": 5, "discharge": 200}
    for line in ["SILOFLOW_STAGE fill 100", "100 0.1 50 0 0 0 0 0", "SILOFLOW_INSERTED 50",
                 "SILOFLOW_STAGE settle 1000", "150 0.15 50 0 0 0 0 0", "SILOFLOW_SETTLED 1e-9",
                 "SILOFLOW_STAGE static 10"]:
        s.feed(line)
    assert s.stage_steps == {"fill": 0, "settle": 100, "static": 150}
    assert s.inserted == 50 and s.settled_ke_pe == 1e-9
    assert s.total_steps(planned) == 150 + 10 + 5 + 200   # settle ended early: total shrinks


def test_log_state_counts_the_mobilising_stages_once_in_order():
    """fill.mobilise adds mobilise and resettle between the settle and the static window: while they
    run, the stages before them count as they ran and none counts twice."""
    s = LogState()
    planned = {"fill": 100, "settle": 1000, "mobilise": 40, "resettle": 1000, "static": 10, "open": 5,
               "discharge": 200}
    for line in ["SILOFLOW_STAGE fill 100", "100 0.1 50 0 0 0 0 0", "SILOFLOW_STAGE settle 1000",
                 "300 0.3 50 0 0 0 0 0"]:
        s.feed(line)
    assert s.total_steps(planned) == 100 + 1000 + 40 + 1000 + 10 + 5 + 200
    for line in ["SILOFLOW_STAGE mobilise 40", "340 0.34 50 0 0 0 0 0"]:
        s.feed(line)
    assert s.total_steps(planned) == 300 + 40 + 1000 + 10 + 5 + 200
    for line in ["SILOFLOW_STAGE resettle 1000", "500 0.5 50 0 0 0 0 0"]:
        s.feed(line)
    assert s.total_steps(planned) == 340 + 1000 + 10 + 5 + 200


def test_diagnose_known_messages():
    msg, cause, fix = diagnose(["ERROR: Cannot open mesh file meshes/x.stl"], [], 1)
    assert "mesh file" in cause
    msg, cause, fix = diagnose([], [], -9)
    assert "SIGKILL" in msg


def test_run_refused_when_the_output_would_not_fit(tmp_path, monkeypatch):
    """The disk estimate is checked before anything is written."""
    import shutil as _shutil
    from collections import namedtuple

    from typer.testing import CliRunner

    from siloflow.cli import app
    from conftest import SMALL

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(_shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 1000, 1000))
    fake = tmp_path / "liggghts"
    fake.write_text("#!/bin/sh\nexit 0\n")
    fake.chmod(0o755)
    result = CliRunner().invoke(app, ["run", str(SMALL), "-o", str(tmp_path / "run"), "--engine-executable", str(fake)])
    assert result.exit_code == 1
    assert "free" in result.output and "dump_interval" in result.output
    assert not (tmp_path / "run").exists()


@pytest.mark.engine
@pytest.mark.skipif(__import__("shutil").which("liggghts") is None, reason="LIGGGHTS not installed "
                    "(make install-engine); CI installs it, so CI never skips this")
def test_error_that_aborts_mpi_still_reaches_the_message(tmp_path, quick_dict):
    """An ERROR on one rank ends in MPI_Abort, which drops LIGGGHTS' block-buffered screen output
    on a pipe: the message must still reach the user (the engine line-buffers it)."""
    import re

    quick_dict["engine"]["ranks"] = 1
    engine = LiggghtsEngine()
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    deck = (folder / "in.liggghts").read_text()
    # a fill batch that is not there: read_dump opens it on rank 0 only, which ends in error->one
    deck = re.sub(r"read_dump       fill/batch_0002\.txt", "read_dump       fill/batch_none.txt", deck)
    (folder / "in.liggghts").write_text(deck)
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    assert "batch_none.txt" in str(info.value) + info.value.log_tail
    assert info.value.returncode != 0


def test_time_step_verdict_of_the_engine_stops_the_run(tmp_path, quick_dict):
    """check/timestep/gran only warns; siloflow treats its verdict as a failure and stops the
    engine at once instead of letting a wrong run go on for hours."""
    import time

    quick_dict["engine"]["ranks"] = 1
    exe = _fake_engine(tmp_path, "echo 'SILOFLOW_STAGE fill 100'\necho '   50 0.1 10 0 0 0 0 0'\n"
                                 "echo 'WARNING: time-step is 45.676620 % of hertz time "
                                 "(./src/fix_check_timestep_gran.cpp:200)'\nsleep 60\necho 'SILOFLOW_DONE'\n")
    engine = LiggghtsEngine(executable=exe)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    start = time.perf_counter()
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    assert time.perf_counter() - start < 30                       # stopped, not waited for
    msg = str(info.value)
    assert "hertz time" in msg and "timestep_fraction" in msg
    assert info.value.returncode != 0
    assert read_status(folder)["state"] == "failed"
    deck = (folder / "in.liggghts").read_text()
    guard = min(1.0, 1.5 * quick_dict["engine"]["timestep_fraction"])
    line = next(ln for ln in deck.splitlines() if "check/timestep/gran" in ln)
    assert [float(v) for v in line.split()[-2:]] == pytest.approx([guard, guard])


def test_resume_refuses_running_and_complete_runs(tmp_path, quick_dict):
    from siloflow.run_folder import write_status

    engine = LiggghtsEngine(executable="sh")
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    write_status(folder, "complete")
    with pytest.raises(SetupError, match="complete: there is nothing to resume"):
        engine.resume(folder)
    write_status(folder, "running", engine_pid=os.getpid(), siloflow_pid=os.getpid())   # alive
    with pytest.raises(SetupError, match="running"):
        engine.resume(folder)


def test_splice_keeps_the_first_part_before_the_restart_and_the_resumed_rows(tmp_path):
    from siloflow.engine.liggghts.engine import splice_table

    before, after = tmp_path / "flow.txt.before_resume", tmp_path / "flow.txt"
    before.write_text("# header 1\n# step a b\n0 1 2\n100 1 2\n200 9 9\n300 9 9\n")   # 200, 300: lost part
    after.write_text("# header 1\n# step a b\n200 3 4\n300 5 6\n")
    splice_table(before, after, 200)
    assert after.read_text() == "# header 1\n# step a b\n0 1 2\n100 1 2\n200 3 4\n300 5 6\n"
    assert not before.exists()


@pytest.mark.parametrize("templates, atoms, expected", [
    (3990, 3990, "insertion fell short: 3990 of 4000 grains"),          # the fixes did not place them all
    (4000, 3900, r"100 of 4000 atoms \(spheres\) left the box during the fill"),   # placed, then lost: > 1 %
    (4000, 3999, "the run ended before the discharge stage finished"),  # 1 lost: recorded, not the failure
])
def test_short_insertion_and_fill_losses_are_told_apart(tmp_path, quick_dict, templates, atoms, expected):
    quick_dict["engine"]["ranks"] = 1
    quick_dict["fill"] = {"count": 4000}
    half = templates // 2
    log = "\n".join(["SILOFLOW_STAGE fill 100",
                     f"INFO: Particle insertion ins: inserted {half} particle templates (mass 1e-3) at step 1",
                     f"INFO: Particle insertion ins: inserted {templates - half} particle templates (mass 1e-3) at step 50",
                     f"   100 0.1 {atoms} 0 0 0 0 0", f"SILOFLOW_INSERTED {atoms}"])
    # the engine writes its log (-log log.liggghts, the command's last argument) and stops after the fill
    exe = _fake_engine(tmp_path, f"for a; do last=$a; done\nprintf '%s\\n' '{log}' | tee \"$last\"\nexit 0\n")
    engine = LiggghtsEngine(executable=exe)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    engine.execute(folder)
    with pytest.raises(EngineRunError, match=expected):
        engine.collect(folder)


# ------------------------------------------------------------------ issue 13, item 9: messages
def test_an_engine_that_prints_nothing_is_not_sent_to_a_missing_log(tmp_path, quick_dict):
    """/bin/false as the engine: no output and no log.liggghts, so the message may not name it."""
    quick_dict["engine"]["ranks"] = 1
    engine = LiggghtsEngine(executable="/bin/false")
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    assert not (folder / "log.liggghts").exists()
    msg = str(info.value)
    assert "log.liggghts" not in msg
    assert "printed nothing" in msg and "SILOFLOW_LIGGGHTS" in msg


def test_diagnosis_names_only_the_files_that_exist(tmp_path):
    _, _, fix = diagnose([], [], 1, ("some engine output",))
    assert "log.liggghts" not in fix and "screen.txt" not in fix          # no folder: no file named
    (tmp_path / "screen.txt").write_text("some engine output\n")
    _, _, fix = diagnose([], [], 1, ("some engine output",), folder=tmp_path)
    assert "screen.txt" in fix and "log.liggghts" not in fix
    (tmp_path / "log.liggghts").write_text("some engine output\n")
    _, _, fix = diagnose([], [], 1, ("some engine output",), folder=tmp_path)
    assert "log.liggghts" in fix and "screen.txt" in fix


@pytest.mark.parametrize("fix_id, field", [("pts_dust", "particles.dust.radius"), ("pts1", "particles.radius")])
def test_volume_expectancy_too_small_is_explained_in_case_terms(fix_id, field):
    line = (f"ERROR: Fix particletemplate/sphere (id {fix_id}): Volume expectancy too small. Change "
            "'volume_limit' if you are sure you know what you're doing (../fix_template_sphere.cpp:218)")
    message, cause, fix = diagnose([line], [], 1, ("MPI_ABORT was invoked on rank 0",))   # as on 2 ranks
    assert "Volume expectancy too small" in message
    assert "volume_limit" in cause and "1e-12 m3" in cause and "62 um" in cause
    assert field in fix and "6.2e-05 m" in fix


def test_bad_mesh_is_explained_and_engine_bytes_never_reach_the_message(tmp_path, quick_dict):
    """LIGGGHTS' mesh refusal gets a cause and the fields to change; stray binary bytes and
    terminal escape sequences around it are dropped from the message (the screen file keeps them)."""
    quick_dict["engine"]["ranks"] = 1
    exe = _fake_engine(tmp_path, (
        "printf 'ERROR: Mesh plate: The minumum angle of mesh element 9 (line 58) is lower than the specified "
        "curvature. Increase mesh quality or decrease curvature (currently 0.256235\\302\\260)\\n'\n"
        "printf '\\033[31mERROR on proc 0: Fix mesh: Bad mesh, cannot continue.\\033[0m\\n'\n"
        "printf '\\377\\376\\001\\033]0;t\\007\\n'\n"
        "exit 1\n"))
    engine = LiggghtsEngine(executable=exe)
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    with pytest.raises(EngineRunError) as info:
        engine.execute(folder)
    msg = str(info.value)
    assert all(c == "\n" or (c.isprintable() and c != "\ufffd") for c in msg), repr(msg)
    assert "meshes/plate.stl" in info.value.cause and "geometry.orifice_radius" in info.value.fix
    assert "Bad mesh, cannot continue." in info.value.log_tail
    assert b"\xff\xfe\x01\x1b]0;t\x07" in (folder / "screen.txt").read_bytes()


def test_printable_drops_escapes_controls_and_undecodable_bytes():
    from siloflow.engine.liggghts.log import decode, printable

    assert printable("a\x1b[31mred\x1b[0m\x1b]0;title\x07\tx\x00\x9b\ufffd\n") == "ared x\n"
    assert decode(b"ERROR: x\xff\xfe\x1b[2J done\n") == "ERROR: x done\n"


def _tiny_grain_case(quick_dict, radius=3e-5):
    quick_dict["particles"]["radius"] = radius
    quick_dict["fill"]["count"] = 300
    quick_dict["geometry"].update(radius=0.002, height=0.01, orifice_radius=0.0005)
    quick_dict["sensors"] = {"bands": 2}
    return case_from_dict(quick_dict)


def test_grains_below_liggghts_default_volume_limit_get_their_own(quick_dict):
    """LIGGGHTS' particletemplate/sphere refuses spheres under 1e-12 m3 (r < 62 um) unless the
    deck lowers volume_limit; decks of larger grains keep the default (unchanged lines)."""
    from siloflow.derived import derive
    from siloflow.engine.liggghts.deck import monte_carlo_tries, particle_templates
    from siloflow.engine.liggghts.encoding import encode

    def templates(case):
        plan = derive(case)
        return particle_templates(plan, encode(plan), monte_carlo_tries(plan))

    case = _tiny_grain_case(quick_dict)
    (t,) = templates(case)
    assert t["volume_limit"] == pytest.approx(4 / 3 * math.pi * 3e-5 ** 3 / 10)
    quick = case_from_dict(yaml.safe_load((ROOT / "decks" / "quick.yaml").read_text()))
    assert all(t["volume_limit"] is None for t in templates(quick))


def test_a_silo_too_many_grains_across_for_the_engine_bins_is_refused(tmp_path, quick_dict, write_case):
    """LIGGGHTS' bin limit is the engine's own check: the plan derives, its encoding (so render,
    LiggghtsEngine.check and `siloflow validate`) refuses it, naming the field."""
    from typer.testing import CliRunner

    from siloflow.cli import app
    from siloflow.derived import derive
    from siloflow.engine.liggghts.encoding import encode

    quick_dict["particles"]["radius"] = 3e-5
    quick_dict["fill"]["count"] = 300
    case = case_from_dict(quick_dict)
    plan = derive(case)
    with pytest.raises(CaseError, match="neighbour bins") as info:
        encode(plan)
    assert [w for w, _ in info.value.problems] == ["particles"]
    problems = LiggghtsEngine().check(case, plan)
    assert [w for w, _ in problems] == ["particles"] and "neighbour bins" in problems[0][1]
    with pytest.raises(CaseError, match="neighbour bins"):
        render(case, tmp_path / "deck", plan=plan)
    assert not (tmp_path / "deck").exists()
    result = CliRunner().invoke(app, ["validate", str(write_case(quick_dict))])
    assert result.exit_code != 0 and "neighbour bins" in " ".join(result.output.split())


@pytest.mark.engine
def test_engine_reads_the_placed_batch_of_tiny_grains(tmp_path, quick_dict):
    """The deck of 30 um grains, cut after its first placed batch, starts in LIGGGHTS and holds that
    batch's every grain (their insertion template was refused with 'Volume expectancy too small'
    before the deck set volume_limit; siloflow now places sphere fills itself)."""
    folder = render(_tiny_grain_case(quick_dict), tmp_path / "deck")
    lines = (folder / "in.liggghts").read_text().splitlines()
    first = next(k for k, ln in enumerate(lines) if ln.startswith("read_dump"))
    batch = lines[first].split()[1]
    end = next(k for k in range(first, len(lines)) if lines[k].startswith("run "))
    (folder / "in.cut").write_text("\n".join(lines[:end]) + '\nrun 1\nprint "TINY_ATOMS ${natoms}"\n')
    proc = subprocess.run(["liggghts", "-in", "in.cut", "-log", "log.cut"], cwd=folder, capture_output=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    out = proc.stdout.decode("utf-8", "replace")
    assert proc.returncode == 0 and "ERROR" not in out, out[-2000:]
    planned = int((folder / batch).read_text().splitlines()[3])
    assert planned > 0 and f"TINY_ATOMS {planned}" in out


#: stands in for LIGGGHTS stopped by SIGTERM: like its signal handler, it writes a forced restart into
#: its working directory (the run folder) before it quits
_TERM_WRITES_RESTART = """trap 'echo bed > restart_forced_liggghts_$$.data; touch "$TERMINATED"; exit 1' TERM
echo 'SILOFLOW_STAGE fill 100'
while :; do echo '   50 0.1 10 0 0 0 0 0'; sleep 0.05; done
"""


def test_an_interrupted_run_leaves_no_forced_restart_of_liggghts(tmp_path, quick_dict):
    """Issue 34 (smaller): with outputs.vtk false, an interrupted LIGGGHTS run left
    restart_forced_liggghts_<n>.data in the run folder; siloflow wrote it (its engine did), so it goes,
    and one that was there before the run is kept."""
    from siloflow.run_folder import foreign_entries
    quick_dict["engine"]["ranks"] = 1
    quick_dict["outputs"]["vtk"] = False
    terminated = tmp_path / "terminated"
    engine = LiggghtsEngine(executable=_fake_engine(tmp_path, f"TERMINATED='{terminated}'\n" + _TERM_WRITES_RESTART))
    folder = engine.prepare(case_from_dict(quick_dict), tmp_path / "run")
    (folder / "restart_forced_liggghts_7.data").write_text("not this run's")

    def interrupt(stage, step, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        engine.execute(folder, progress=interrupt)
    assert read_status(folder)["state"] == "interrupted"
    assert terminated.is_file()                          # the engine got its SIGTERM and wrote its restart
    assert sorted(p.name for p in folder.glob("restart_forced_liggghts_*")) == ["restart_forced_liggghts_7.data"]
    assert (folder / "restart_forced_liggghts_7.data").read_text() == "not this run's"
    (folder / "restart_forced_liggghts_7.data").unlink()
    assert foreign_entries(folder) == []
