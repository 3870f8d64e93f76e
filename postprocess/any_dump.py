"""Analyses of dump files written by any LIGGGHTS/LAMMPS run (not only siloflow's):
per-frame counts and energies, porosity in measurement spheres, coordination number (from
a contact dump local, else from overlaps) and the force chains of the last frame
(:func:`analyse_dump_files`: :class:`DumpResults`, data only). The report layer
(``postprocess.report.dumps.analyse_any``) writes them."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from siloflow.errors import ReadError

from .analysis_base import FrameAnalysis
from .coordination import Coordination
from .dumps import last_frame, read_frames
from .force_chains import ForceChains, force_chains
from .porosity import MeasureRegion, Porosity


class FrameSummary(FrameAnalysis):
    """Particle count, solid volume (m3), mass (kg, when a mass column exists), kinetic energy
    (J, with mass and velocities), mean speed (m/s) and the height of the highest grain (m)."""

    name = "frames"

    def _single_frame(self, frame, contacts):
        row = {"particles": frame.n}
        if contacts is not None:
            row["contacts"] = contacts.n
        if frame.n == 0:
            return [row]
        pos = frame.positions()
        row["z_max"] = float(pos[:, 2].max())
        if "radius" in frame.data or "diameter" in frame.data:
            row["solid_volume"] = float((4.0 / 3.0 * np.pi * frame.radii() ** 3).sum())
        if "vx" in frame.data:
            v2 = (frame.velocities() ** 2).sum(axis=1)
            row["mean_speed"] = float(np.sqrt(v2).mean())
            if "mass" in frame.data:
                row["kinetic_energy"] = float(0.5 * (frame.column("mass") * v2).sum())
        if "mass" in frame.data:
            row["mass"] = float(frame.column("mass").sum())
        return [row]


_MUST_BE_FINITE = ("x", "y", "z", "xu", "yu", "zu", "xs", "ys", "zs", "xsu", "ysu", "zsu", "vx", "vy", "vz")
_MUST_BE_POSITIVE = ("radius", "diameter", "mass")


def checked(frame):
    """``frame`` if the columns the analyses use hold finite values (positive radii and masses);
    else a ReadError naming the file, step and row (nan in a dump: the run blew up?)."""
    data = frame.data
    cols = [c for c in data.columns if frame.kind == "entries" or c in _MUST_BE_FINITE + _MUST_BE_POSITIVE]
    for col in cols:
        values = data[col].to_numpy()
        bad = ~np.isfinite(values) | ((values <= 0) if col in _MUST_BE_POSITIVE else False)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            line = f", line {frame.meta['line'] + k}" if "line" in frame.meta else f", row {k + 1}"
            want = "a positive finite number" if col in _MUST_BE_POSITIVE else "a finite number"
            raise ReadError(f"{frame.source}: frame at step {frame.timestep}{line}: {col} = {values[k]:g}, "
                            f"expected {want} (did the run blow up?)")
    return frame


def _checked_frames(frames):
    return None if frames is None else (checked(f) for f in frames)


def default_sphere(frame) -> MeasureRegion:
    """A measurement sphere about the grains' median position, radius a quarter of the
    smallest extent of their bounding box (inside the packing for a compact bed)."""
    pos = frame.positions()
    if len(pos) == 0:
        raise ReadError(f"{frame.source}: the last frame (step {frame.timestep}) has no grains; "
                        "give a measurement sphere with --sphere x,y,z,R")
    lo, hi = np.percentile(pos, 2, axis=0), np.percentile(pos, 98, axis=0)
    radius = 0.25 * float((hi - lo).min())
    if not radius > 2.0 * float(frame.radii().mean()):
        raise ReadError(f"{frame.source}: the packing is too thin for a default measurement sphere; "
                        "give one with --sphere x,y,z,R")
    return MeasureRegion("sphere_1", "sphere", tuple(float(c) for c in np.median(pos, axis=0)), radius)


@dataclass
class DumpResults:
    """What :func:`analyse_dump_files` computed: ``summary`` (summary.json's content), the frame
    analyses run (``analyses``: their results and figures) and the last frame's force chains
    (``force_chains``, None without contact forces)."""

    summary: dict
    analyses: list = field(default_factory=list)
    force_chains: ForceChains | None = None


def analyse_dump_files(files, contacts=None, contact_columns=None, spheres=None, every: int = 1) -> DumpResults:
    """Analyse the dump files ``files`` (``dumps.dump_files``' list) and, optionally, the contact
    dumps ``contacts`` (with their ``contact_columns``): per-frame counts, porosity in ``spheres``
    (default: :func:`default_sphere`), coordination, the last frame's force chains."""

    def contact_frames(steps=None):
        """Contact frames streamed from disk (None without contact dumps)."""
        return _checked_frames(read_frames(contacts, columns=contact_columns, steps=steps)) if contacts else None

    def frames_of():
        return _checked_frames(read_frames(files, every=every))

    last = checked(last_frame(files))      # reads and checks every frame
    summary: dict = {"source": [str(f) for f in files][:3] + (["..."] if len(files) > 3 else []),
                     "files": len(files)}
    results = DumpResults(summary)

    frames = FrameSummary().run(frames_of(), contact_frames())
    results.analyses.append(frames)
    summary["frames"] = frames.n_frames
    summary["last_step"] = int(last.timestep)
    summary["particles_last"] = int(last.n)

    if "radius" in last.data or "diameter" in last.data:
        regions = spheres
        if regions is None:
            try:
                regions = [default_sphere(last)]
            except ReadError as exc:
                summary["porosity_skipped"] = str(exc)
        if regions:
            por = Porosity(regions).run(frames_of())
            results.analyses.append(por)
            final = por.table[por.table.step == por.table.step.max()]
            summary["porosity_last"] = dict(zip(final.region, final.porosity.astype(float)))
            if "bulk_density" in final:      # the dump has a mass column
                summary["bulk_density_last_kg_m3"] = dict(zip(final.region, final.bulk_density.astype(float)))
            summary["regions"] = [{"name": r.name, "shape": r.shape, "center": list(r.center), "radius": r.radius}
                                  for r in regions]
        coord = Coordination().run(frames_of(), contact_frames())
        results.analyses.append(coord)
        table = coord.table[coord.table.species == "all"]
        row = table[table.step == table.step.max()].iloc[0]
        summary["coordination_last"] = {"step": int(row.step), "z_mean": float(row.z_mean),
                                        "z_mech": float(row.z_mech), "source": row.source,
                                        "convention": row.convention,
                                        "note": "all grains; grains at walls lack their wall contacts"}
    if contacts:
        match = list(contact_frames([last.timestep]))
        if match and any(c in match[0].data for c in ("fnx", "fx")):
            results.force_chains = force_chains(last, match[0])
    return results


def parse_sphere(text: str, k: int) -> MeasureRegion:
    """``x,y,z,R`` (m) -> a measurement sphere named sphere_<k>."""
    try:
        x, y, z, r = (float(v) for v in text.split(","))
    except ValueError:
        raise ReadError(f"--sphere {text!r}: expected x,y,z,R in metres") from None
    try:
        return MeasureRegion(f"sphere_{k}", "sphere", (x, y, z), r)
    except ValueError as exc:
        raise ReadError(f"--sphere {text!r}: {exc}") from None

