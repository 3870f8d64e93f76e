"""Issue 37 item 2: one run-to-row function (siloflow.run_row.run_row) for the sweep table, the bench
and the stability envelope: what it reads from a run folder, NaN where the folder holds nothing,
and the three studies' columns are its numbers. No engine runs here."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from siloflow import accuracy_bench, stability, sweep
from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.run_folder import RECORD_NAME, RESULTS, SUMMARY_NAME, RunFolder
from siloflow.run_row import ROW_KEYS, run_row


def write_record(folder: Path, wall=12.5, hit=True, peaks=None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    record = {"folder": str(folder), "engine": "fake", "command": ["fake"], "returncode": 0, "wall_time": wall,
              "stage_steps": {}, "inserted": 10, "settled_ke_pe": 1e-6, "completed": True,
              "fill_cache": {"key": "k", "hit": hit}, "guard_peaks": peaks}
    (folder / RECORD_NAME).write_text(json.dumps(record))


def write_summary(folder: Path, **extra) -> None:
    (folder / RESULTS).mkdir(parents=True, exist_ok=True)
    summary = {"engine_wall_time_s": 99.0,
               "flow_rate": {"rate": 0.02, "stderr": 0.001, "fit_stderr": 0.0004},
               "force_balance": {"ratio": 0.98},
               "bands": [{"band": 0, "static_pressure": 800.0, "dynamic_max_pressure": 1200.0},
                         {"band": 1, "static_pressure": 600.0, "dynamic_max_pressure": 1000.0},
                         {"band": 2, "static_pressure": 30.0, "dynamic_max_pressure": 5000.0}],   # < 5 %: unloaded
               "frame_analyses": {"bulk_solid_fraction": 0.61, "coordination_settled": {"z_mean": 4.5}}, **extra}
    (folder / RESULTS / SUMMARY_NAME).write_text(json.dumps(summary))


def test_a_finished_run_gives_its_headline_numbers(tmp_path):
    write_record(tmp_path)
    write_summary(tmp_path)
    row = run_row(tmp_path)
    assert set(row) == set(ROW_KEYS)
    assert row["wall_s"] == 12.5                          # the run record's, before the summary's copy
    assert row["fill_from_cache"] is True
    assert (row["flow_rate"], row["flow_rate_stderr"]) == (0.02, 0.001)
    assert (row["flow_rate_fit_se"], row["flow_rate_batch_se"]) == (0.0004, 0.001)
    assert row["force_balance_ratio"] == 0.98
    assert row["static_pressure"] == pytest.approx(700.0) and row["dynamic_pressure_max"] == pytest.approx(1100.0)
    assert (row["solid_fraction"], row["coordination"]) == (0.61, 4.5)
    assert all(math.isnan(row[k]) for k in ("max_speed", "max_overlap_fraction", "speed_ratio", "overlap_ratio"))


def test_a_folder_without_results_is_nan_and_a_failed_measurement_too(tmp_path):
    empty = run_row(tmp_path / "nothing")
    assert empty["fill_from_cache"] is None and empty["clogged"] is None
    assert all(math.isnan(v) for k, v in empty.items() if k not in ("fill_from_cache", "clogged"))
    write_record(tmp_path, hit=False)                     # ran, not post-processed
    row = run_row(tmp_path)
    assert row["wall_s"] == 12.5 and row["fill_from_cache"] is False and math.isnan(row["flow_rate"])
    write_summary(tmp_path, frame_analyses={"bulk_solid_fraction": {"error": "too shallow"}})
    row = run_row(tmp_path)
    assert math.isnan(row["solid_fraction"]) and math.isnan(row["coordination"]) and row["flow_rate"] == 0.02
    (tmp_path / RECORD_NAME).unlink()                      # no record: the summary's engine wall time
    assert run_row(tmp_path)["wall_s"] == 99.0


def test_the_guard_peaks_against_its_limits(tmp_path, quick_dict):
    quick_dict.setdefault("engine", {})["guard"] = {"enabled": True}
    plan = derive(case_from_dict(quick_dict))
    g = plan.guard
    RunFolder(tmp_path).write_plan(plan)
    write_record(tmp_path, peaks={"max_speed": 0.5 * g.max_speed, "max_overlap": 0.25 * g.max_overlap})
    row = run_row(tmp_path)
    assert row["speed_ratio"] == pytest.approx(0.5) and row["overlap_ratio"] == pytest.approx(0.25)
    assert row["max_speed"] == pytest.approx(0.5 * g.max_speed)
    assert row["max_overlap_fraction"] == pytest.approx(0.25 * g.max_overlap / g.grain_radius)
    assert stability.peaks(tmp_path) == {k: row[k] for k in ("max_speed", "max_overlap_fraction", "speed_ratio",
                                                              "overlap_ratio")}


def test_the_three_studies_take_their_columns_from_the_row(tmp_path):
    write_record(tmp_path)
    write_summary(tmp_path)
    row = run_row(tmp_path)
    bench = accuracy_bench.run_metrics(tmp_path)
    assert bench == {k: row[k] for k in ("wall_s", *accuracy_bench.QUANTITIES, "flow_rate_fit_se",
                                         "flow_rate_batch_se")}
    table = sweep._results(tmp_path)
    assert table == {"fill_from_cache": True, "wall_s": 12.5, "flow_rate_kg_s": 0.02, "flow_rate_stderr_kg_s": 0.001,
                     "clogged": None, "steady_t_start_s": table["steady_t_start_s"],
                     "steady_t_end_s": table["steady_t_end_s"], "force_balance_ratio": 0.98, "bulk_solid_fraction": 0.61}
    assert math.isnan(table["steady_t_start_s"])          # this summary predates clog and window detection
    write_summary(tmp_path, clogged=None, steady_window_detected={"t_start": 0.4, "t_end": 0.9})
    table = sweep._results(tmp_path)
    assert (table["clogged"], table["steady_t_start_s"], table["steady_t_end_s"]) == (False, 0.4, 0.9)
