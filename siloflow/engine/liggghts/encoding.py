"""How a run plan is encoded for LIGGGHTS 3.8: what only this engine needs.

- atom types: species k (plan order) is type k + 1, the walls the next type, a slab's front and
  back faces the one after (LIGGGHTS gives every mesh an atom type for its material constants);
- per-type-pair contact matrices (``fix property/global peratomtypepair``);
- multisphere mass weights: LIGGGHTS' per-atom mass of a clump's sphere is the whole clump's;
- the plate shift: multisphere refuses ``delete_atoms``, so clumps cannot be deleted at the
  counting disc; the orifice plate also moves aside, and they fall on out of the box;
- prime seeds (LIGGGHTS requires primes > 10000), derived from the case seed;
- ``fix ave/time`` sampling (Nevery, Nrepeat, Nfreq) of the plan's wall-force averages;
- the simulation box, the neighbour skin and LIGGGHTS' bin limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from ...derived import check_opening
from ...errors import CaseError
from ...plan import FACES, WALL, PairParameters, RunPlan

#: LIGGGHTS counts its neighbour and atom-sorting bins in a C int ("Too many neighbor bins",
#: "Too many atom sorting bins"); half of INT_MAX leaves room for its ghost bins
MAX_ENGINE_BINS = 2 ** 30


#: Miller-Rabin with these bases is exact below 3.4e14 (Jaeschke 1993), beyond any seed prime here
_WITNESSES = (2, 3, 5, 7, 11, 13, 17)


def is_prime(n: int) -> bool:
    """Whether ``n`` is prime: deterministic Miller-Rabin, exact for n < 3.4e14 (prime seeds are
    below 5.1e7); larger ``n`` fall back to trial division."""
    if n < 2:
        return False
    for p in _WITNESSES:
        if n % p == 0:
            return n == p
    if n >= 341_550_071_728_321:
        k = 19
        while k * k <= n:
            if n % k == 0:
                return False
            k += 2
        return True
    d, r = n - 1, 0
    while d % 2 == 0:
        d, r = d // 2, r + 1
    for a in _WITNESSES:
        x = pow(a, d, n)
        if x in (1, n - 1):
            continue
        for _ in range(r - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


@lru_cache(maxsize=65536)
def prime_seed(seed: int, salt: int) -> int:
    """A prime > 10000 (LIGGGHTS requires it) derived deterministically from the case seed."""
    n = 10007 + (seed * 7919 + salt * 104729) % 50_000_000
    while not is_prime(n):
        n += 1
    return n


def engine_bins(box: dict, radius: float, skin: float) -> int:
    """How many neighbour bins LIGGGHTS makes for ``box`` (m) with grains of largest radius
    ``radius`` and neighbour ``skin`` (m): bins of half the cutoff 2 r + skin, as its default."""
    size = 0.5 * (2 * radius + skin)
    return math.prod(math.ceil((box[f"{a}hi"] - box[f"{a}lo"]) / size) for a in "xyz")


def check_bins(box: dict, radius: float, skin: float) -> None:
    """Refuse a silo too many grains wide and tall for the engine's bins (``CaseError``)."""
    bins = engine_bins(box, radius, skin)
    if bins > MAX_ENGINE_BINS:
        size = max(box[f"{a}hi"] - box[f"{a}lo"] for a in "xyz")
        raise CaseError([("particles", f"grains of radius {radius:.3g} m in a silo whose box is {size:.3g} m long need "
                          f"{bins:.3g} neighbour bins, more than LIGGGHTS can count ({MAX_ENGINE_BINS:.3g}): "
                          "use larger grains or a smaller silo (geometry)")])


@dataclass(frozen=True)
class LiggghtsEncoding:
    """The LIGGGHTS encoding of a plan (see the module docstring); lengths m, speeds m/s."""

    types: dict[str, int]                 # species name -> atom type
    wall_type: int
    face_type: int | None
    type_pairs: dict[tuple[int, int], PairParameters]   # (i <= j) -> parameters
    mass_weights: list[float]             # per atom type: share of LIGGGHTS' per-atom mass
    plate_shift: float
    plate_velocity: tuple[float, float, float]
    open_steps: int
    box: dict
    skin: float
    seeds: dict
    sample_every: int
    sample_repeat: int
    sample_freq: int

    @property
    def n_types(self) -> int:
        return self.face_type or self.wall_type


def encode(plan: RunPlan) -> LiggghtsEncoding:
    """The LIGGGHTS encoding of ``plan``. Raises ``CaseError`` when the opening plate, moving
    aside for clumps, is too slow, or the box needs more bins than LIGGGHTS counts."""
    types = {sp.name: k + 1 for k, sp in enumerate(plan.species)}
    wall_type = len(plan.species) + 1
    face_type = wall_type + 1 if plan.planar else None
    side = {WALL: wall_type, FACES: face_type, **types}
    type_pairs = {}
    for p in plan.contacts:
        i, j = sorted((side[p.a], side[p.b]))
        type_pairs[(i, j)] = p
    g, r = plan.geometry, plan.particle_radius
    d = 2 * r
    plate_shift = 2.0 * g.outlet_radius + d if plan.has_clumps else 0.0
    travel = plan.opening.travel
    path = math.hypot(travel, plate_shift)
    check_opening(plan.gravity, plan.opening.speed, plan.outlet.z, down=travel / path)
    open_steps = max(1, math.ceil(path / plan.opening.speed / plan.dt - 1e-9))
    v = plan.opening.speed
    plate_velocity = (v * plate_shift / path, 0.0, -v * travel / path)
    margin = 2 * d
    half_y = g.half_depth
    box = {"xlo": -g.reach - margin,
           "xhi": max(g.reach, g.outlet_offset + plate_shift + g.outlet_radius) + margin,
           "ylo": -half_y - (0.0 if g.periodic_depth else margin), "yhi": half_y + (0.0 if g.periodic_depth else margin),
           "zlo": plan.outlet.z - travel - margin, "zhi": g.top + margin}
    skin = 0.5 * r
    check_bins(box, r, skin)
    seed = plan.seed
    seeds = {"insertion": prime_seed(seed, 1), "distribution": prime_seed(seed, 3),
             "templates": [prime_seed(seed, 10 + k) for k in range(len(plan.species))],
             "dust_insertion": prime_seed(seed, 5), "dust_distribution": prime_seed(seed, 7),
             "shrink": [prime_seed(seed, 40 + k) for k in range(len(plan.fill.radii))]}
    out = plan.outputs
    every = out.sample_steps // out.samples_per_average
    return LiggghtsEncoding(
        types=types, wall_type=wall_type, face_type=face_type, type_pairs=type_pairs,
        mass_weights=[1.0 / sp.n_spheres for sp in plan.species], plate_shift=plate_shift,
        plate_velocity=plate_velocity, open_steps=open_steps, box=box, skin=skin, seeds=seeds,
        sample_every=every, sample_repeat=out.samples_per_average, sample_freq=out.sample_steps)
