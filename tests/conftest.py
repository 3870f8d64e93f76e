"""Shared fixtures: the quick case as a dict, and writing case dicts to YAML files; the engine-test mark."""
from __future__ import annotations

import copy
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
QUICK = ROOT / "decks" / "quick.yaml"
SMALL = ROOT / "tests" / "data" / "small_silo.yaml"
#: a LIGGGHTS run of a few seconds: 400 spheres settled in a small silo, 0.1 s of discharge
TINY = {"name": "tiny", "geometry": {"kind": "cylinder", "radius": 0.0125, "height": 0.08, "orifice_radius": 0.0055,
                                     "mesh_segments": 24},
        "sensors": {"bands": 2, "sectors": 4},
        "materials": {"model": "hertz", "particle": {"density": 2500.0, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3},
                      "wall": {"youngs_modulus": 5.0e6, "poisson_ratio": 0.3},
                      "particle_particle": {"friction": 0.5, "restitution": 0.5},
                      "particle_wall": {"friction": 0.5, "restitution": 0.5}},
        "particles": {"kind": "spheres", "radius": 0.00125},
        "fill": {"count": 400, "settle": {"ke_pe_ratio": 1.0e-5, "check_interval": 0.02, "max_time": 1.0,
                                          "static_window": 0.01}},
        "discharge": {"duration": 0.1}, "outputs": {"sample_interval": 0.005, "dump_interval": 0.05},
        "engine": {"ranks": 1, "timestep_fraction": 0.2}, "seed": 4242}


def needs_liggghts(test):
    """An engine test: marked ``engine``, skipped where LIGGGHTS or mpirun is missing."""
    return pytest.mark.engine(pytest.mark.skipif(
        shutil.which("liggghts") is None or shutil.which("mpirun") is None,
        reason="LIGGGHTS not installed (make install-engine); CI installs it")(test))


def engine_run(tmp_path_factory, case, name: str, engine: str | None = None, post: bool = True):
    """A real run of ``case`` (a case file or a dict of case fields; ``engine``: the name of the engine
    to run it on instead of the case's), its case file written as ``<name>.yaml`` in a fresh temporary
    folder and run beside it (``siloflow.run``; ``post``: compute its results now); skipped where the
    engine is LIGGGHTS and LIGGGHTS or mpirun is missing. Returns the ``siloflow.Run`` (``folder``,
    ``record``, ``summary``)."""
    import siloflow
    data = copy.deepcopy(case) if isinstance(case, dict) else yaml.safe_load(Path(case).read_text())
    if engine is not None:
        data["engine"] = {**data.get("engine", {}), "name": engine}
    if data.get("engine", {}).get("name", "liggghts") == "liggghts" and (
            shutil.which("liggghts") is None or shutil.which("mpirun") is None):
        pytest.skip("LIGGGHTS not installed (make install-engine); CI installs it")
    path = tmp_path_factory.mktemp(name) / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return siloflow.run(path, path.with_suffix(""), post=post)


def render(case, folder, **kwargs):
    """``siloflow.deck.render`` with the case's own engine (``siloflow.engine.get_engine``): the
    deck module imports no engine, its callers pass one (``Engine.prepare`` passes itself)."""
    from siloflow.deck import render as render_with
    from siloflow.engine import get_engine
    kwargs.setdefault("engine", get_engine(case.engine.name))
    return render_with(case, folder, **kwargs)


def render_deck(data: dict, folder: Path) -> str:
    """The LIGGGHTS deck ``siloflow render`` writes into ``folder`` for the case fields ``data``
    (their YAML beside it, ``folder.yaml``)."""
    case = folder.with_suffix(".yaml")
    case.write_text(yaml.safe_dump(data))
    subprocess.run([sys.executable, "-m", "siloflow.cli", "render", str(case), "-o", str(folder)], check=True,
                   capture_output=True)
    return (folder / "in.liggghts").read_text()


@pytest.fixture(scope="session")
def small_run(tmp_path_factory):
    """One real LIGGGHTS run of tests/data/small_silo.yaml (about a minute), shared by the
    engine and post-processing tests: (case, folder, run record, results summary)."""
    import siloflow
    from siloflow.case_file import load_case

    folder = tmp_path_factory.mktemp("engine") / "small"
    run = siloflow.run(SMALL, folder)               # the Python entry point, as a notebook uses it
    return load_case(SMALL), run.folder, run.record, run.summary


@pytest.fixture
def quick_dict():
    return copy.deepcopy(yaml.safe_load(QUICK.read_text()))


@pytest.fixture
def write_case(tmp_path):
    def _write(data, name="case.yaml"):
        path = tmp_path / name
        path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
        return path
    return _write


def hooke_materials(density: float, youngs_modulus: float, restitution: float,
                    characteristic_velocity: float = 1.0) -> dict:
    """A ``materials`` section for paper B's hooke law (v_c in m/s, default 1; friction 0.5, same
    particle and wall). Test Eq. 10 at v_c != 1 too (the paper decks use 1.37 and 0.88): at 1 a
    V^2 -> V slip in the formula is invisible."""
    elastic = {"youngs_modulus": youngs_modulus, "poisson_ratio": 0.3}
    pair = {"friction": 0.5, "restitution": restitution}
    return {"model": "hooke", "characteristic_velocity": characteristic_velocity,
            "particle": {"density": density, **elastic},
            "wall": dict(elastic), "particle_particle": dict(pair), "particle_wall": dict(pair)}


def set_path(data: dict, dotted: str, value):
    """Set ``a.b.c`` in a nested dict (creating nothing: the path must exist up to its last key)."""
    keys = dotted.split(".")
    for k in keys[:-1]:
        data = data[k]
    data[keys[-1]] = value
