"""One run over many nodes (issue 59 item 1): ``siloflow run CASE -o DIR --slurm`` renders the folder for
nodes x ranks-per-node MPI ranks and writes one batch script that runs it; the engines launch their
ranks with the job's launcher and count the job's tasks, not this machine's cores."""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from siloflow.cli import app
from siloflow.engine import LiggghtsEngine
from siloflow.engine.processes import check_ranks, launch_ranks, mpi_slots
from siloflow.errors import CaseError, SetupError
from siloflow.slurm import RUN_SCRIPT, slurm_job

ROOT = Path(__file__).resolve().parents[1]
HOSTILE = "run $HOME `id` 'q' \"d\" ; x"


def sbatch_options(script: str) -> dict:
    return dict(line[len("#SBATCH --"):].split("=", 1) for line in script.splitlines() if line.startswith("#SBATCH --")
                and "=" in line)


def submit(tmp_path: Path, *options: str, folder: str = HOSTILE):
    return CliRunner().invoke(app, ["run", str(ROOT / "decks" / "quick.yaml"), "-o", str(tmp_path / folder),
                                    "--slurm", *options], catch_exceptions=False)


def test_one_run_over_four_nodes_is_one_mpi_job_with_the_folder_as_one_argument(tmp_path):
    result = submit(tmp_path, "--nodes", "4", "--ntasks-per-node", "16", "--time", "1-12:00:00",
                    "--partition", "cpu_long", "--account", "silo.lab", "--requeue")
    assert result.exit_code == 0, result.output
    folder = tmp_path / HOSTILE
    script = (folder / RUN_SCRIPT).read_text()
    subprocess.run(["bash", "-n", str(folder / RUN_SCRIPT)], check=True)
    opts = sbatch_options(script)
    assert (opts["nodes"], opts["ntasks-per-node"], opts["ntasks"], opts["cpus-per-task"]) == ("4", "16", "64", "1")
    assert (opts["time"], opts["partition"], opts["account"]) == ("1-12:00:00", "cpu_long", "silo.lab")
    assert opts["signal"].startswith("B:TERM@") and "#SBATCH --requeue" in script
    [line] = [ln for ln in script.splitlines() if " run --resume " in ln]
    words = shlex.split(line.rstrip(" &"))
    assert words[:4] == [sys.executable, "-m", "siloflow.cli", "run"] and words[4:] == ["--resume", str(folder)]
    assert json.loads((folder / "plan.json").read_text())["engine"]["ranks"] == 64       # rendered for the job
    assert "export SILOFLOW_MPIRUN=mpirun" in script and "scontrol requeue" in script
    printed = re.search(r"submit it with: (.*)", result.output.replace("\n", "")).group(1)
    assert shlex.split(printed) == ["cd", str(folder), "&&", "sbatch", RUN_SCRIPT]


def test_the_ranks_default_to_the_case_spread_over_the_nodes(tmp_path):
    assert submit(tmp_path, "--nodes", "2", folder="even").exit_code == 0     # quick.yaml: engine.ranks 2
    assert sbatch_options((tmp_path / "even" / RUN_SCRIPT).read_text())["ntasks-per-node"] == "1"
    result = submit(tmp_path, "--nodes", "4", folder="odd")
    assert result.exit_code != 0 and "--ntasks-per-node" in result.output and not (tmp_path / "odd").exists()


@pytest.mark.parametrize("option, value", [("--time", "1 day"), ("--partition", "a;rm -rf ~"),
                                           ("--account", "$(id)"), ("--nodes", "0"), ("--launcher", "ssh")])
def test_a_bad_job_option_is_refused_by_name_and_nothing_is_written(tmp_path, option, value):
    result = submit(tmp_path, "--ntasks-per-node", "2", option, value, folder="bad")
    assert result.exit_code != 0 and option in result.output, result.output
    assert not (tmp_path / "bad").exists()


def test_job_options_are_validated_with_their_names():
    with pytest.raises(CaseError) as info:
        slurm_job(nodes=2, ntasks_per_node=2, time="99:99:99:99")
    assert [f for f, _ in info.value.problems] == ["--time"]
    assert slurm_job(nodes=3, ntasks_per_node=40, time="90").ranks == 120


def test_ranks_are_counted_against_the_slurm_job_not_this_machine(monkeypatch):
    monkeypatch.setenv("SLURM_NTASKS", "256")
    assert mpi_slots()[0] == 256
    check_ranks(256)
    with pytest.raises(SetupError, match="this Slurm job has 256 tasks"):
        check_ranks(257)
    monkeypatch.delenv("SLURM_NTASKS")
    with pytest.raises(SetupError, match=f"this machine has {os.cpu_count()} cores.*siloflow run --slurm"):
        check_ranks((os.cpu_count() or 1) + 1)


def test_liggghts_starts_its_ranks_with_the_jobs_launcher(tmp_path, monkeypatch):
    srun = tmp_path / "bin" / "srun"
    srun.parent.mkdir()
    srun.write_text("#!/bin/sh\nexit 0\n")
    srun.chmod(0o755)
    monkeypatch.setenv("PATH", f"{srun.parent}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("SILOFLOW_MPIRUN", "srun")
    monkeypatch.setenv("SLURM_NTASKS", "64")
    command = LiggghtsEngine(executable="/bin/sh").command(64)
    assert command[:3] == [str(srun), "--ntasks=64", "--cpus-per-task=1"] and "-np" not in command
    assert launch_ranks(str(srun), 8) == [str(srun), "--ntasks=8", "--cpus-per-task=1"]


def test_a_run_slurm_restarted_on_another_node_is_abandoned_not_running(tmp_path, monkeypatch):
    """A job requeued after a node failure finds its folder 'running' on the dead node: the status names
    the Slurm job and its restart count, so the requeued start knows that run is over and resumes it."""
    from siloflow.run_folder import run_state, write_status

    monkeypatch.setenv("SLURM_JOB_ID", "4242")
    monkeypatch.setenv("SLURM_RESTART_COUNT", "0")
    write_status(tmp_path, "running")
    status = json.loads((tmp_path / "status.json").read_text())
    (tmp_path / "status.json").write_text(json.dumps({**status, "host": "node-017"}))
    assert run_state(tmp_path)["state"] == "running"                # the same start: cannot be checked here
    monkeypatch.setenv("SLURM_RESTART_COUNT", "1")
    state = run_state(tmp_path)
    assert state["state"] == "abandoned" and "Slurm restarted job 4242" in state["reason"]
    monkeypatch.setenv("SLURM_JOB_ID", "9999")                      # another job: not ours to judge
    assert run_state(tmp_path)["state"] == "running"
