"""Predict the disk space a run will use, before it starts, and refuse a run that would not fit.

Text dumps cost about 12 bytes per number; a particle line of siloflow's dump has 16 numbers,
a contact line 15, a VTK particle about 21; a settled frictional bed has about 2 contacts per
particle in pair/gran/local (measured: 4800 per 2500 grains in tests/data/small_silo.yaml,
with 12.5 bytes per number). The number of frames is the planned steps (the settle stage at
its cap) over the dump interval: an upper bound (2.4x what the small test run wrote, which
settled well before its cap).
"""
from __future__ import annotations

import shutil
from pathlib import Path

from .case import Case
from .plan import RunPlan
from .errors import SetupError

BYTES_PER_NUMBER = 12.5
PARTICLE_NUMBERS = 16
CONTACT_NUMBERS = 15
VTK_NUMBERS = 21
CONTACTS_PER_PARTICLE = 2.0
TABLES_BYTES = 5_000_000      # log, screen, ave/time tables, meshes, results (generous)
#: a row of the engine-neutral wall-force table (step, time, wall, 3 forces at 17 digits), and
#: the same wall's three columns in LIGGGHTS' own table
WALL_FORCE_ROW_BYTES = 110


def estimate_bytes(case: Case, d: RunPlan) -> dict:
    """Upper estimate (bytes) of what a run writes, by kind, and the number of dump frames."""
    frames = 0
    planned = sum(d.planned_steps().values())
    out = d.outputs
    if out.dump_every:
        frames = planned // out.dump_every + 1
    n = d.fill.count
    per_frame = {"particle_dumps": n * PARTICLE_NUMBERS * BYTES_PER_NUMBER,
                 "contact_dumps": n * CONTACTS_PER_PARTICLE * CONTACT_NUMBERS * BYTES_PER_NUMBER
                 if out.contacts else 0.0,
                 "vtk": n * VTK_NUMBERS * BYTES_PER_NUMBER if out.vtk else 0.0}
    sizes = {k: int(v * frames) for k, v in per_frame.items()}
    walls = len([w for w in d.walls if w.is_wall])
    sizes["tables"] = TABLES_BYTES + int((planned // out.sample_steps + 1) * walls * WALL_FORCE_ROW_BYTES)
    sizes["total"] = sum(sizes.values())
    sizes["frames"] = frames
    return sizes


def check_disk_space(case: Case, d: RunPlan, folder: Path, allow: bool = False) -> dict:
    """Raise SetupError when the estimate exceeds the free space where ``folder`` will be
    (unless ``allow``); return the estimate."""
    sizes = estimate_bytes(case, d)
    parent = Path(folder).absolute()
    while not parent.exists():
        parent = parent.parent
    free = shutil.disk_usage(parent).free
    if sizes["total"] > free and not allow:
        raise SetupError(
            f"this run would write about {sizes['total'] / 1e9:.2f} GB ({sizes['frames']} dump frames) but "
            f"{parent} has {free / 1e9:.2f} GB free; raise outputs.dump_interval, turn off outputs.vtk or "
            "outputs.contacts, free space, or pass --allow-large-output")
    return sizes
