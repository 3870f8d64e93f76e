# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # siloflow from Python
#
# A case from YAML, changed and validated; a run; its results as pandas tables, its particle
# frames, its coarse-grained fields (xarray) and its dumps as an MDAnalysis Universe.
#
# This notebook needs no engine: it reads the stored run folder `tests/data/tiny_run` (300
# spheres, made once from `tiny_silo.yaml` beside this file; its README says how). Set
# `RUN_ENGINE = True` to run the case with LIGGGHTS instead (about 15 s).
#
# Open it with `jupytext --to notebook examples/silo_api.py` (or Jupyter with jupytext); the
# tests run it headless from this folder (tests/test_python_api.py).

# %%
from pathlib import Path

import siloflow
from siloflow.case import Case
from siloflow.errors import CaseError

HERE = Path.cwd()                      # examples/
STORED_RUN = HERE.parent / "tests" / "data" / "tiny_run"
RUN_ENGINE = False

# %% [markdown]
# ## The case
# `Case.from_yaml` reads and validates a case file; `Case.model_validate` a dict. A case is
# frozen: `case.with_changes({dotted path: value})` gives a new one, validated again whole.

# %%
case = Case.from_yaml(HERE / "tiny_silo.yaml")
print(case.name, case.geometry.kind, case.geometry.orifice_radius, case.fill.count)

wider = case.with_changes({"geometry.orifice_radius": 0.006, "fill.count": 400})
print(wider.geometry.orifice_radius, wider.fill.count)

# %%
for change in ({"geometry.orifice_diameter": 0.012},      # no such field
               {"geometry.orifice_radius": 0.01}):         # wider than the silo
    try:
        case.with_changes(change)
    except CaseError as exc:
        print(exc.problems)

# %%
data = case.model_dump(mode="json")    # a plain dict
data["discharge"]["duration"] = 0.5
print(Case.model_validate(data).discharge.duration)

# %% [markdown]
# ## The run
# `siloflow.run(case, folder)` renders, runs, checks and post-processes as `siloflow run` does
# and returns a `Run`; `siloflow.open_run(folder)` opens a finished one.

# %%
if RUN_ENGINE:
    run = siloflow.run(case, HERE / "runs" / "tiny", force=True)
else:
    run = siloflow.open_run(STORED_RUN)
print(run, run.state)
rate = run.summary["flow_rate"]
print(f"flow rate {rate['rate'] * 1000:.2f} +/- {rate['stderr'] * 1000:.2f} g/s")

# %%
run.flow.head()

# %%
run.wall_pressure.pivot_table(index="time", columns="band", values="pressure").tail()

# %%
for frame in run.frames(every=3):      # the first, before the fill's first batch, is empty
    top = f"top grain at {frame.positions()[:, 2].max() * 1000:.1f} mm" if frame.n else ""
    print(frame.timestep, frame.n, top)

# %% [markdown]
# ## Coarse-grained fields
# `run.cg()` is the folder's `results/cg/fields.nc` (from `siloflow cg`), or, with settings,
# computed now (`run.cg(nr=8, nz=24)`) and not written: an `xarray.Dataset`.

# %%
ds = run.cg()
print(ds.solid_fraction.sizes, float(ds.solid_fraction.max()))
ds.velocity.sel(component="z").plot()

# %% [markdown]
# ## MDAnalysis
# `run.to_universe()` is the closed silo's frames (after the fill, before the opening: a fixed
# set of particles) as an MDAnalysis Universe, in SI units; radius, type, species and body are
# atom attributes. MDAnalysis' analyses then run on the silo.

# %%
import numpy as np
from MDAnalysis.analysis.rdf import InterRDF
from MDAnalysis.lib.NeighborSearch import AtomNeighborSearch

u = run.to_universe()
print(u, u.trajectory, u.dump_steps)
print(u.atoms.radii[:3], u.atoms.types[:3], u.atoms.names[:3])

rdf = InterRDF(u.atoms, u.atoms, nbins=60, range=(0.0, 0.0075), norm="density", exclusion_block=(1, 1)).run()
print(f"first peak at {rdf.results.bins[np.argmax(rdf.results.rdf)] * 1000:.2f} mm (grain diameter 2.5 mm)")

# %%
u.trajectory[-1]                       # the settled bed
search = AtomNeighborSearch(u.atoms)
touching = [len(search.search(a, 1.01 * 2 * a.radius)) - 1 for a in u.atoms]
print(f"mean number of neighbours within 1 % of contact: {np.mean(touching):.2f}")

# %% [markdown]
# Over the discharge the particle count falls: `atoms="common"` keeps those still in the silo at
# the window's end (the default, `atoms="fixed"`, refuses a window whose particles change).

# %%
flowing = run.to_universe("discharge", atoms="common")
print(flowing.trajectory, flowing.dump_times)
