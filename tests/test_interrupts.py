"""Stopping a running engine from outside: SIGTERM (Ctrl-C's sibling) and SIGKILL of siloflow
at a random moment of the run (seeded). The folder must say what happened, keep the log, and
no engine may be left running."""
from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from siloflow.run_folder import run_state

from conftest import ROOT, SMALL

pytestmark = [pytest.mark.engine,
              pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed "
                                 "(make install-engine); CI installs it, so CI never skips this")]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purpose
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except OSError:
        return False


def wait_until(check, timeout: float, what: str):
    end = time.time() + timeout
    while time.time() < end:
        value = check()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def start_run(tmp_path, seed: int):
    folder = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "siloflow.cli", "run", str(SMALL), "-o", str(folder), "--no-post"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)

    def engine_started():
        try:
            status = json.loads((folder / "status.json").read_text())
            screen = (folder / "screen.txt").read_text(errors="replace")
        except (OSError, ValueError):
            return None
        return status if status.get("state") == "running" and "SILOFLOW_STAGE fill" in screen else None

    status = wait_until(engine_started, 60, "the engine to start")
    time.sleep(random.Random(seed).uniform(0.5, 4.0))       # a random moment of the fill or settling
    return proc, folder, status


def test_sigterm_stops_the_engine_and_marks_the_folder(tmp_path):
    proc, folder, status = start_run(tmp_path, seed=1)
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130, out[-2000:]
    assert b"interrupted" in out
    wait_until(lambda: not alive(status["engine_pid"]), 20, "the engine to stop")
    final = run_state(folder)
    assert final["state"] == "interrupted" and final["stage"] in ("fill", "settle", "static")
    assert (folder / "screen.txt").stat().st_size > 0 and (folder / "in.liggghts").is_file()
    assert not list(folder.glob(".*tmp*"))                      # no half-written files left


def test_sigkill_of_siloflow_takes_the_engine_down_and_is_reported(tmp_path):
    proc, folder, status = start_run(tmp_path, seed=2)
    proc.kill()
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    # Linux's parent-death signal stops the engine although siloflow could not
    wait_until(lambda: not alive(status["engine_pid"]), 20, "the engine to die with siloflow")
    assert run_state(folder)["state"] == "abandoned"
    done = subprocess.run([sys.executable, "-m", "siloflow.cli", "status", str(folder)], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert "abandoned" in done.stdout


@pytest.mark.parametrize("how,seed", [("SIGKILL", 3), ("SIGTERM", 4)])
def test_resume_finishes_an_interrupted_run_like_an_uninterrupted_one(tmp_path, small_run, how, seed):
    """Kill siloflow at a random moment after the settled bed was saved (the static, opening or
    discharge stage), then ``siloflow run --resume``: the run completes, its tables run on
    without a gap, and it discharges the same mass as the uninterrupted small run (within the
    run-to-run noise of a chaotic flow: 15 %)."""
    from siloflow.engine.tables import FLOW_COLUMNS, read_ave_time

    folder = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "siloflow.cli", "run", str(SMALL), "-o", str(folder), "--no-post"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    wait_until(lambda: "SILOFLOW_RESTART" in _screen(folder), 180, "the settled bed's restart file")
    status = json.loads((folder / "status.json").read_text())
    time.sleep(random.Random(seed).uniform(0.5, 15.0))
    proc.send_signal(signal.SIGKILL if how == "SIGKILL" else signal.SIGTERM)
    proc.communicate(timeout=60)
    wait_until(lambda: not alive(status["engine_pid"]), 20, "the engine to stop")
    assert run_state(folder)["state"] in ("abandoned", "interrupted")
    done = subprocess.run([sys.executable, "-m", "siloflow.cli", "run", "--resume", str(folder)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert run_state(folder)["state"] == "complete"
    assert (folder / "in.resume.liggghts").is_file() and (folder / "log.resume.liggghts").is_file()
    for table in (read_ave_time(folder / "output" / "flow.txt", FLOW_COLUMNS),
                  read_ave_time(folder / "output" / "wall_forces.txt")):
        steps = table.iloc[:, 0]                              # the step column (named by the file)
        assert steps.is_monotonic_increasing and steps.is_unique                  # spliced, no overlap
        gaps = np.diff(steps.to_numpy())
        assert gaps.max() == np.median(gaps)           # and no hole (the wall forces lost one at the join)
    summary = json.loads((folder / "results" / "summary.json").read_text())
    reference = small_run[3]
    assert summary["particles_inserted"] == reference["particles_inserted"]
    assert summary["initial_mass_kg"] == pytest.approx(reference["initial_mass_kg"], rel=1e-6)
    assert summary["discharged_mass_kg"] == pytest.approx(reference["discharged_mass_kg"], rel=0.15)
    assert summary["force_balance"]["ratio"] == pytest.approx(1.0, abs=0.01)


def _screen(folder) -> str:
    try:
        return (folder / "screen.txt").read_text(errors="replace")
    except OSError:
        return ""
