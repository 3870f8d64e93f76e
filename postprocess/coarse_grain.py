"""Coarse-grained continuum fields from particles (paper B, Section 2.1; MercuryCG's definitions).

For a kernel phi (``cg_kernels``, m^-3), particles i (mass m_i, position r_i, velocity v_i,
species s_i) and contacts (force f_ij on i from j, branch b_ij = r_i - r_j):

    rho(x)      = sum_i m_i phi(x - r_i)                          mass density, kg/m3
    P(x)        = sum_i m_i v_i phi(x - r_i)                      momentum density, kg/(m2 s)
    V           = P / rho                                         velocity, m/s
    sigma_k     = sum_i m_i v'_i v'_i phi,  v'_i = v_i - V(x)     kinetic stress, Pa
                = sum_i m_i v_i v_i phi - rho V V                 (computed this way, one pass)
    sigma_k^a   = sum_{i in a} m_i v'_i v'_i phi                  partial kinetic stress; sums to sigma_k
    sigma_c     = sum_ij f_ij (x) b_ij int_0^1 phi(x - r_j - s b_ij) ds   contact stress, Pa
                  (compressive positive; the line integral by Gauss-Legendre, 2-16 points by
                  branch length over kernel width: see cg_grids.line_points_needed)
    phi_s = rho / rho_p (with species: sum_a rho_a / rho_a,p),  pressures p = trace / 3.

This module holds the accumulator: :func:`coarse_grain_frame` (one frame's kernel sums),
:func:`fields_from_sums` (the fields above from sums) and :class:`CoarseGraining`, a
:class:`~postprocess.analysis_base.FrameAnalysis` that streams frames, accumulates their sums
and time-averages them (or keeps per-frame fields), so memory is one frame plus the grid. The
grids (Cartesian, slab, axisymmetric (r, z)) are in :mod:`postprocess.cg_grids`, their numba
cores in :mod:`postprocess.cg_cores`, the dump-frame adapters in :mod:`postprocess.cg_contacts`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .analysis_base import FrameAnalysis, StepCursor
from .cg_contacts import joined_contacts, species_of
from .cg_cores import CONTACT_CODES, PARTICLE_CODES, PARTICLE_COLUMNS
from .cg_grids import AxisymmetricGrid, CartesianGrid, contact_points, line_points_needed, particle_weights
from .cg_kernels import Kernel
from .clump_bodies import body_centres, body_frame
from .dumps import read_frames
from .memory import check_memory, memory_budget

# the grids are re-exported: every user of CoarseGraining builds one
__all__ = ["AxisymmetricGrid", "CartesianGrid", "CoarseGraining", "coarse_grain_frame", "fields_from_sums"]


# ----------------------------------------------------------------------------- one frame

def coarse_grain_frame(grid, kernel: Kernel, pos, vel, mass, species=None, n_species: int = 0,
                       contacts=None, n_s: int | None = None) -> dict:
    """Raw kernel sums of one frame: ``particles`` (grid..., 10 * (1 + n_species)) and, with
    ``contacts`` = (pos_i, pos_j, force_on_i), ``contact`` (grid..., 9)."""
    pos = np.asarray(pos, float)
    spos, svel = grid.particle_frame(pos, np.asarray(vel, float))
    weights = particle_weights(mass, svel)
    ncol = len(PARTICLE_COLUMNS)
    dest = np.zeros((len(pos), 2), np.int64)
    if species is not None and n_species:
        sp = np.asarray(species, np.int64)
        if sp.min(initial=0) < 0 or sp.max(initial=0) >= n_species:
            raise ValueError(f"species indices must lie in 0..{n_species - 1}")
        dest[:, 1] = ncol * (1 + sp)
    else:
        dest[:, 1] = -1
    nfields = ncol * (1 + (n_species if species is not None else 0))
    raw = grid.accumulate(kernel, spos, weights, dest, nfields, PARTICLE_CODES)
    out = {"particles": grid.combine(raw, PARTICLE_CODES)}
    if contacts is not None:
        pi, pj, f = contacts
        pts, tens = contact_points(pi, pj, f, n_s, kernel)
        cpos, cw = grid.contact_frame(pts, tens)
        cdest = np.zeros((len(cpos), 1), np.int64)
        raw = grid.accumulate(kernel, cpos, cw, cdest, 9, CONTACT_CODES)
        out["contact"] = grid.combine(raw, CONTACT_CODES)
    return out


def fields_from_sums(sums: dict, particle_density: float | None = None, n_species: int = 0,
                     species_density=None) -> dict:
    """Continuum fields from (time-averaged) kernel sums: rho, phi, P, V, kinetic stress and
    pressure, partial fields per species, contact stress and pressure. ``species_density``
    (kg/m3 per species): the partial solid fractions are rho_a / rho_a,p and the solid fraction
    their sum (species of different densities, e.g. scaled dust); else rho / ``particle_density``."""
    part = sums["particles"]
    ncol = len(PARTICLE_COLUMNS)
    rho = part[..., 0]
    P = part[..., 1:4]
    with np.errstate(invalid="ignore", divide="ignore"):
        V = np.where(rho[..., None] > 0, P / rho[..., None], 0.0)
    mvv = part[..., 4:10]
    vv = np.stack([V[..., 0] * V[..., 0], V[..., 1] * V[..., 1], V[..., 2] * V[..., 2],
                   V[..., 0] * V[..., 1], V[..., 0] * V[..., 2], V[..., 1] * V[..., 2]], axis=-1)
    kin = mvv - rho[..., None] * vv
    f = {"rho": rho, "momentum": P, "velocity": V, "kinetic_stress": kin,
         "kinetic_pressure": kin[..., :3].sum(axis=-1) / 3.0}
    if particle_density:
        f["solid_fraction"] = rho / particle_density
    if n_species:
        rho_a, kin_a = [], []
        idx = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
        for s in range(n_species):
            blk = part[..., ncol * (1 + s): ncol * (2 + s)]
            ra, Pa, mvva = blk[..., 0], blk[..., 1:4], blk[..., 4:10]
            comps = [mvva[..., k] - V[..., a] * Pa[..., b] - Pa[..., a] * V[..., b] + ra * V[..., a] * V[..., b]
                     for k, (a, b) in enumerate(idx)]
            rho_a.append(ra)
            kin_a.append(np.stack(comps, axis=-1))
        f["rho_species"] = np.stack(rho_a, axis=-1)
        f["kinetic_stress_species"] = np.stack(kin_a, axis=-2)
        f["kinetic_pressure_species"] = f["kinetic_stress_species"][..., :3].sum(axis=-1) / 3.0
        if species_density is not None:
            f["solid_fraction_species"] = f["rho_species"] / np.asarray(species_density, float)
            f["solid_fraction"] = f["solid_fraction_species"].sum(axis=-1)
        elif particle_density:
            f["solid_fraction_species"] = f["rho_species"] / particle_density
    if "contact" in sums:
        c = sums["contact"]
        f["contact_stress"] = c
        f["contact_pressure"] = (c[..., 0] + c[..., 4] + c[..., 8]) / 3.0
    return f


# ----------------------------------------------------------------------------- over frames

class CoarseGraining(FrameAnalysis):
    """Coarse-grain frames onto a grid; time-average (default) or keep per-frame fields.

        cg = CoarseGraining(grid, gaussian(w), particle_density=7520, species="radius")
        cg.run(read_frames(dumps), contacts=read_frames(local, columns=...))
        ds = cg.dataset()          # xarray.Dataset of the fields
        postprocess.report.files.write_coarse_graining(cg, folder)   # coarse_graining.csv/.parquet, fields.nc

    Frames need positions, velocities, radius, and mass (or ``particle_density`` (kg/m3) to
    compute it from the radius). Memory: one frame, plus the grid sums (times frames if
    per_frame); before the first frame's sums are allocated, :meth:`memory_estimate` is checked
    against half the machine's available memory (``postprocess.memory``), and with per_frame
    again at every frame: a grid beyond it is refused (``SetupError`` naming the estimate and
    the options that size the grid), never allocated.

    After :meth:`run`, in :attr:`results` (and as attributes): ``sum`` (the kernel sums over all
    frames, as :func:`coarse_grain_frame` returns them), ``frames`` (each frame's sums, per_frame
    runs), ``steps`` (the timesteps used), ``classes`` (species labels), ``class_density`` (kg/m3
    per species class, from the first frame with a mass column) and ``table``: one row per frame with ``step``,
    ``particles`` (sources: clumps count once), ``contacts`` (pair and wall contacts used) and
    ``mass`` (kg). :meth:`fields` and :meth:`dataset` give the fields.
    """

    name = "coarse_graining"

    def __init__(self, grid, kernel: Kernel, particle_density: float | None = None, species: str | None = None,
                 species_classes=None, per_frame: bool = False, n_s: int | None = None, clump_mass: str = "body"):
        super().__init__()
        self.clump_mass = clump_mass            # how the dumps carry a clump's mass (clump_bodies.body_frame)
        self.grid, self.kernel, self.rho_p = grid, kernel, particle_density
        self.species, self.species_classes, self.per_frame, self.n_s = species, species_classes, per_frame, n_s
        self._walls: StepCursor | None = None   # wall contact frames during run()
        self._prepare()

    def _prepare(self) -> None:
        """Empty sums: a second run starts afresh."""
        self.classes = self.species_classes
        self.sum = None
        self.class_density = None               # kg/m3 per species class, from the first frame
        self.frames: list[dict] = []
        self.steps: list[int] = []
        self._memory: tuple | None = None      # (budget, first frame's particles, points, species) once checked

    def _mass(self, frame):
        if "mass" in frame.data:
            return frame.column("mass").astype(float)
        if not self.rho_p:
            raise ValueError(f"{frame.source}: no mass column; give particle_density")
        return self.rho_p * 4.0 / 3.0 * np.pi * frame.radii() ** 3

    def add_frame(self, frame, contacts=None, wall_contacts=None) -> dict:
        """Add one frame's sums; clumps (a ``mol`` column) are coarse-grained as rigid bodies
        (:mod:`postprocess.clump_bodies`). Returns the frame's row of :attr:`table` (without
        its step)."""
        centres = body_centres(frame) if "mol" in frame.data else None
        joined = joined_contacts(contacts, wall_contacts, atoms=frame, centres=centres)
        if centres is not None and centres[1] is not None:
            frame = body_frame(frame, self.rho_p, centres, self.clump_mass)
        sp, labels = species_of(frame, self.species, self.classes)
        if self.species is not None and self.classes is None:
            self.classes = labels              # the first frame fixes the classes
        if self.species is not None and self.class_density is None and "mass" in frame.data:
            volume = frame.column("volume").astype(float) if "volume" in frame.data else \
                4.0 / 3.0 * np.pi * frame.radii() ** 3
            mass = frame.column("mass").astype(float)
            k = len(self.classes)
            m, v = np.bincount(sp, mass, k), np.bincount(sp, volume, k)
            if np.all(v > 0):                  # each class's mass per solid volume
                self.class_density = m / v
        pos, vel, masses = frame.positions(), frame.velocities(), self._mass(frame)
        self._check_memory(frame.n, joined, len(self.classes or []))
        sums = coarse_grain_frame(self.grid, self.kernel, pos, vel, masses, sp, len(self.classes or []), joined,
                                  self.n_s)
        if self.per_frame:
            self.frames.append(sums)
        if self.sum is None:
            self.sum = {k: v.copy() for k, v in sums.items()}
        else:
            for k in self.sum:
                self.sum[k] += sums[k]
        self.steps.append(int(frame.timestep))
        return {"particles": frame.n, "contacts": 0 if joined is None else len(joined[0]), "mass": float(masses.sum())}

    def memory_estimate(self, n_particles: int, n_points: int = 0, n_species: int = 0, kept_frames: int = 0) -> int:
        """Bytes (float64 arrays) the coarse-graining holds at once for frames of ``n_particles``
        particles and ``n_points`` contact line-integral points, ``n_species`` partial fields and
        ``kept_frames`` per-frame sums: the running and this frame's sums on every cell, the
        kept frames', and the larger of one accumulation (``grid.sums_bytes``) and the fields
        computed from the sums (about 30 + 14 per species values per cell)."""
        cells = self.grid.cells
        nf = len(PARTICLE_COLUMNS) * (1 + n_species)
        nc = 9 if n_points else 0
        held = 8 * cells * (nf + nc) * (2 + kept_frames)
        accumulate = max(self.grid.sums_bytes(self.kernel, nf, n_particles),
                         self.grid.sums_bytes(self.kernel, 9, n_points) if n_points else 0)
        fields = 8 * cells * (nf + 2 * nc + 30 + 14 * n_species)
        return held + max(accumulate, fields)

    def _memory_fix(self) -> str:
        grid = self.grid
        fix = "choose fewer cells: siloflow cg --nr and --nz (Python: Run.cg(nr=..., nz=...))"
        if grid.kind == "cartesian" and not getattr(grid, "slab", False):
            fix += "; a Cartesian grid has nr x nr x nz cells (--grid rz: nr x nz)"
        if getattr(grid, "method", "") == "lattice":
            fix += "; or a smaller --refine (refine=...), or --method exact"
        if self.species is not None:
            fix += "; --species none (species=None) drops the per-species sums"
        return fix

    def _check_memory(self, n_particles: int, joined, n_species: int) -> None:
        """Refuse (``SetupError``) a grid whose sums would not fit in the memory budget, before
        the first frame's are allocated, and with ``per_frame`` each next frame's that would not."""
        if self._memory is None:
            if joined is None:
                points = 0
            elif self.n_s is not None:
                points = int(self.n_s) * len(joined[0])
            else:
                points = int(line_points_needed(np.linalg.norm(joined[0] - joined[1], axis=1), self.kernel).sum())
            self._memory = (memory_budget(), n_particles, points, n_species)
            need = self.memory_estimate(n_particles, points, n_species, 1 if self.per_frame else 0)
            check_memory(need, f"coarse-graining on {self.grid.describe()} ({self.grid.cells:,} cells)",
                         self._memory_fix() + ("; --per-frame (per_frame=True) keeps every frame's sums too"
                                               if self.per_frame else ""), self._memory[0])
        elif self.per_frame:
            budget, particles, points, species = self._memory
            need = self.memory_estimate(particles, points, species, len(self.frames) + 1)
            check_memory(need, f"--per-frame (per_frame=True) on {self.grid.describe()}, keeping the sums of "
                         f"{len(self.frames) + 1} frames,",
                         "leave --per-frame off (the time average needs one frame's sums), keep fewer frames "
                         "(--every n; Python every=n) or " + self._memory_fix(), budget)

    def run(self, frames, contacts=None, wall_contacts=None, start: int = 0, stop: int | None = None,
            step: int = 1):
        """Coarse-grain ``frames``; with ``contacts`` (and ``wall_contacts``), only the frames that
        have a contact frame of the same timestep (all streams in increasing step order; a
        path is read with :func:`postprocess.dumps.read_frames`). ``start``, ``stop``,
        ``step``: which of those frames, as for every :class:`FrameAnalysis`."""
        if isinstance(wall_contacts, (str, Path)):
            wall_contacts = read_frames(wall_contacts)
        self._walls = StepCursor(wall_contacts) if wall_contacts is not None else None
        try:
            return super().run(frames, contacts, start, stop, step)
        finally:
            self._walls = None

    def _single_frame(self, frame, contacts) -> list[dict]:
        walls = self._walls.at(frame.timestep) if self._walls is not None else None
        return [self.add_frame(frame, contacts, walls)]

    def _conclude(self) -> None:
        self.results.update(sum=self.sum, frames=self.frames, steps=self.steps, classes=self.classes,
                            class_density=self.class_density)

    def fields(self, k: int | None = None) -> dict:
        """Time-averaged fields, or those of frame ``k`` (per_frame runs)."""
        if k is None:
            sums = {key: v / len(self.steps) for key, v in self.sum.items()}
        else:
            sums = self.frames[k]
        return fields_from_sums(sums, self.rho_p, len(self.classes or []), self.class_density)

    def dataset(self, k: int | None = None):
        """The fields as an xarray Dataset with coordinates and units (SI)."""
        import xarray as xr

        f = self.fields(k)
        axes = self.grid.axes()
        dims = ("z", "r") if self.grid.kind == "rz" else ("z", "y", "x")
        comps = "rtz" if self.grid.kind == "rz" else "xyz"
        coords = {d: axes[d] for d in dims}
        sym = [comps[a] + comps[b] for a, b in [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]]
        full = [comps[a] + comps[b] for a in range(3) for b in range(3)]
        data = {"rho": (dims, f["rho"], "kg m-3", "mass density"),
                "momentum": (dims + ("component",), f["momentum"], "kg m-2 s-1", "momentum density"),
                "velocity": (dims + ("component",), f["velocity"], "m s-1", "velocity P/rho"),
                "kinetic_stress": (dims + ("sym",), f["kinetic_stress"], "Pa", "kinetic stress"),
                "kinetic_pressure": (dims, f["kinetic_pressure"], "Pa", "trace of the kinetic stress / 3")}
        if "solid_fraction" in f:
            data["solid_fraction"] = (dims, f["solid_fraction"], "1", "rho / rho_p" if self.class_density is None
                                      else "sum over species of rho_a / rho_a,p")
        if "contact_stress" in f:
            data["contact_stress"] = (dims + ("tensor",), f["contact_stress"], "Pa", "contact stress")
            data["contact_pressure"] = (dims, f["contact_pressure"], "Pa", "trace of the contact stress / 3")
        if "rho_species" in f:
            data["rho_species"] = (dims + ("species",), f["rho_species"], "kg m-3", "partial density")
            data["kinetic_stress_species"] = (dims + ("species", "sym"), f["kinetic_stress_species"], "Pa",
                                              "partial kinetic stress")
            data["kinetic_pressure_species"] = (dims + ("species",), f["kinetic_pressure_species"], "Pa",
                                                "partial kinetic pressure")
            if "solid_fraction_species" in f:
                data["solid_fraction_species"] = (dims + ("species",), f["solid_fraction_species"], "1",
                                                  "partial solid fraction")
        ds = xr.Dataset({name: xr.DataArray(v, dims=d, attrs={"units": u, "long_name": ln})
                         for name, (d, v, u, ln) in data.items()},
                        coords={**coords, "component": list(comps), "sym": sym, "tensor": full})
        if "rho_species" in f:
            ds = ds.assign_coords(species=[float(c) for c in self.classes])
        ds.attrs.update({"grid": self.grid.kind, "frames": len(self.steps), "first_step": self.steps[0],
                         "last_step": self.steps[-1], "contact_line_points": "adaptive: 2 + ceil(2 L / s)" if self.n_s is None else self.n_s,
                         **{f"kernel_{k}": v for k, v in self.kernel.describe().items()}})
        if self.class_density is not None:
            ds.attrs["species_density_kg_m3"] = [float(v) for v in self.class_density]
        if getattr(self.grid, "slab", False):
            ds.attrs["slab_thickness_m"] = float(self.grid.spacing[1])
            ds.attrs["slab_average"] = "kernel integrated over y, divided by the slab thickness"
        if self.grid.kind == "rz":
            ds.attrs["rz_method"] = self.grid.method
            if self.grid.method == "lattice":
                ds.attrs["lattice_refine"] = self.grid.refine
        return ds
