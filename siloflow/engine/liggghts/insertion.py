"""Whether a fill batch fits where LIGGGHTS can put it.

``fix insert/rate/region`` (``overlapcheck yes``, ``random_distribute exact``) splits each batch
among the ranks by their share of the region (its volume inside the subdomain, shrunk by the
largest grain's radius), and each rank places its share by random sequential insertion from one
pool of 50 tries per grain, largest grains first. A grain's centre must lie at least its bounding
radius inside the region (``all_in yes``, cylinders) and at least that far from every face of its
rank's subdomain (``check_dist_from_subdomain_border``, default yes; a draw rejected there uses up
a try too; docs/engine_facts.md). A batch asking for more than fits comes in short, and what it
leaves out are its smallest grains (the list is placed largest first): the fill takes more batches
than planned and ends with more large grains than the case asks for, a heavier bed of another size
mix. Since the borders depend on the rank count, so do the fill, the bed's weight and its wall
loads (``make bench-rank-fill``).

:func:`batch_solid_fraction` estimates the solid fraction a batch asks for in the part of the
region its centres can take, on the rank that is asked most, on the processor grid LIGGGHTS builds
(:func:`processor_grid`, the rule of LAMMPS' ``ProcMap``). Cylinders of spheres only: a slab's
region holds the centres (``all_in no``) of a layer a few grains thick, and clumps pack at random
to another fraction, neither measured.
"""
from __future__ import annotations

import math

import numpy as np

from ...plan import RunPlan

#: solid fraction of the usable region a batch may ask for and still come in whole; measured on
#: 1 and 2 ranks with paper B's 7 sizes: whole at 0.27 (8 seeds x 2 rank counts), stalled at
#: 0.41-0.43 on both (benchmarks/results/rank_fill, tests/test_insertion_ranks.py)
PLACEABLE_FRACTION = 0.30
#: Monte-Carlo points for the usable fraction of the region (its error is about 0.2 %)
SAMPLES = 200_000
#: LIGGGHTS gives no grain to a rank whose share of the region is below this over the rank count
MIN_SHARE = 0.02


def processor_grid(box: dict, ranks: int, planar: bool) -> tuple[int, int, int]:
    """The (px, py, pz) grid LIGGGHTS makes of ``ranks`` under the deck's ``processors * * 1``
    (``* 1 *`` for a slab): of the factorisations allowed, the first with the smallest subdomain
    surface (LAMMPS' ``ProcMap::factor``, ``cull_user`` and ``best_factors``)."""
    factors = [(i, j, ranks // i // j) for i in range(1, ranks + 1) if ranks % i == 0
               for j in range(1, ranks // i + 1) if (ranks // i) % j == 0]
    fixed = (0, 1, 0) if planar else (0, 0, 1)
    n, k = len(factors), 0
    while k < n:                 # cull_user: a culled entry is replaced by the last one
        if any(u and f != u for f, u in zip(factors[k], fixed)):
            factors[k] = factors[n - 1]
            n -= 1
        else:
            k += 1
    lx, ly, lz = box["xhi"] - box["xlo"], box["yhi"] - box["ylo"], box["zhi"] - box["zlo"]
    best, best_surf = factors[0], 2.0 * (lx * ly + lx * lz + ly * lz)
    for px, py, pz in factors[:n]:
        surf = lx * ly / px / py + lx * lz / px / pz + ly * lz / py / pz
        if surf < best_surf:
            best, best_surf = (px, py, pz), surf
    return best


def _region_volume(reg) -> float:
    """The cylindrical insertion region's volume, m3."""
    return math.pi * reg.radius ** 2 * (reg.z_max - reg.z_min)


def _region_points(plan: RunPlan, rng) -> tuple[np.ndarray, np.ndarray, float]:
    """Uniform points of the (cylindrical) insertion region, (N, 3); each one's distance to the
    region's surface, m; the region's volume, m3."""
    reg = plan.fill.region
    z = rng.uniform(reg.z_min, reg.z_max, SAMPLES)
    rho = reg.radius * np.sqrt(rng.uniform(0.0, 1.0, SAMPLES))
    phi = rng.uniform(0.0, 2 * math.pi, SAMPLES)
    pts = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])
    to_surface = np.minimum.reduce([reg.radius - rho, z - reg.z_min, reg.z_max - z])
    return pts, to_surface, _region_volume(reg)


def _subdomains(pts: np.ndarray, box: dict, grid: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Each point's subdomain (0 .. px py pz - 1, a uniform split of the box) and its distance to
    the nearest face of it, m."""
    cell = np.zeros(len(pts), dtype=int)
    to_face = np.full(len(pts), np.inf)
    for axis, (lo, hi, n) in enumerate(zip((box["xlo"], box["ylo"], box["zlo"]), (box["xhi"], box["yhi"], box["zhi"]),
                                           grid)):
        width = (hi - lo) / n
        index = np.clip(np.floor((pts[:, axis] - lo) / width), 0, n - 1)
        sub_lo = lo + index * width
        to_face = np.minimum(to_face, np.minimum(pts[:, axis] - sub_lo, sub_lo + width - pts[:, axis]))
        cell = cell * n + index.astype(int)
    return cell, to_face


def _batch_kinds(plan: RunPlan) -> list[tuple[float, float, float]]:
    """(grains of the kind in one batch, its volume m3, its bounding radius m), dust included."""
    f = plan.fill
    grains = [sp for sp in plan.species if sp.stream == "grains"]
    if f.shrink_classes:            # poured as grains of the largest size, shrunk after settling
        big = max(grains, key=lambda sp: sp.radius)
        return [(float(f.batch), big.volume, big.bounding_radius)]
    return ([(f.batch * sp.number_fraction, sp.volume, sp.bounding_radius) for sp in grains]
            + [(f.dust_batch * sp.number_fraction, sp.volume, sp.bounding_radius)
               for sp in plan.species if sp.stream == "dust"])


def batch_solid_fraction(plan: RunPlan, box: dict, ranks: int) -> float:
    """Solid fraction one grain batch (with its dust) asks for in the part of the insertion region
    its centres can take, on the rank asked most: each rank's share of the batch (LIGGGHTS'
    ``distribute_ninsert_this``), each kind's volume over the volume where its centre may go on
    that rank (at least its bounding radius from the region's surface and the subdomain's faces).
    Cylinders of spheres only (module docstring)."""
    if plan.planar or plan.has_clumps:
        raise ValueError("batch_solid_fraction: slabs and clumps are not estimated")
    pts, to_surface, volume = _region_points(plan, np.random.default_rng(0))
    grid = processor_grid(box, ranks, plan.planar)
    cell, to_face = _subdomains(pts, box, grid)
    reach = np.minimum(to_face, to_surface)
    kinds = [k for k in _batch_kinds(plan) if k[0] > 0]
    r_max = max(r for _, _, r in kinds)
    n_cells = grid[0] * grid[1] * grid[2]
    share = np.bincount(cell[to_surface >= r_max], minlength=n_cells) / SAMPLES
    share[share < MIN_SHARE / n_cells] = 0.0
    share /= share.sum()
    asked = 0.0
    for k in np.flatnonzero(share):
        here = cell == k
        rank = sum(count * share[k] * v / (volume * np.mean(here & (reach >= r)))
                   if np.any(here & (reach >= r)) else math.inf for count, v, r in kinds)
        asked = max(asked, rank)
    return float(asked)


def short_batch_warning(plan: RunPlan, box: dict, ranks: int, fill=None) -> str | None:
    """A warning when a grain batch asks for more than :data:`PLACEABLE_FRACTION` of where it can go
    on ``ranks`` ranks, naming the field that sets the batch (``fill.batch_volume_fraction``, or
    ``fill.pour_time`` for a pour) and a value that fits; None when it fits, and for slabs and
    clumps (not estimated). ``fill``: the case's fill fields, for their values in the text."""
    if plan.planar or plan.has_clumps:
        return None
    asked = batch_solid_fraction(plan, box, ranks)
    if asked <= PLACEABLE_FRACTION:
        return None
    f = plan.fill
    where = (f"on {ranks} ranks (LIGGGHTS keeps every grain a radius from each subdomain border)" if ranks > 1
             else "on one rank")
    batch_fit = max(1, math.floor(f.batch * PLACEABLE_FRACTION / asked))
    if f.protocol == "pour":
        field, value = "fill.pour_time", (f" {fill.pour_time:g} s" if fill is not None else "")
        pour = math.ceil(f.count / batch_fit) * f.insert_every * plan.dt
        advice = f"pour for at least {math.ceil(pour * 100) / 100:g} s"
    else:
        field, value = "fill.batch_volume_fraction", (f" {fill.batch_volume_fraction:g}" if fill is not None else "")
        solid = sum(count * v for count, v, _ in _batch_kinds(plan)) / f.batch      # m3 per grain, dust included
        fits = batch_fit * solid / _region_volume(f.region)
        advice = f"use at most {math.floor(fits * 100) / 100:g}"
    return (f"{field}{value} makes batches of {f.batch} grains that ask for a solid fraction of {asked:.2f} in the "
            f"part of the insertion region a grain's centre can take {where}; LIGGGHTS' random insertion places "
            f"about {PLACEABLE_FRACTION:g} there at most, so batches come in short of their smallest grains (it "
            f"places the largest first): the fill takes longer than planned and the bed holds more large grains "
            f"than asked, both by amounts that depend on engine.ranks, and so do the bed's weight and wall loads: "
            f"{advice}")


def short_batches_note(batches: dict[str, list[int]], short: dict[str, list[int]], planned: dict[str, int]) -> list[str]:
    """The run's warnings for insertion fixes whose batches came in short: ``batches`` what each
    batch of a fix placed, ``short`` what its short ones placed, ``planned`` the planned batch per
    fix (``ins`` grains, ``ins_dust`` dust spheres)."""
    out = []
    for fix, what in (("ins", "grain"), ("ins_dust", "dust")):
        got = short.get(fix) or []
        if not got:
            continue
        placed = f"{min(got)}" if min(got) == max(got) else f"{min(got)}-{max(got)}"
        out.append(f"siloflow: {len(got)} of {len(batches.get(fix, []))} {what} batches came in short (placed "
                   f"{placed}, batches of {planned.get(fix, 0)} planned; LIGGGHTS places the largest first and "
                   "could not place the rest without overlaps): the fill took longer than planned and the bed holds "
                   "more large grains than asked, both by amounts that depend on engine.ranks, and so do its weight "
                   "and wall loads; lower fill.batch_volume_fraction (a pour: lengthen fill.pour_time)")
    return out
