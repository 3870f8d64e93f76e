"""Where each sphere of a fill goes, placed in Python: the case's exact particle mix on any rank
count and in every engine.

A fill inserts its grains (and dust) in batches, one every ``insert_every`` steps, at rest in the
insertion region and moving down at the insertion speed. Every grain of a batch has the same
velocity and acceleration, so a batch falls as a block and has left the region (of height h)
after ``1.1 t_clear`` (``siloflow.derived``), before the next batch comes: a batch need only
avoid itself, and, for an engine that can say where its grains are, anything still near the
region (``obstacles``).

The list of what to insert is the case's count of each size class (and the dust, in its ratio),
shuffled once (:func:`fill_order`); each batch takes the next ``batch + dust_batch`` of it and
places them by random sequential addition in that order. What does not fit in a batch's region
goes in with the next batch, so no size class is favoured: LIGGGHTS' own insertion places the
largest first and drops what it cannot place, and so filled beds heavier than asked by 9 % on
1 rank and 17.5 % on 2 (issue 36; ``benchmarks/results/rank_fill``).

Spheres only: a clump needs its engine's rigid-body registration (LIGGGHTS' multisphere
insertion, LAMMPS' ``fix pour``), and one clump shape has no size mix to bias.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np
from scipy.spatial import cKDTree

from .errors import CaseError
from .plan import RunPlan

#: random centres tried for one sphere before its batch's region counts as full
TRIES = 200
#: a fill may take this many times its planned batches when they come in short (the region fills
#: up before a batch is whole); beyond, the case asks for batches that do not fit
FILL_OVERTIME = 3
#: the stream of the case's seed the placement draws from (the LAMMPS driver's own stream)
FILL_STREAM = 17


def fill_rng(plan: RunPlan) -> np.random.Generator:
    """The placement's random generator: the case's seed, its own stream."""
    return np.random.default_rng([plan.seed, FILL_STREAM])


def class_counts(plan: RunPlan) -> dict[int, int]:
    """Species index -> spheres the fill inserts: each size class's number fraction of the count
    (rounded down, the remainder to the largest share), the dust's count; with paper B's
    shrinking, every grain at the poured (largest) size."""
    f = plan.fill
    grains = [k for k, sp in enumerate(plan.species) if sp.stream == "grains"]
    if f.shrink_classes:
        big = max(grains, key=lambda k: plan.species[k].radius)
        counts = {big: f.count}
    else:
        share = np.floor(np.array([plan.species[k].number_fraction for k in grains]) * f.count).astype(int)
        share[np.argmax(share)] += f.count - share.sum()
        counts = {k: int(c) for k, c in zip(grains, share)}
    dust = [k for k, sp in enumerate(plan.species) if sp.stream == "dust"]
    if dust and f.dust_count:
        counts[dust[0]] = f.dust_count
    return counts


def fill_order(plan: RunPlan, rng: np.random.Generator) -> list[int]:
    """The species index of every sphere to insert (:func:`class_counts`), shuffled."""
    order = [k for k, c in class_counts(plan).items() for _ in range(c)]
    rng.shuffle(order)
    return [int(k) for k in order]


def _random_centres(plan: RunPlan, r: np.ndarray, dust: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Uniform random centres (n, 3) for spheres of radii ``r`` wholly inside the insertion region
    (a slab's block holds the centres; its dust keeps to the mid-plane); NaN rows where none fits."""
    reg = plan.fill.region
    n = len(r)
    if reg.shape == "cylinder":
        z0, z1, rho_max = reg.z_min + r, reg.z_max - r, reg.radius - r
        rho, phi = rho_max * np.sqrt(rng.uniform(size=n)), rng.uniform(0.0, 2 * math.pi, n)
        out = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z0 + (z1 - z0) * rng.uniform(size=n)])
        out[(z1 < z0) | (rho_max <= 0)] = np.nan
        return out
    y = rng.uniform(reg.ylo, reg.yhi, n)
    if plan.planar:
        y = np.where(dust, rng.uniform(-1e-3, 1e-3, n) * r, y)
    return np.column_stack([rng.uniform(reg.xlo, reg.xhi, n), y, rng.uniform(reg.z_min, reg.z_max, n)])


def _overlapping(x: np.ndarray, r: np.ndarray, y: np.ndarray, s: np.ndarray,
                 period_y: tuple[float, float] | None = None) -> np.ndarray:
    """(i, j) pairs, (m, 2), of spheres ``x``/``r`` overlapping spheres ``y``/``s`` (k-d trees);
    ``period_y`` (lo, hi), m: the box is periodic along y between them (a periodic slab)."""
    if not len(x) or not len(y):
        return np.empty((0, 2), int)
    cutoff = float(r.max() + s.max())
    if period_y is not None:
        # k-d trees with a box: every coordinate in [0, size); x and z get a box too wide to wrap
        lo_y, length = period_y[0], period_y[1] - period_y[0]
        both = np.vstack([x, y])
        lo = both.min(axis=0)
        size = both.max(axis=0) - lo + 4 * cutoff + 1.0
        size[1] = length

        def shifted(p):
            q = p - lo
            q[:, 1] = np.mod(p[:, 1] - lo_y, length)
            return q
        d = cKDTree(shifted(x), boxsize=size).sparse_distance_matrix(cKDTree(shifted(y), boxsize=size), cutoff,
                                                                      output_type="ndarray")
    else:
        d = cKDTree(x).sparse_distance_matrix(cKDTree(y), cutoff, output_type="ndarray")
    hit = d["v"] < r[d["i"]] + s[d["j"]]
    return np.column_stack([d["i"][hit], d["j"][hit]])


def place(plan: RunPlan, kinds: list[int], rng: np.random.Generator, obstacles=None,
          tries: int = TRIES, chunk: int = 8000) -> np.ndarray:
    """Centres (n, 3), m, for the first n of ``kinds`` (species indices) placed by random
    sequential addition in the insertion region, in order, touching neither each other nor
    ``obstacles`` (``(x (m, 3), r (m,))`` or None); n stops at the first sphere that found no room
    beside the ones before it in ``tries`` draws.

    Vectorised in rounds: candidates are drawn for up to ``chunk`` unplaced spheres at once; one
    touching an obstacle or an earlier sphere (placed, or a candidate of the round) is rejected and
    draws again next round; a later sphere it touches gives way (it draws again, as it would have
    in one-at-a-time addition, where the earlier sphere came first)."""
    radii = np.array([plan.species[k].radius for k in kinds], float)
    dust = np.array([plan.species[k].stream == "dust" for k in kinds], bool)
    n = len(kinds)
    g = plan.geometry
    period = (-0.5 * g.thickness, 0.5 * g.thickness) if g.periodic_depth else None
    fixed_x = np.asarray(obstacles[0], float).reshape(-1, 3) if obstacles is not None else np.empty((0, 3))
    fixed_r = np.asarray(obstacles[1], float).reshape(-1) if obstacles is not None else np.empty(0)
    centres = np.full((n, 3), np.nan)
    failed = np.zeros(n, int)
    placed = np.zeros(n, bool)
    stop = n                                        # the first sphere that found no room
    while True:
        todo = np.flatnonzero(~placed[:stop])[:chunk]
        if len(todo) == 0:
            return centres[:stop]
        cand = _random_centres(plan, radii[todo], dust[todo], rng)
        ok = ~np.isnan(cand[:, 0])
        # against the obstacles (index -1) and the placed spheres
        others = np.concatenate([np.full(len(fixed_r), -1), np.flatnonzero(placed)])
        good = np.flatnonzero(ok)
        hits = _overlapping(cand[good], radii[todo][good], np.vstack([fixed_x, centres[placed]]),
                            np.concatenate([fixed_r, radii[placed]]), period)
        mine, theirs = todo[good][hits[:, 0]], others[hits[:, 1]]
        ok[good[hits[:, 0]][theirs < mine]] = False
        # against each other: the earlier candidate wins
        good = np.flatnonzero(ok)
        pairs = _overlapping(cand[good], radii[todo][good], cand[good], radii[todo][good], period)
        later: dict[int, list[int]] = {}
        for i, j in pairs[pairs[:, 0] < pairs[:, 1]]:
            later.setdefault(int(good[j]), []).append(int(good[i]))
        for j in sorted(later):
            if any(ok[i] for i in later[j]):
                ok[j] = False
        # later spheres touched by an accepted one give way
        kept = set(todo[ok].tolist())
        evicted = [int(b) for a, b in zip(mine, theirs) if a in kept and b > a]
        placed[evicted] = False
        centres[todo[ok]] = cand[ok]
        placed[todo[ok]] = True
        failed[todo[~ok]] += 1
        full = todo[~ok & (failed[todo] >= tries)]
        if len(full):
            stop = min(stop, int(full.min()))
            placed[stop:] = False                   # what came after it waits for the next batch


@dataclass(frozen=True)
class Batch:
    """One batch of a fill: inserted at ``step`` (from the fill's start), species indices
    ``kinds`` at ``centres`` (n, 3), m, all moving down at the insertion speed."""

    step: int
    kinds: tuple[int, ...]
    centres: np.ndarray


def planned_batches(plan: RunPlan) -> int:
    """Batches the plan's fill steps hold (``siloflow.derived``: one per ``insert_every``)."""
    return math.ceil(plan.fill.count / plan.fill.batch)


def fill_steps(plan: RunPlan, batches: int) -> int:
    """Steps of a fill that took ``batches`` batches: the plan's, longer by ``insert_every`` for
    each batch beyond the planned ones."""
    return plan.fill.steps + max(0, batches - planned_batches(plan)) * plan.fill.insert_every


def fill_batches(plan: RunPlan) -> list[Batch]:
    """Every batch of the plan's fill, placed (:func:`place`; leftovers go with the next batch, so
    a batch that came in short makes the fill longer: :func:`fill_steps`). Raises ``CaseError``
    naming ``fill.batch_volume_fraction`` when they need more than :data:`FILL_OVERTIME` times the
    planned batches. Clumps are not placed here (module docstring)."""
    key = (plan.seed, plan.planar, plan.fill.model_dump_json(),
           tuple(sp.model_dump_json() for sp in plan.species))
    if key not in _MEMO:
        _MEMO.clear()                       # one plan at a time: validating and writing its deck
        _MEMO[key] = _place_fill(plan)
    return list(_MEMO[key])


_MEMO: dict[tuple, tuple[Batch, ...]] = {}


def _place_fill(plan: RunPlan) -> tuple[Batch, ...]:
    if plan.has_clumps:
        raise ValueError("fill_batches: clumps are inserted by their engine")
    f = plan.fill
    rng = fill_rng(plan)
    todo = fill_order(plan, rng)
    allowed = FILL_OVERTIME * planned_batches(plan)
    out: list[Batch] = []
    while todo:
        centres = place(plan, todo[:f.batch + f.dust_batch], rng)
        n = len(centres)
        if n == 0 or len(out) == allowed:
            placed = sum(len(b.kinds) for b in out) + n
            raise CaseError([("fill.batch_volume_fraction",
                              f"{allowed} batches ({FILL_OVERTIME} times the fill's) of {f.batch + f.dust_batch} spheres placed only {placed} of "
                              f"{placed + len(todo) - n} in the insertion region (random sequential addition, {TRIES} tries "
                              "a sphere): lower fill.batch_volume_fraction, or make the silo taller above the bed")])
        out.append(Batch(step=len(out) * f.insert_every, kinds=tuple(todo[:n]), centres=centres))
        todo = todo[n:]
    return tuple(out)
