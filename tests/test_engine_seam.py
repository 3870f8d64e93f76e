"""The seam between what a case means and how an engine writes it (issue 14): the run plan, the
run folder's owner and its engine-neutral tables, the engine registry and launch profile; and the
import graph that follows the data flow, without cycles (issue 37)."""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from siloflow import run_folder as rf
from siloflow.case_file import case_from_dict, load_case
from siloflow.derived import derive
from siloflow.engines import ENGINE_FILES
from siloflow.errors import ReadError
from siloflow.plan import RunPlan
from siloflow.run_folder import RunFolder

ROOT = Path(__file__).resolve().parents[1]
CASES = sorted([*(ROOT / "decks").glob("*.yaml"), *(ROOT / "tests" / "data").glob("*.yaml")])


# ---------------------------------------------------------------- the plan
@pytest.mark.parametrize("case_file", CASES, ids=[c.stem for c in CASES])
def test_plan_round_trips_through_plan_json(case_file):
    """Every shipped case's plan reads back from its JSON equal, field for field, typed."""
    plan = derive(load_case(case_file))
    back = RunPlan.from_json(plan.to_json())
    assert back.model_dump() == plan.model_dump()      # (the plan read back has no triangles)
    assert back.timestep.dt == plan.dt and isinstance(back.fill.region.z_min, float)
    assert [w.name for w in back.walls] == [w.name for w in plan.walls]
    assert all(w.normal is not None and w.projected_area > 0 for w in back.walls if w.role == "band")


def test_plan_json_of_another_shape_or_version_is_refused(quick_dict):
    plan = derive(case_from_dict(quick_dict))
    data = json.loads(plan.to_json())
    data["fill"]["count"] = "many"
    with pytest.raises(ReadError, match=r"fill\.count"):
        RunPlan.from_json(json.dumps(data))
    data = json.loads(plan.to_json())
    data["plan_version"] = 99
    with pytest.raises(ReadError, match="version 99"):
        RunPlan.from_json(json.dumps(data))
    data = json.loads(plan.to_json())
    data["surprise"] = 1
    with pytest.raises(ReadError, match="surprise"):
        RunPlan.from_json(json.dumps(data))


def test_plan_holds_no_liggghts_encoding(quick_dict):
    """Atom types, prime seeds, ave/time's Nevery, the box and the plate shift are LIGGGHTS'
    (siloflow.engine.liggghts.encoding), not the plan's."""
    data = json.loads(derive(case_from_dict(quick_dict)).to_json())
    text = json.dumps(data)
    for word in ("wall_type", "type_pairs", "mass_weights", "plate_shift", "seeds", "sample_every", "box", "skin"):
        assert f'"{word}"' not in text
    assert all("type" not in sp for sp in data["species"])


def test_siloflow_run_derives_the_plan_once(tmp_path, quick_dict, monkeypatch):
    """``siloflow run`` computes the plan once and hands it on: rendering, the engine's check
    and the run itself do not derive again (the engine is stubbed: no run, no post)."""
    import yaml
    from typer.testing import CliRunner

    import siloflow.derived
    from siloflow.cli import app
    from siloflow.engine.liggghts.engine import LiggghtsEngine
    from siloflow.run_folder import RunRecord

    calls = []
    real = siloflow.derived.derive
    monkeypatch.setattr(siloflow.derived, "derive", lambda case: calls.append(case.name) or real(case))

    def fake_execute(self, folder, progress=None, resume=False):
        assert RunFolder(folder).plan.fill.count > 0          # the folder's plan is complete
        return RunRecord(str(folder), "liggghts", [], 0, 0.0, {}, None, None, True)

    monkeypatch.setattr(LiggghtsEngine, "execute", fake_execute)
    monkeypatch.setattr(LiggghtsEngine, "collect", lambda self, folder: fake_execute(self, folder))
    monkeypatch.setattr(LiggghtsEngine, "command", lambda self, ranks, *a, **k: ["liggghts"])
    case_file = tmp_path / "case.yaml"
    case_file.write_text(yaml.safe_dump(quick_dict))
    result = CliRunner().invoke(app, ["run", str(case_file), "-o", str(tmp_path / "run"), "--no-post"])
    assert result.exit_code == 0, result.output
    assert calls == [quick_dict["name"]]


def test_postprocess_never_derives_nor_reads_the_case():
    """No module of postprocess/ imports the case (schema or loader) or derives a plan, and
    none spells a run-folder file name: they read runs through RunFolder and the dump reader."""
    names = {v for k, v in vars(rf).items() if k.isupper() and isinstance(v, str) and k.endswith(("_NAME", "_TABLE", "DUMPS", "FILE"))}
    names |= {n for f in ENGINE_FILES.values() for n in (*f.names.values(), *f.tables)} | {"derived.json", "output/"}
    assert {"case.yaml", "plan.json", "status.json", "run_record.json", "output/flow.csv", "dump.*.txt"} <= names
    for path in sorted((ROOT / "postprocess").glob("*.py")):
        tree = ast.parse(path.read_text())
        docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                      if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef)) and n.body
                      and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                assert node.module not in ("siloflow.case", "siloflow.case_file", "siloflow.derived"), path.name
                assert not any(a.name.startswith("_") for a in node.names), (path.name, node.module)
            elif isinstance(node, ast.Import):
                assert not any(a.name in ("siloflow.case", "siloflow.case_file") for a in node.names), path.name
            elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                hits = [n for n in names if n in node.value]
                assert not hits, f"{path.name} line {node.lineno} spells {hits}"


# ---------------------------------------------------------------- the import graph (issue 37)
#: the low layers: errors, atomic writes, the case schema and its reading. They reach (through any
#: chain of imports, inside functions too) nothing of the layers after the case in the data flow
LOW_LAYERS = ("siloflow.errors", "siloflow.atomic_files", "siloflow.engines", "siloflow.case", "siloflow.case_reader",
              "siloflow.case_file", "siloflow.packaged_profile")
HIGH_LAYERS = ("siloflow.derived", "siloflow.run_folder", "siloflow.deck", "siloflow.engine", "siloflow.runs",
               "siloflow.cli", "postprocess")


def import_graph(root: Path = ROOT) -> tuple[dict[str, dict[str, int]], dict[str, Path]]:
    """The internal imports of siloflow/ and postprocess/: every import statement anywhere in a
    module (inside functions too), resolved as ../shared/tools/import-cycles resolves them: a
    relative import from the module's package, ``from pkg import name`` to the module ``pkg.name``
    when there is one, else to the nearest enclosing module (``from siloflow import X`` is the
    package's ``__init__``). Returns (module -> {imported module: line}, module -> file)."""
    files = {}
    for pkg in ("siloflow", "postprocess"):
        for path in sorted((root / pkg).rglob("*.py")):
            rel = path.relative_to(root).with_suffix("")
            files[".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)] = path

    def module_of(name):
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = graph.setdefault(name, {})
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module
                if node.level:
                    parts = package.split(".")
                    base = ".".join(parts[:len(parts) - (node.level - 1)] + ([node.module] if node.module else []))
                targets = [f"{base}.{alias.name}" for alias in node.names] + [base]
            else:
                continue
            found = {module_of(t) for t in targets} - {None, name}
            for target in found:
                if not any(other.startswith(target + ".") for other in found):   # the submodule, not its package
                    edges[target] = min(edges.get(target, node.lineno), node.lineno)
    return graph, files


def import_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def test_internal_imports_are_acyclic():
    """Data flows one way (case file -> case -> plan -> deck -> engine -> run folder -> analyses ->
    report) and so do imports: no chain of imports, not even one inside a function, leads from a
    module back to itself (what ../shared/tools/import-cycles reports)."""
    graph, files = import_graph()
    assert {"siloflow", "siloflow.case", "siloflow.engine.base", "postprocess.first_results"} <= set(graph)
    assert graph["siloflow.deck"]["siloflow.run_folder"] and graph["siloflow.runs"]["postprocess.report"]
    problems = []
    for cycle in import_cycles(graph):
        edges = [f"{a} -> {b} ({files[a].relative_to(ROOT)}:{graph[a][b]})" for a in cycle for b in cycle
                 if b in graph[a]]
        problems.append(f"cycle of {len(cycle)}: " + "; ".join(edges))
    assert not problems, "\n".join(problems)


def test_import_cycles_are_found(tmp_path):
    """The check above sees imports inside functions, relative ones, submodules imported from
    their package and names imported from a package's ``__init__``, and finds their cycles."""
    for name, text in {"siloflow/__init__.py": "def __getattr__(name):\n    from . import b\n",
                       "siloflow/a.py": "def f():\n    from .b import g\n",
                       "siloflow/b.py": "from siloflow import a\n",
                       "siloflow/c.py": "import os\nfrom . import VERSION\n",
                       "siloflow/engine/__init__.py": "from ..c import x\n",
                       "postprocess/__init__.py": "import siloflow.engine\n"}.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    graph, _ = import_graph(tmp_path)
    assert graph == {"siloflow": {"siloflow.b": 2}, "siloflow.a": {"siloflow.b": 2}, "siloflow.b": {"siloflow.a": 1},
                     "siloflow.c": {"siloflow": 2}, "siloflow.engine": {"siloflow.c": 1},
                     "postprocess": {"siloflow.engine": 1}}
    assert import_cycles(graph) == [["siloflow.a", "siloflow.b"]]
    assert import_cycles({**graph, "siloflow.b": {"siloflow.c": 1}}) == [["siloflow", "siloflow.b", "siloflow.c"]]


def test_low_layers_import_no_later_step():
    """errors, atomic writes, the engine names and the case (schema, reading, packaged profile)
    import, directly or not, nothing of the plan, the run folder, decks, engines or analyses."""
    graph, _ = import_graph()
    for low in LOW_LAYERS:
        reached, todo = set(), [low]
        while todo:
            for target in graph[todo.pop()]:
                if target not in reached:
                    reached.add(target)
                    todo.append(target)
        later = sorted(m for m in reached if any(m == h or m.startswith(h + ".") for h in HIGH_LAYERS))
        assert not later, f"{low} imports (through a chain) {later}"


def _reach(graph, modules) -> set[str]:
    """Every module ``modules`` import, directly or through a chain (inside functions too)."""
    reached, todo = set(), list(modules)
    while todo:
        for target in graph[todo.pop()]:
            if target not in reached:
                reached.add(target)
                todo.append(target)
    return reached


def _within(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


#: the readers of dump files: they read any dump, ours or not, and import nothing of siloflow's
#: but its errors
READERS = ("postprocess.dumps",)
#: what analyses and the report may import of siloflow: errors (and the optional extras' names),
#: atomic writes, the run folder (and the plan it holds), the engine names, and pure formulas
#: (EN 1991-4, clump shapes, the silo kinds: siloflow.silos reaches no step before the run folder)
POST_MAY_IMPORT = ("siloflow.errors", "siloflow.extras", "siloflow.atomic_files", "siloflow.run_folder",
                   "siloflow.plan", "siloflow.engines", "siloflow.design_loads", "siloflow.clumps",
                   "siloflow.silos.registry")
#: the steps before the run folder, which post-processing never reaches
BEFORE_THE_RUN_FOLDER = ("siloflow.derived", "siloflow.profiles", "siloflow.geometry", "siloflow.deck",
                         "siloflow.engine", "siloflow.runs", "siloflow.fill_cache", "siloflow.cli", "siloflow.sweep",
                         "siloflow.case_file")


def test_layers_readers_post_geometry_and_the_run_folder():
    """Issue 37's layers, counting imports inside functions: readers import nothing of ours but
    errors; analyses and the report import only readers, the run folder and pure formulas, and
    reach no step before the run folder; geometry takes the plan's silo, never the case; the run
    folder reaches no engine, deck or analysis."""
    graph, _ = import_graph()
    for reader in READERS:
        ours = {m for m in _reach(graph, [reader]) if not _within(m, READERS)}
        assert ours <= {"siloflow.errors"}, f"{reader} imports {sorted(ours)}"
    post = [m for m in graph if _within(m, ("postprocess",))]
    direct = {t for m in post for t in graph[m] if not _within(t, ("postprocess",))}
    assert direct <= set(POST_MAY_IMPORT), sorted(direct - set(POST_MAY_IMPORT))
    early = sorted(m for m in _reach(graph, post) if _within(m, BEFORE_THE_RUN_FOLDER))
    assert not early, f"postprocess reaches {early}"
    geometry = [m for m in graph if _within(m, ("siloflow.geometry",))]
    assert not {t for m in geometry for t in graph[m] if _within(t, ("siloflow.case", "siloflow.case_file"))}
    late = sorted(m for m in _reach(graph, ["siloflow.run_folder"])
                  if _within(m, ("siloflow.engine", "siloflow.deck", "siloflow.derived", "postprocess", "siloflow.cli",
                                 "siloflow.case_file")))
    assert not late, f"the run folder reaches {late}"


def test_the_run_folder_spells_no_engine_file_name():
    """Each engine declares its files (siloflow.engines.ENGINE_FILES); the run folder spells none
    of them, yet counts every one as siloflow's (``--force`` may replace it) and as evidence of a
    run, and an unknown file beside them as foreign."""
    names = {n for f in ENGINE_FILES.values() for n in (*f.names.values(), *f.tables)}
    tree = ast.parse((ROOT / "siloflow" / "run_folder.py").read_text())
    spelled = {n for node in ast.walk(tree) if isinstance(node, ast.Constant) and isinstance(node.value, str)
               for n in names | {"liggghts", "lammps"} if n in node.value.lower()}
    assert not spelled, f"run_folder.py spells {sorted(spelled)}"
    for f in ENGINE_FILES.values():
        assert all(rf._fixed_name(n) for n in (*f.names.values(), *f.tables) if "deck" not in n)
        assert set(f.ran) <= set(rf.RUN_EVIDENCE)
    assert rf._fixed_name("output/vtk/particles_120.vtk") and rf._fixed_name("output/lammps_state.json")
    assert not rf._fixed_name("log.other_engine") and not rf._fixed_name("output/vtk/notes.txt")


# ---------------------------------------------------------------- the tables
def _flow(n=7):
    step = np.arange(n, dtype=np.int64) * 10
    return pd.DataFrame({"step": step, "time": step * 1e-5, "atoms": np.full(n, 100), "mass_total": 1.0 / 3 + step,
                         "mass_silo": np.linspace(1.0, 0.1, n), "discharged_mass": np.linspace(0, 0.9, n) / 7,
                         "discharged_count": np.arange(n), "ke": np.pi * step, "pe": np.e + step})


def test_engine_neutral_tables_round_trip_exactly_and_refuse_other_shapes(tmp_path):
    run = RunFolder(tmp_path)
    (tmp_path / "output").mkdir()
    flow = _flow()
    run.write_flow(flow.iloc[:, ::-1])               # written in schema order whatever the input's
    back = run.flow()
    assert list(back.columns) == list(rf.FLOW_SCHEMA)
    pd.testing.assert_frame_equal(back, flow, check_exact=True)
    with pytest.raises(ReadError, match="discharged_count"):
        run.write_flow(flow.drop(columns="discharged_count"))
    (tmp_path / rf.FLOW_TABLE).write_text("step,time\n1,2\n")
    with pytest.raises(ReadError, match="lacks column"):
        run.flow()
    with pytest.raises(ReadError, match="wall-force table"):
        run.wall_forces()


def test_liggghts_wall_forces_become_the_long_table_and_back(tmp_path):
    """LIGGGHTS' wide ave/time table -> the engine-neutral long table -> the wide table post
    uses: the same numbers, in the plan's wall order, the counting disc left out."""
    from postprocess.wall_pressure import wide_forces
    from siloflow.case_file import load_case as load
    from siloflow.engine.tables import neutral_wall_forces, wall_force_columns

    plan = derive(load(ROOT / "tests" / "data" / "small_silo.yaml"))
    cols = wall_force_columns(plan.walls)
    rng = np.random.default_rng(3)
    values = rng.normal(size=(5, len(cols) - 1))
    path = tmp_path / "wall_forces.txt"
    lines = ["# Time-averaged data", "# " + " ".join(cols)]
    lines += [" ".join([str(100 * (k + 1))] + [repr(float(v)) for v in row]) for k, row in enumerate(values)]
    path.write_text("\n".join(lines) + "\n")
    long = neutral_wall_forces(path, plan)
    walls = [w for w in plan.walls if w.is_wall]
    assert len(long) == 5 * len(walls) and "outlet" not in set(long.wall)
    run = RunFolder(tmp_path)
    (tmp_path / "output").mkdir()
    run.write_wall_forces(long)
    wide = wide_forces(run.wall_forces(), plan.walls)
    assert list(wide.columns) == cols
    np.testing.assert_array_equal(wide.iloc[:, 1:].to_numpy(), values)
    np.testing.assert_allclose(run.wall_forces().time, np.repeat([[100, 200, 300, 400, 500]], len(walls), 0).ravel()
                               * plan.dt, rtol=1e-15)


# ---------------------------------------------------------------- engines
def test_engine_registry_imports_no_engine_until_asked():
    code = ("import sys, siloflow.engine as e; assert 'siloflow.engine.liggghts' not in sys.modules; "
            "cls = e.engine_class('liggghts'); assert 'siloflow.engine.liggghts' in sys.modules; print(cls.name)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "liggghts"
    from siloflow.engine import get_engine
    from siloflow.errors import SetupError
    with pytest.raises(SetupError, match="unknown engine 'lamps'; known: liggghts"):
        get_engine("lamps")


def test_launch_profile_is_the_machines_not_the_cases(monkeypatch, tmp_path):
    """The binary, launcher and environment come from the profile (or SILOFLOW_LIGGGHTS), and
    the environment reaches the engine's process."""
    from siloflow.engine import LaunchProfile, get_engine
    monkeypatch.setenv("SILOFLOW_LIGGGHTS", "/opt/x/liggghts")
    assert get_engine("liggghts").profile.executable == "/opt/x/liggghts"
    engine = get_engine("liggghts", executable="lmp", mpirun="srun", env={"OMP_NUM_THREADS": "1"})
    assert engine.profile == LaunchProfile("lmp", "srun", {"OMP_NUM_THREADS": "1"})
    env = engine.profile.environment()
    assert env["OMP_NUM_THREADS"] == "1" and env["SILOFLOW_LIGGGHTS"] == "/opt/x/liggghts"
    assert LaunchProfile().environment() is None          # no extra variables: siloflow's own


@pytest.mark.skipif(__import__("shutil").which("liggghts") is None, reason="LIGGGHTS is not installed")
def test_asking_the_engine_version_writes_nothing_where_it_runs(tmp_path, monkeypatch):
    """``liggghts -h`` writes log.liggghts in its working directory: siloflow asks it elsewhere,
    so a user's own log.liggghts in the current directory is never replaced."""
    from siloflow.engine import get_engine
    mine = tmp_path / "log.liggghts"
    mine.write_text("my notes\n")
    monkeypatch.chdir(tmp_path)
    assert "LIGGGHTS" in get_engine("liggghts").version()
    assert mine.read_text() == "my notes\n" and sorted(p.name for p in tmp_path.iterdir()) == ["log.liggghts"]
