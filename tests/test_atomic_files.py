"""Atomic writes (siloflow.atomic_files.atomic_path): whole files or none, the umask's mode, and a
temporary name the run folder recognises as an interrupted write."""
import os
import stat

import matplotlib
import pytest

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

from postprocess.report.figures import save_figure  # noqa: E402
from siloflow.atomic_files import atomic_path, write_text  # noqa: E402
from siloflow.run_folder import _TEMP  # noqa: E402


@pytest.fixture
def umask():
    """Set the process umask for one test, and restore it."""
    old = os.umask(0o022)
    yield lambda mask: os.umask(mask)
    os.umask(old)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_files_get_the_umask_mode_not_owner_only(tmp_path, umask, mask, mode):
    umask(mask)
    write_text(tmp_path / "table.csv", "a,b\n1,2\n")
    fig = Figure()
    fig.add_subplot().plot([0, 1])
    save_figure(fig, tmp_path / "figure.png")
    for name in ("table.csv", "figure.png"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "result.csv"
    path.write_text("old\n")
    seen = []
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            seen.append(tmp)
            tmp.write_text("half")
            raise RuntimeError("disk full, say")
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.csv"]
    assert _TEMP.fullmatch(seen[0].name), "the run folder would not know this temporary file"


def test_a_figure_that_fails_to_draw_keeps_the_old_one_and_is_closed(tmp_path):
    import matplotlib.pyplot as plt
    path = tmp_path / "pareto.png"
    path.write_bytes(b"old")
    fig = plt.figure()
    fig.savefig = lambda *a, **k: (_ for _ in ()).throw(ValueError("cannot draw"))
    with pytest.raises(ValueError):
        save_figure(fig, path)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["pareto.png"]
    assert plt.get_fignums() == []
