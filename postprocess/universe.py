"""LIGGGHTS/LAMMPS granular dumps as an MDAnalysis ``Universe`` (``siloflow.Run.to_universe``).

A Universe has a fixed number of atoms, a silo's dumps do not (the fill inserts grains, the
discharge removes them), so :func:`universe_from_frames` takes the frames of a window and the
particles ``atoms`` says:

- ``"fixed"``: every frame must hold the same particles (by id); otherwise ``ReadError`` naming
  the first frame that differs and the counts;
- ``"common"``: the particles present in every frame of the window (those inserted later or
  discharged earlier are left out; over a discharge, those still in the silo at its end).

For a changing particle count, build one Universe per frame (``universe_from_frames([frame])``).

The Universe (``MDAnalysis.Universe.empty`` with an in-memory trajectory, ``MemoryReader``):

- atoms ordered by dump id; ``ids`` the dump ids, ``types`` the dump's atom type (as a string,
  MDAnalysis' convention: "1"), ``names`` the siloflow species of that type (``type_names``;
  else the type), ``radii`` (m), ``masses`` (kg, from the ``mass`` column when the dump has one);
- residues are rigid bodies: a clump's spheres (same ``mol`` > 0) form one residue with ``resid``
  the clump's ``mol``; every other particle is a residue of its own, ``resid`` = its id plus the
  largest ``mol`` (so the two never clash); one segment ``"silo"``;
- positions in m, velocities in m/s and forces in N when the dump has them (``vx``.., ``fx``..),
  stored as float32 by MDAnalysis (about 1e-8 m at a metre's scale);
- no unit cell: the dump's box is not periodic, and MDAnalysis would take a cell as periodic
  (pass ``dimensions`` to set one, [lx, ly, lz, 90, 90, 90] in m, for analyses that normalise by
  the box volume, e.g. ``InterRDF(norm="rdf")``; ``norm="density"`` or ``"none"`` needs none);
- ``ts.time`` is the time since the window's first frame (s; ``dt`` apart) and the engine's steps
  and times of the frames are ``universe.dump_steps`` and ``universe.dump_times`` (s) when given.

MDAnalysis' units are Angstrom and ps; siloflow's are SI, kept as they are: distances, cutoffs
and ranges given to MDAnalysis' analyses are then in m.
"""
from __future__ import annotations

from typing import Iterable, Optional, Sequence

import numpy as np

from siloflow.errors import ReadError
from siloflow.extras import require

ATOM_POLICIES = ("fixed", "common")


def _mdanalysis():
    """MDAnalysis, or ``siloflow.extras.MissingExtra`` naming the extra to install."""
    return require("mdanalysis", purpose="a Universe of the dumps (Run.to_universe)")


def _ids(frame) -> np.ndarray:
    if "id" not in frame.data:
        raise ReadError(f"{frame.source}: frame at step {frame.timestep} has no id column: its particles "
                        "cannot be followed from frame to frame")
    ids = frame.column("id").astype(np.int64)
    if len(np.unique(ids)) != len(ids):
        raise ReadError(f"{frame.source}: frame at step {frame.timestep} repeats particle ids")
    return ids


def universe_from_frames(frames: Iterable, atoms: str = "fixed", type_names: Optional[dict] = None,
                         dt: Optional[float] = None, steps_to_time: Optional[float] = None,
                         dimensions: Optional[Sequence[float]] = None):
    """An MDAnalysis Universe of the particle ``frames`` (``postprocess.dumps.Frame``, read into
    memory); ``atoms``: ``"fixed"`` or ``"common"`` (module docstring); ``type_names``: {type:
    species name}; ``dt``: the trajectory's frame spacing (s; default from ``steps_to_time`` x the
    steps between the first two frames, else 1); ``steps_to_time``: s per engine step, for
    ``dump_times``; ``dimensions``: a unit cell (m, degrees), default none."""
    if atoms not in ATOM_POLICIES:
        raise ReadError(f"atoms={atoms!r}: choose one of {', '.join(ATOM_POLICIES)}")
    frames = list(frames)
    if not frames:
        raise ReadError("no particle frames in the window")
    mda = _mdanalysis()
    ids = [_ids(f) for f in frames]
    if atoms == "fixed":
        first = np.sort(ids[0])
        for f, i in zip(frames[1:], ids[1:]):
            if len(i) != len(first) or not np.array_equal(np.sort(i), first):
                raise ReadError(f"the particles change in the window: {frames[0].n} at step {frames[0].timestep}, "
                                f"{f.n} at step {f.timestep} (the fill inserts, the discharge removes them); choose "
                                "a window in which they do not (a stage), or atoms='common' (those present in "
                                "every frame), or one Universe per frame")
        keep = first
    else:
        keep = np.sort(ids[0])
        for i in ids[1:]:
            keep = np.intersect1d(keep, i, assume_unique=True)
    if len(keep) == 0:
        raise ReadError(f"no particle is present in every frame of the window (steps {frames[0].timestep}-"
                        f"{frames[-1].timestep})")
    rows = [np.searchsorted(i, keep, sorter=np.argsort(i, kind="stable")) for i in ids]
    rows = [np.argsort(i, kind="stable")[r] for i, r in zip(ids, rows)]
    first, r0 = frames[0], rows[0]
    positions = np.stack([f.positions()[r] for f, r in zip(frames, rows)])
    velocities = np.stack([f.velocities()[r] for f, r in zip(frames, rows)]) if "vx" in first.data else None
    forces = (np.stack([f.data[["fx", "fy", "fz"]].to_numpy(float)[r] for f, r in zip(frames, rows)])
              if all(c in first.data for c in ("fx", "fy", "fz")) else None)

    n = len(keep)
    mol = first.column("mol").astype(np.int64)[r0] if "mol" in first.data else np.zeros(n, np.int64)
    base = int(max(mol.max(initial=0), 0))
    body = np.where(mol > 0, mol, keep + base)
    resids, resindex = np.unique(body, return_inverse=True)
    u = mda.Universe.empty(n, n_residues=len(resids), n_segments=1, atom_resindex=resindex,
                           residue_segindex=np.zeros(len(resids), int), trajectory=False)
    types = first.column("type").astype(np.int64)[r0] if "type" in first.data else np.ones(n, np.int64)
    names = type_names or {}
    u.add_TopologyAttr("ids", keep)
    u.add_TopologyAttr("types", [str(t) for t in types])
    u.add_TopologyAttr("names", [str(names.get(int(t), names.get(str(int(t)), t))) for t in types])
    u.add_TopologyAttr("radii", first.radii()[r0])
    if "mass" in first.data:
        u.add_TopologyAttr("masses", first.column("mass").astype(float)[r0])
    u.add_TopologyAttr("resids", resids)
    u.add_TopologyAttr("segids", ["silo"])
    steps = np.array([f.timestep for f in frames], dtype=np.int64)
    if dt is None:
        dt = float((steps[1] - steps[0]) * steps_to_time) if steps_to_time and len(steps) > 1 else 1.0
    from MDAnalysis.coordinates.memory import MemoryReader
    u.load_new(positions, format=MemoryReader, order="fac", dt=dt, velocities=velocities, forces=forces,
               dimensions=None if dimensions is None else np.asarray(dimensions, float))
    u.dump_steps = steps
    u.dump_times = steps * steps_to_time if steps_to_time else None
    return u
