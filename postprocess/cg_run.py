"""``siloflow cg``: coarse-grain a run folder's dumps (steady window, geometry from the case)
or any LIGGGHTS/LAMMPS dumps (grid given on the command line) into fields and paper B's
profiles and numbers (:func:`analyse_cg`: :class:`CgResults`, data only); the report layer
(``postprocess.report.cg``) writes fields.nc (NetCDF), the profiles as CSV, a summary and figures."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from siloflow.atomic_files import read_json
from siloflow.errors import ReadError
from siloflow.run_folder import CG_SUMMARY_NAME, RunFolder
from siloflow.silos.registry import silo_kind

from .cg_analyses import axial_profiles, janda_fit, kinetic_peak_height, outlet_profiles, species_kinetic_table
from .cg_kernels import make_kernel
from .cg_grids import AxisymmetricGrid, CartesianGrid
from .coarse_grain import CoarseGraining
from .dumps import PRIMITIVE_CONTACT_COLUMNS, frames_by_step, primitive_wall_contacts, read_frames
from .paraview import particle_dump_files


@dataclass
class CgSetup:
    """Where and how to coarse-grain: grid extents (m), outlet (m), time window (timesteps)."""

    atoms: list
    contacts: list | None
    contact_columns: list | None
    r_max: float
    z_lo: float
    z_hi: float
    z_outlet: float
    outlet_radius: float
    particle_density: float | None
    step_lo: int | None = None
    step_hi: int | None = None
    wall_contacts: list | None = None
    wall_contact_columns: list | None = None
    slab_thickness: float | None = None     # a slab silo: the grid is planar (x, z), r_max its half width
    note: str | None = None                  # said in the cg summary
    clump_mass: str = "body"                 # how the dumps carry a clump's mass (clump_bodies.CLUMP_MASS)
    outlet_offset: float = 0.0               # an eccentric outlet's centre at x = outlet_offset, m
    half_depth: float | None = None          # a box silo: the grid is Cartesian, y within -+ half_depth, m
    primitive_walls: list = field(default_factory=list)   # [(layout's primitive wall, its dump files)]: more wall contacts


def primitive_wall_files(run: RunFolder) -> list[tuple[dict, list]]:
    """Each primitive wall of the run's dump layout with its touching-grain dump files in step order
    (``output/dumps/primitive_<name>.<step>.txt``)."""
    files = run.dump_files("primitive_walls") or []
    return [(w, [f for f in files if f.name.startswith(f"primitive_{w['name']}.")]) for w in run.dump_layout.primitive_walls]


def setup_from_run(folder) -> CgSetup:
    """Grid and window of a siloflow run: the silo radius, the outlet region to the settled
    surface, and the steady-flow window of its results."""
    run = folder if isinstance(folder, RunFolder) else RunFolder(folder)
    plan = run.plan
    summary = run.read_summary()
    dt = plan.dt
    rate = summary["flow_rate"]
    atoms = particle_dump_files(run)
    layout = run.dump_layout
    contacts = run.dump_files("contacts")
    walls = run.dump_files("wall_contacts") if layout.wall_contact_columns else None
    primitives = primitive_wall_files(run) if walls else []
    g = plan.geometry
    kind = silo_kind(g.kind)
    top = summary.get("frame_analyses", {}).get("settled_surface_height_m") or g.top
    densities = {sp.density for sp in plan.species}
    rho_p = plan.grains[0].density
    note = None
    if len(densities) > 1:
        note = (f"species of different densities ({', '.join(f'{v:g}' for v in sorted(densities))} kg/m3): "
                f"without partial fields (--species none), solid_fraction = rho / {rho_p:g} "
                "counts the others by their mass")
    return CgSetup(atoms, contacts, layout.contact_columns or None, g.half_width, plan.outlet.z,
                   float(top), 0.0, g.outlet_radius, rho_p,
                   int(rate["t_start"] / dt), int(rate["t_end"] / dt), walls, layout.wall_contact_columns or None,
                   slab_thickness=kind.grid_slab(g), note=note,
                   clump_mass=layout.clump_mass, outlet_offset=getattr(g, "outlet_offset", 0.0),
                   half_depth=kind.grid_half_depth(g), primitive_walls=primitives)


@dataclass
class CgResults:
    """A coarse-graining's results, computed and not yet written: ``dataset`` (the time-averaged
    fields, an xarray Dataset: fields.nc), ``summary`` (cg_summary.json, without its list of
    figures), ``tables`` ({file name: DataFrame}: the outlet, axial and species profiles of an
    (r, z) grid), and for its figures (drawn for an (r, z) grid only, ``figures``) the outlet's
    height ``z_outlet`` and radius ``outlet_radius`` (m)."""

    dataset: Any
    summary: dict
    z_outlet: float
    outlet_radius: float
    figures: bool
    tables: dict = field(default_factory=dict)


def analyse_cg(setup: CgSetup, kernel_name: str = "gaussian", width: float = 2.0, unit: str = "radius",
               nr: int = 100, nz: int = 300, species: str | None = "radius", per_frame: bool = False,
               grid_kind: str = "rz", every: int = 1, method: str = "exact", refine: int = 2) -> CgResults:
    """Coarse-grain the frames in the window: the fields, paper B's profiles and numbers."""

    def in_window(frames):
        for f in frames:
            if setup.step_hi is not None and f.timestep > setup.step_hi:
                return
            if setup.step_lo is None or f.timestep >= setup.step_lo:
                yield f

    first = next(in_window(read_frames(setup.atoms, every=every)), None)   # frames are streamed, not kept
    if first is None:
        raise ReadError(f"no particle frames between steps {setup.step_lo} and {setup.step_hi}")
    radius = float(np.mean(first.radii()))
    kernel = make_kernel(kernel_name, width, unit, radius)
    if setup.slab_thickness is not None:       # planar (x, z): one cell through the slab
        if grid_kind == "rz":
            raise ReadError("a slab silo has no axis: use --grid cartesian (a planar x-z grid)")
        t = 0.5 * setup.slab_thickness
        grid = CartesianGrid([-setup.r_max, -t, setup.z_lo], [setup.r_max, t, setup.z_hi], (nr, 1, nz), slab=True)
    elif grid_kind == "rz":
        if setup.half_depth is not None:
            raise ReadError("a rectangular silo has no axis: use --grid cartesian (an x-y-z grid)")
        if setup.outlet_offset:
            raise ReadError(f"the outlet is {setup.outlet_offset:g} m off the silo's axis: the flow has no axis to "
                            "average about; use --grid cartesian (an x-y-z grid)")
        grid = AxisymmetricGrid(setup.r_max, setup.z_lo, setup.z_hi, nr, nz, method=method, refine=refine)
    else:
        ry = setup.r_max if setup.half_depth is None else setup.half_depth
        grid = CartesianGrid([-setup.r_max, -ry, setup.z_lo], [setup.r_max, ry, setup.z_hi], (nr, nr, nz))
    contacts = read_frames(setup.contacts, columns=setup.contact_columns) if setup.contacts else None
    walls = read_frames(setup.wall_contacts, columns=setup.wall_contact_columns) if setup.wall_contacts else None
    if walls is not None and setup.primitive_walls:      # LIGGGHTS' primitive side walls: their grains' contacts
        walls = frames_by_step(walls, *((primitive_wall_contacts(f, w["style"], w["args"])
                                         for f in read_frames(files, columns=PRIMITIVE_CONTACT_COLUMNS))
                                        for w, files in setup.primitive_walls if files))
    cg = CoarseGraining(grid, kernel, setup.particle_density, species, per_frame=per_frame,
                        clump_mass=setup.clump_mass).run(
        in_window(read_frames(setup.atoms, every=every)), contacts, walls)
    ds = cg.dataset()
    summary = {"frames": len(cg.steps), "steps": [cg.steps[0], cg.steps[-1]], "grid": grid_kind,
               "contacts": setup.contacts is not None, "wall_contacts": setup.wall_contacts is not None,
               "outlet_radius_m": setup.outlet_radius,
               "method": method if grid_kind == "rz" else "exact", **({"lattice_refine": refine} if
                                                                       grid_kind == "rz" and method == "lattice" else {}),
               "z_outlet_m": setup.z_outlet, **kernel.describe(),
               **({"note": setup.note} if setup.note and not species else {})}
    results = CgResults(ds, summary, setup.z_outlet, setup.outlet_radius, figures=grid_kind == "rz")
    if grid_kind == "rz":
        prof = outlet_profiles(ds, setup.z_outlet, setup.outlet_radius)
        axial = axial_profiles(ds, setup.z_outlet)
        results.tables.update({"outlet_profiles.csv": prof, "axial_profiles.csv": axial})
        summary["v_z_centre_outlet"] = float(prof.v_z.iloc[0])
        summary["solid_fraction_centre_outlet"] = float(prof.solid_fraction.iloc[0])
        try:
            summary["janda_fit"] = janda_fit(prof)
        except (RuntimeError, ValueError, TypeError) as exc:
            summary["janda_fit"] = {"error": str(exc)}
        summary["kinetic_peak_height_m"] = kinetic_peak_height(axial, setup.z_outlet)
        if species and "kinetic_pressure_species" in ds:
            results.tables["species_kinetic.csv"] = species_kinetic_table(ds, setup.z_outlet)
    return results


def scaling_across_runs(folders) -> dict:
    """Paper B's scaling with the outlet radius R across coarse-grained runs (folders holding
    cg_summary.json): power-law fits v_z(0) = a R^b (expected b = 1/2) and h_c = a R^b
    (expected b = 1), and the table of the runs."""
    import pandas as pd

    from .cg_analyses import power_law_fit

    rows = []
    for folder in folders:
        try:
            s = read_json(Path(folder) / CG_SUMMARY_NAME, "a coarse-graining summary", allow_nan=True)
        except ReadError as exc:
            raise ReadError(f"{folder}: no readable {CG_SUMMARY_NAME} ({exc}; run `siloflow cg` first)") from None
        if "v_z_centre_outlet" not in s:
            raise ReadError(f"{folder}: not an axisymmetric coarse-graining")
        rows.append({"folder": str(folder), "R": s["outlet_radius_m"], "v_z0": abs(s["v_z_centre_outlet"]),
                     "phi0": s["solid_fraction_centre_outlet"], "h_c": s["kinetic_peak_height_m"]})
    table = pd.DataFrame(rows)
    if table.R.nunique() < 2:
        raise ReadError("scaling needs runs with at least two outlet radii")
    a, b, b_err = power_law_fit(table.R, table.v_z0)
    result = {"v_z0": {"prefactor": a, "exponent": b, "exponent_stderr": b_err, "expected_exponent": 0.5}}
    valid = table[table.h_c > 0]
    if valid.R.nunique() >= 2:
        a, b, b_err = power_law_fit(valid.R, valid.h_c)
        result["h_c"] = {"prefactor": a, "exponent": b, "exponent_stderr": b_err, "expected_exponent": 1.0}
    return {"runs": table.to_dict(orient="records"), **result}
