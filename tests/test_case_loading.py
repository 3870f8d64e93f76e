"""Reading a case file (issue 13, item 4): hostile files end in a CaseError naming the line, never
a traceback, a hang or an unbounded read."""
from __future__ import annotations

import contextlib
import os
import signal
import stat

import pytest
from typer.testing import CliRunner

from siloflow.case_file import MAX_CASE_BYTES, MAX_CASE_DEPTH, load_case
from siloflow.cli import app
from siloflow.errors import CaseError

from conftest import QUICK

runner = CliRunner()


class Hung(Exception):
    """Raised by :func:`deadline` (not an OSError, so the code under test cannot swallow it)."""


@contextlib.contextmanager
def deadline(seconds: float):
    """Fail (instead of hanging the suite) if the block takes longer than ``seconds``."""
    def expired(signum, frame):
        raise Hung(f"still reading after {seconds} s")
    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def memory_cap(extra_bytes: int = 512 * 2 ** 20):
    """Cap this process's address space at its current size plus ``extra_bytes`` (an unbounded read
    then fails with MemoryError instead of exhausting the machine)."""
    try:
        import resource
        with open("/proc/self/status") as status:
            size = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmSize:"))
    except (ImportError, OSError, StopIteration):
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = size + extra_bytes if hard == resource.RLIM_INFINITY else min(hard, size + extra_bytes)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def quick_text(seed: str = "12345") -> str:
    return QUICK.read_text().replace("seed: 12345", f"seed: {seed}")


HOSTILE = [
    # (id, text, line of the problem, words)
    ("nested-400-flow", "name: q\ndescription: " + "[" * 400 + "]" * 400 + "\n", 2, "nested deeper"),
    ("nested-400-block", "name: q\n" + "".join("  " * k + f"k{k}:\n" for k in range(400)) + "  " * 400 + "x: 1\n",
     MAX_CASE_DEPTH + 2, "nested deeper"),
    ("complex-key", "name: q\n? [a, b]\n: 1\n", 2, "mapping key"),
    ("complex-key-map", "name: q\n? {a: 1}\n: 1\n", 2, "mapping key"),
    ("tag-float-text", 'name: q\ngravity: !!float "0.00125 shell"\n', 2, "not a valid float"),
    ("tag-int-abc", 'name: q\nseed: !!int "abc"\n', 2, "not a valid int"),
    ("tag-int-0b2", 'name: q\nseed: !!int "0b2"\n', 2, "not a valid int"),
    ("tag-float-empty", 'name: q\ngravity: !!float ""\n', 2, "not a valid float"),
    ("tag-timestamp", 'name: q\ndescription: !!timestamp "x"\n', 2, "not a valid timestamp"),
    ("bad-date", "seed: 1\nname: 2020-13-45\n", 2, "month must be in 1..12"),
    ("seed-4301-digits", quick_text("9" * 4301), quick_text().splitlines().index("seed: 12345") + 1,
     "4300 digits"),
]


@pytest.mark.parametrize("text,line,words", [h[1:] for h in HOSTILE], ids=[h[0] for h in HOSTILE])
def test_hostile_yaml_is_a_case_error_naming_the_line(write_case, text, line, words):
    with pytest.raises(CaseError) as info:
        load_case(write_case(text))
    [(where, message)] = info.value.problems
    assert where == "(yaml)"
    assert message.startswith(f"line {line}, column "), message
    assert words in message
    assert len(message) < 300                     # a 4301-digit value is not echoed whole


def test_depth_limit_leaves_real_cases_alone(write_case):
    """The deepest real nesting (a clump sphere's centre, an analysis region's centre) is far below it."""
    nested = "name: q\n" + "".join("  " * k + f"k{k}:\n" for k in range(MAX_CASE_DEPTH - 2)) + \
        "  " * (MAX_CASE_DEPTH - 2) + "x: [1]\n"
    with pytest.raises(CaseError) as info:
        load_case(write_case(nested))
    assert all(where != "(yaml)" for where, _ in info.value.problems)   # parsed; refused by the schema
    assert load_case(QUICK).name == "quick"


def test_dev_zero_is_refused_without_reading(tmp_path):
    with deadline(10), memory_cap():
        with pytest.raises(CaseError, match="not a regular file|is a device"):
            load_case("/dev/zero")


def test_fifo_is_refused_without_hanging(tmp_path):
    fifo = tmp_path / "case.yaml"
    os.mkfifo(fifo)
    with deadline(10):
        with pytest.raises(CaseError, match="FIFO"):
            load_case(fifo)


def test_a_fifo_swapped_in_after_the_check_cannot_hang(tmp_path, monkeypatch):
    """The open is non-blocking and the opened file is checked again: a FIFO that passes the first
    check (as if swapped in between) is refused, not waited on."""
    fifo = tmp_path / "case.yaml"
    os.mkfifo(fifo)
    real_stat = os.stat
    regular = real_stat(QUICK)

    def stat_as_regular(path, *args, **kwargs):
        return regular if str(path) == str(fifo) else real_stat(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat_as_regular)
    with deadline(10):
        with pytest.raises(CaseError, match="FIFO"):
            load_case(fifo)


def test_directory_and_missing_file_are_case_errors(tmp_path):
    with pytest.raises(CaseError, match="directory"):
        load_case(tmp_path)
    with pytest.raises(CaseError, match="cannot read"):
        load_case(tmp_path / "missing.yaml")


def bytes_read_by_this_process() -> int:
    with open("/proc/self/io") as io:
        return next(int(line.split()[1]) for line in io if line.startswith("rchar:"))


@pytest.mark.skipif(not os.path.exists("/proc/self/io"), reason="needs Linux /proc/self/io")
def test_read_stops_one_byte_past_the_limit(tmp_path):
    """A file over the limit is read only up to one byte past it, never whole."""
    path = tmp_path / "big.yaml"
    path.write_bytes(b"#" * (5 * MAX_CASE_BYTES))
    before = bytes_read_by_this_process()
    with pytest.raises(CaseError, match="larger than"):
        load_case(path)
    assert bytes_read_by_this_process() - before < MAX_CASE_BYTES + 100_000


def test_non_utf8_names_the_line(write_case, tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"name: q\ndescription: caf\xe9\n")
    with pytest.raises(CaseError, match=r"not UTF-8 text \(line 2"):
        load_case(path)


@pytest.mark.parametrize("kind", ["dev-zero", "fifo", "deep"])
def test_validate_cli_gives_a_message_not_a_traceback(tmp_path, kind):
    if kind == "dev-zero":
        target = "/dev/zero"
    elif kind == "fifo":
        target = tmp_path / "pipe.yaml"
        os.mkfifo(target)
    else:
        target = tmp_path / "deep.yaml"
        target.write_text("a: " + "[" * 400 + "]" * 400 + "\n")
    with deadline(20), memory_cap():
        result = runner.invoke(app, ["validate", str(target)])
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert {"dev-zero": "regular file", "fifo": "regular file", "deep": "nested deeper"}[kind] in result.output


def test_regular_case_still_loads_through_a_symlink(tmp_path):
    link = tmp_path / "link.yaml"
    link.symlink_to(QUICK)
    assert stat.S_ISLNK(os.lstat(link).st_mode)
    assert load_case(link).name == "quick"
