"""Issue 55 item 2: ``siloflow beverloo`` leaves out a run whose discharge clogged or never flowed
steadily, naming it; a fit of fewer runs than its parameters + 1, or one missing its runs by more
than 20 % (rms relative residual), is refused with an error and exit code 1, not printed as a
result; ``sweep.csv`` carries ``clogged`` and the steady window. Synthetic run folders (a plan and
a summary), no engine."""
from __future__ import annotations

import json
import math

import pandas as pd
import pytest
from typer.testing import CliRunner

from postprocess.flow_rate import (MAX_RMS_RELATIVE_RESIDUAL, BeverlooFit, beverloo, check_beverloo_fit,
                                   flow_verdict)
from siloflow import sweep
from siloflow.answers import beverloo as fit_runs
from siloflow.atomic_files import write_json
from siloflow.case_file import case_from_dict
from siloflow.cli import app
from siloflow.derived import derive
from siloflow.errors import ReadError
from siloflow.run_folder import RunFolder

runner = CliRunner(env={"COLUMNS": "400"})

#: the probe's silo: 60 mm across, 3 mm spheres; the 7.5 mm orifice clogged with 1.8 g out
CLOG = {"t_last_outflow_s": 0.12, "discharged_mass_kg": 0.0018, "mass_left_kg": 0.6, "window": 0.4}


def steady(t0=0.3, t1=0.8):
    return {"t_start": t0, "t_end": t1, "median_rate": 0.05, "tolerance": 0.2, "n_samples": 40, "resolved": True,
            "reason": ""}


def make_run(tmp_path, quick_dict, name, orifice, rate, clogged=None, steady_window=..., **extra):
    """A run folder of the 60 mm silo with ``orifice`` (m): its plan and a summary with ``rate`` (kg/s),
    ``clogged`` and ``steady_window`` (default :func:`steady`)."""
    case = dict(quick_dict, name=name)
    case["geometry"] = dict(case["geometry"], radius=0.03, orifice_radius=orifice)
    folder = tmp_path / name
    (folder / "results").mkdir(parents=True)
    RunFolder(folder).write_plan(derive(case_from_dict(case)))
    summary = {"flow_rate": {"rate": rate, "stderr": 0.01 * rate, "t_start": 0.3, "t_end": 0.8},
               "frame_analyses": {"bulk_density_kg_m3": 1500.0}, "clogged": clogged,
               "steady_window_detected": steady() if steady_window is ... else steady_window, **extra}
    write_json(RunFolder(folder).summary_file, summary)
    return folder


def law(orifice):
    """Beverloo's flow rate (kg/s) of the 3 mm spheres through ``orifice`` (radius, m): C 0.58, k 1.5."""
    return float(beverloo(2 * orifice, 0.003, 0.58, 1.5, 1500.0, 9.81))


def test_the_verdict_of_a_summary():
    ok = flow_verdict({"flow_rate": {"rate": 0.05}, "clogged": None, "steady_window_detected": steady()})
    assert ok == {"clogged": False, "steady_t_start_s": 0.3, "steady_t_end_s": 0.8, "unsteady": ""}
    clog = flow_verdict({"flow_rate": {"rate": 0.0004}, "clogged": CLOG, "steady_window_detected": steady()})
    assert clog["clogged"] is True and "clogged" in clog["unsteady"] and "1.8 g out" in clog["unsteady"]
    stopped = flow_verdict({"flow_rate": {"rate": 0.01}, "clogged": None, "discharge_stop": {"reason": "clogged"}})
    assert stopped["clogged"] is True and "clogged" in stopped["unsteady"]
    none = flow_verdict({"flow_rate": {"rate": 0.01}, "clogged": None, "steady_window_detected": None})
    assert none["clogged"] is False and "no steady discharge" in none["unsteady"]
    assert math.isnan(none["steady_t_start_s"]) and math.isnan(none["steady_t_end_s"])
    no_rate = flow_verdict({"flow_rate": {"rate": float("nan")}, "clogged": None, "steady_window_detected": steady()})
    assert "no steady flow rate" in no_rate["unsteady"]
    # a summary from before clog detection: not known to have clogged, its rate taken
    old = flow_verdict({"flow_rate": {"rate": 0.05}})
    assert old["clogged"] is None and old["unsteady"] == ""
    # an unresolved window (too few samples) is still a window: the rate has its own
    few = flow_verdict({"flow_rate": {"rate": 0.05}, "clogged": None,
                        "steady_window_detected": {**steady(), "n_samples": 7, "resolved": False}})
    assert few["unsteady"] == ""


def test_the_probe_a_clogged_run_is_left_out_and_two_runs_are_refused(tmp_path, quick_dict):
    """The probe: 7.5, 9, 10.5 mm orifices, the smallest clogged (1.8 g out); the fit printed
    C = 1.445 +/- 1.380, k = 3.38 (rms residual 36224.8 %) and exited 0."""
    runs = [make_run(tmp_path, quick_dict, "r075", 0.0075, 0.0018 / 0.9, clogged=CLOG),
            make_run(tmp_path, quick_dict, "r090", 0.009, 0.0498),
            make_run(tmp_path, quick_dict, "r105", 0.0105, 0.0829)]
    with pytest.raises(ReadError) as info:
        fit_runs(runs)
    text = str(info.value)
    assert "at least 3 runs" in text and "given 2 run(s)" in text
    assert f"left out: {runs[0]}: its discharge clogged" in text
    out = tmp_path / "bev.csv"
    for args in ([str(r) for r in runs], [str(sweep_csv(tmp_path, runs))]):
        result = runner.invoke(app, ["beverloo", *args, "-o", str(out)])
        assert result.exit_code == 1, result.output
        assert "at least 3 runs" in result.output and str(runs[0]) in result.output and "clogged" in result.output
        assert "C = " not in result.output and "Traceback" not in result.output
        assert not out.exists() and not out.with_suffix(".json").exists()


def sweep_csv(tmp_path, runs):
    """A sweep table of ``runs``, every one complete, as an older sweep wrote it (no clogged column)."""
    path = tmp_path / "sweep.csv"
    pd.DataFrame({"run": [str(r) for r in runs], "name": [r.name for r in runs],
                  "status": ["complete"] * len(runs)}).to_csv(path, index=False)
    return path


def test_a_clogged_run_is_named_and_the_rest_fitted(tmp_path, quick_dict):
    orifices = (0.009, 0.0105, 0.012)
    runs = [make_run(tmp_path, quick_dict, "clog", 0.0075, 0.002, clogged=CLOG),
            *(make_run(tmp_path, quick_dict, f"r{k}", r, law(r)) for k, r in enumerate(orifices)),
            make_run(tmp_path, quick_dict, "still", 0.0085, 0.03, steady_window=None)]
    table, fit = fit_runs(runs)
    assert fit.n_runs == 3 and (fit.C, fit.k) == pytest.approx((0.58, 1.5), rel=1e-6)
    assert table.left_out.tolist()[1:4] == ["", "", ""]
    assert "clogged" in table.left_out[0] and "no steady discharge" in table.left_out[4]
    assert table.clogged.tolist() == [True, False, False, False, False]
    out = tmp_path / "bev.csv"
    result = runner.invoke(app, ["beverloo", str(sweep_csv(tmp_path, runs)), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert f"left out of the fit: {runs[0]}: its discharge clogged" in result.output
    assert f"left out of the fit: {runs[4]}: no steady discharge" in result.output
    assert "Beverloo over 3 runs" in result.output
    saved = json.loads(out.with_suffix(".json").read_text())
    assert saved["runs"] == 3 and set(saved["left_out"]) == {str(runs[0]), str(runs[4])}
    assert pd.read_csv(out, keep_default_na=False).left_out.astype(bool).tolist() == [True, False, False, False, True]


def test_a_fit_that_misses_its_runs_is_refused(tmp_path, quick_dict):
    """Four runs flowing by the summaries, one rate ten times the law's: no C and k."""
    orifices = (0.0075, 0.009, 0.0105, 0.012)
    scale = (1.0, 1.0, 10.0, 1.0)
    runs = [make_run(tmp_path, quick_dict, f"r{k}", r, s * law(r)) for k, (r, s) in enumerate(zip(orifices, scale))]
    with pytest.raises(ReadError) as info:
        fit_runs(runs)
    assert "rms relative residual" in str(info.value) and "at most 20%" in str(info.value)
    assert str(runs[2]) in str(info.value)                  # each run with its rate and the fit's
    result = runner.invoke(app, ["beverloo", *map(str, runs), "-o", str(tmp_path / "bev.csv")])
    assert result.exit_code == 1 and "rms relative residual" in result.output, result.output
    assert not (tmp_path / "bev.json").exists() and "Traceback" not in result.output
    # the bound itself, on a fit as fit_beverloo returns it
    check_beverloo_fit(BeverlooFit(0.58, 0.01, 1.5, 0.1, 4, MAX_RMS_RELATIVE_RESIDUAL))
    for bad in (BeverlooFit(1.445, 1.38, 3.38, 1.26, 3, 362.248), BeverlooFit(float("nan"), 0, 1.5, 0, 3, 0.01)):
        with pytest.raises(ValueError):
            check_beverloo_fit(bad)


def test_the_sweep_table_carries_clogged_and_the_steady_window(tmp_path, quick_dict):
    assert {"clogged", "steady_t_start_s", "steady_t_end_s"} <= set(sweep.TABLE_TAIL)
    clogged = make_run(tmp_path, quick_dict, "clog", 0.0075, 0.002, clogged=CLOG, steady_window=steady(0.2, 0.25))
    flowing = make_run(tmp_path, quick_dict, "flow", 0.009, 0.05)
    row = sweep._results(clogged)
    assert row["clogged"] is True and (row["steady_t_start_s"], row["steady_t_end_s"]) == (0.2, 0.25)
    row = sweep._results(flowing)
    assert row["clogged"] is False and (row["steady_t_start_s"], row["steady_t_end_s"]) == (0.3, 0.8)
    nothing = sweep._results(tmp_path / "never_ran")
    assert nothing["clogged"] is None and math.isnan(nothing["steady_t_start_s"])
