"""Everything the deck needs that is computed from the case: masses, contact parameters,
time step, stage lengths, insertion batches, output intervals, seeds, box.

``derive(case)`` returns a ``Derived`` record; it is unit-tested and written to
``derived.json`` beside the deck. All values SI.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

from . import contact_physics as cp
from .case import Case, CylinderGeometry, HopperGeometry
from .errors import CaseError

#: speed at which grains are inserted downwards, m/s (keeps batches clear of the region)
INSERTION_SPEED = 1.5


@dataclass
class PairParameters:
    """Contact parameters and contact time of one material pair (``particle_particle`` or ``particle_wall``)."""

    name: str
    m_eff: float          # kg
    r_eff: float          # m
    friction: float
    restitution: float
    rolling_friction: float
    contact_time: float   # s
    y_eff: float | None = None    # Pa (hertz)
    kn: float | None = None       # N/m (linear)
    kt: float | None = None       # N/m (linear)
    gamman: float | None = None   # 1/s (linear, LIGGGHTS hooke/stiffness)
    gammat: float | None = None   # 1/s


@dataclass
class Derived:
    """Derived parameters of a case (SI units)."""

    particle_radius: float     # the largest radius, m
    particle_volume: float     # mean volume per grain (after shrinking, if any), m3
    particle_mass: float       # mean mass per grain (after shrinking, if any), kg
    particle_count: int
    total_mass: float
    bed_height_estimate: float
    impact_velocity: float
    pairs: dict[str, PairParameters]
    rayleigh_time: float | None
    critical_time: float
    critical_time_source: str
    timestep: float
    # insertion
    insertion_region: dict
    insertion_batch: int
    insert_every: int
    insertion_speed: float
    # stages, in steps
    fill_steps: int
    settle_chunk_steps: int
    settle_max_chunks: int
    static_steps: int
    open_steps: int
    discharge_chunk_steps: int
    discharge_max_chunks: int
    # outputs, in steps
    thermo_every: int
    sample_every: int
    sample_repeat: int
    sample_freq: int
    dump_every: int | None
    # geometry of the run
    outlet_z: float
    outlet_disc_radius: float
    plate_travel: float
    box: dict
    skin: float
    seeds: dict = field(default_factory=dict)
    radii: list = field(default_factory=list)             # m
    number_fractions: list = field(default_factory=list)
    mass_fractions: list = field(default_factory=list)    # what LIGGGHTS' distribution takes
    shrink_classes: list = field(default_factory=list)    # [(radius, conditional fraction)], paper B
    type_pairs: dict = field(default_factory=dict)        # (type i, type j) -> PairParameters

    @property
    def wall_type(self) -> int:
        """Atom type of the walls: after the size classes (types 1..K)."""
        return len(self.radii) + 1

    @property
    def planned_steps(self) -> dict[str, int]:
        """Upper bound of the steps each stage can take."""
        out = {"fill": self.fill_steps,
               "settle": self.settle_chunk_steps * self.settle_max_chunks}
        if self.shrink_classes:
            out["shrink"] = self.settle_chunk_steps * self.settle_max_chunks
        return {**out,
                "static": self.static_steps,
                "open": self.open_steps,
                "discharge": self.discharge_chunk_steps * self.discharge_max_chunks}

    def to_json(self) -> dict:
        out = asdict(self)
        out["type_pairs"] = {f"{i}-{j}": asdict(v) for (i, j), v in self.type_pairs.items()}
        out["planned_steps"] = self.planned_steps
        return out


def is_prime(n: int) -> bool:
    if n < 2:
        return False
    if n % 2 == 0:
        return n == 2
    k = 3
    while k * k <= n:
        if n % k == 0:
            return False
        k += 2
    return True


def prime_seed(seed: int, salt: int) -> int:
    """A prime > 10000 (LIGGGHTS requires it) derived deterministically from the case seed."""
    n = 10007 + (seed * 7919 + salt * 104729) % 50_000_000
    while not is_prime(n):
        n += 1
    return n


def bed_volume(case: Case, height: float) -> float:
    """Volume of the silo below ``height`` (m above the outlet), m3."""
    g = case.geometry
    R = g.radius
    if isinstance(g, HopperGeometry):
        hh = g.hopper_height
        t = math.tan(math.radians(g.half_angle_deg))
        h_cone = min(height, hh)
        r_top = g.outlet_radius + h_cone * t
        cone = math.pi * h_cone / 3 * (g.outlet_radius ** 2 + g.outlet_radius * r_top + r_top ** 2)
        return cone + math.pi * R ** 2 * max(0.0, height - hh)
    return math.pi * R ** 2 * height


def bed_height(case: Case, volume: float) -> float:
    """Inverse of :func:`bed_volume` (bisection), m."""
    lo, hi = 0.0, case.geometry.hopper_height + case.geometry.height
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if bed_volume(case, mid) < volume:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _steps(duration: float, dt: float) -> int:
    return max(1, math.ceil(duration / dt - 1e-9))


def _pair(case: Case, name: str, m_eff: float, r_eff: float, wall: bool, v_impact: float) -> PairParameters:
    """Contact parameters of one pair of grains (or grain and wall) with reduced mass and radius."""
    m = case.materials
    pc = m.particle_wall if wall else m.particle_particle
    other = m.wall if wall else m.particle
    common = dict(name=name, m_eff=m_eff, r_eff=r_eff, friction=pc.friction,
                  restitution=pc.restitution, rolling_friction=pc.rolling_friction)
    if m.model in ("hertz", "hooke"):
        y_eff = cp.effective_modulus(m.particle.youngs_modulus, m.particle.poisson_ratio,
                                     other.youngs_modulus, other.poisson_ratio)
    if m.model == "hertz":
        return PairParameters(**common, y_eff=y_eff,
                              contact_time=cp.hertz_contact_time(m_eff, r_eff, y_eff, v_impact))
    if m.model == "hooke":
        kn = cp.hooke_kn(m_eff, r_eff, y_eff, m.characteristic_velocity)
        kt = m.tangential_stiffness_ratio * kn
    else:
        kn, kt = pc.kn, pc.kt
    gamman = cp.linear_gamma(kn, m_eff, pc.restitution)
    return PairParameters(**common, y_eff=y_eff if m.model == "hooke" else None, kn=kn, kt=kt, gamman=gamman,
                          gammat=m.tangential_damping_ratio * gamman, contact_time=cp.linear_contact_time(kn, m_eff))


def type_pair_parameters(case: Case, radii: list[float], v_impact: float) -> dict[tuple[int, int], PairParameters]:
    """Contact parameters of every pair of atom types: size class k is type k + 1 (in the order
    of the case's radii), the walls the last type. A wall acts as infinite mass and radius."""
    rho = case.materials.particle.density
    wall = len(radii) + 1
    out = {}
    for i, ri in enumerate(radii, start=1):
        mi = cp.sphere_mass(ri, rho)
        for j, rj in enumerate(radii, start=1):
            if j >= i:
                mj = cp.sphere_mass(rj, rho)
                out[(i, j)] = _pair(case, f"particle_particle {i}-{j}", cp.reduced(mi, mj), cp.reduced(ri, rj),
                                    False, v_impact)
        out[(i, wall)] = _pair(case, f"particle_wall {i}", mi, ri, True, v_impact)
    return out


def shrink_classes(radii, number_fractions) -> list[tuple[float, float]]:
    """Paper B's random shrinking as a sequence of (radius, conditional fraction): each class in
    turn takes that fraction of the grains not yet assigned, so the classes end with the given
    number fractions; the largest radius (the poured grains) keeps the rest."""
    order = sorted(range(len(radii)), key=lambda k: radii[k])
    largest = order[-1]
    remaining = 1.0
    out = []
    for k in order[:-1]:
        out.append((radii[k], min(1.0, number_fractions[k] / remaining)))
        remaining -= number_fractions[k]
    assert radii[largest] == max(radii)
    return out


def derive(case: Case) -> Derived:
    """Compute the derived parameters of a cylinder or hopper case.

    Raises
    ------
    CaseError
        when the case is valid on its own but cannot be run as stated (bed too high
        for the insertion region, opening too slow, ...), naming the field.
    """
    g = case.geometry
    if not isinstance(g, (CylinderGeometry, HopperGeometry)):
        raise CaseError([("geometry.kind", f"'{g.kind}' has a schema but no deck yet: the planar "
                          "silo deck is part of the particle-systems issue")])
    p = case.particles
    r = p.max_radius                       # geometry margins use the largest grain
    r_min = p.min_radius                   # the time step, the smallest (shortest contacts)
    d = 2 * r
    rho = case.materials.particle.density
    numbers = p.number_fractions
    vol = sum(n * cp.sphere_volume(ri) for n, ri in zip(numbers, p.radii))     # mean volume per grain
    mass = rho * vol
    mass_fractions = [n * ri ** 3 for n, ri in zip(numbers, p.radii)]
    mass_fractions = [w / sum(mass_fractions) for w in mass_fractions]
    final_mass = mass                      # mean grain mass once the bed has its size distribution
    shrink = getattr(p, "protocol", "insert") == "shrink_after_settling"
    if shrink:        # the bed is poured as grains of the largest radius
        vol = cp.sphere_volume(r)
        mass = rho * vol
    f = case.fill
    top = g.hopper_height + g.height
    if f.count is not None:
        count = f.count
    else:
        count = int(f.packing_fraction * bed_volume(case, f.height) / vol)
        if count < 1:
            raise CaseError([("fill.height", "too low to hold a single particle")])
    h_bed = bed_height(case, count * vol / f.packing_fraction)

    # insertion region: above the expected bed, below the top
    z_max = f.insertion_z_max if f.insertion_z_max is not None else top - 0.5 * d
    z_min = f.insertion_z_min if f.insertion_z_min is not None else max(
        h_bed + 2 * d, z_max - max(0.3 * g.height, 4 * d), g.hopper_height + d)
    if z_max - z_min < 2 * d:
        raise CaseError([("fill", f"the expected bed ({h_bed:.4g} m at solid fraction "
                          f"{f.packing_fraction}) leaves no room to insert particles below the top "
                          f"({top:.4g} m): fill fewer particles or make the silo taller")])
    region_radius = g.radius - 0.6 * r
    region_volume = math.pi * region_radius ** 2 * (z_max - z_min)
    batch = max(1, min(count, int(f.batch_volume_fraction * region_volume / vol)))

    # time step
    v_impact = cp.free_fall_speed(z_max, case.gravity, INSERTION_SPEED)
    type_pairs = type_pair_parameters(case, list(p.radii), v_impact)
    smallest = p.radii.index(r_min) + 1          # its contacts are the shortest
    pairs = {"particle_particle": replace(type_pairs[(smallest, smallest)], name="particle_particle"),
             "particle_wall": replace(type_pairs[(smallest, len(p.radii) + 1)], name="particle_wall")}
    candidates = {f"contact time {pp.name}": pp.contact_time for pp in [*pairs.values(), *type_pairs.values()]}
    rayleigh = None
    if case.materials.model == "hertz":
        pm = case.materials.particle
        rayleigh = cp.rayleigh_time(r_min, rho, pm.youngs_modulus, pm.poisson_ratio)
        candidates["Rayleigh time of the particles"] = rayleigh
    source = min(candidates, key=candidates.get)
    t_crit = candidates[source]
    dt = case.engine.timestep_fraction * t_crit

    # fill: batches leave the region before the next one comes
    h_region = z_max - z_min
    t_clear = (-INSERTION_SPEED + math.sqrt(INSERTION_SPEED ** 2 + 2 * case.gravity * h_region)) / case.gravity
    insert_every = _steps(1.1 * t_clear, dt)
    n_batches = math.ceil(count / batch)
    t_fall = (-INSERTION_SPEED + math.sqrt(INSERTION_SPEED ** 2 + 2 * case.gravity * z_max)) / case.gravity
    fill_steps = n_batches * insert_every + _steps(1.5 * t_fall, dt)

    s = f.settle
    settle_chunk = _steps(s.check_interval, dt)
    settle_chunks = max(1, math.ceil(s.max_time / s.check_interval))

    # opening: the plate must outrun the grains to below the counting disc
    outlet_z = -2.0 * d
    v_open = case.discharge.opening.speed
    v_needed = math.sqrt(case.gravity * abs(outlet_z) / 2.0)
    if v_open <= 1.5 * v_needed:
        raise CaseError([("discharge.opening.speed", f"{v_open} m/s is too slow: the plate must move "
                          f"faster than {1.5 * v_needed:.3g} m/s to leave the grains behind")])
    plate_travel = 3.0 * abs(outlet_z)
    open_steps = _steps(plate_travel / v_open, dt)

    dis = case.discharge
    if dis.until_empty:
        chunk_time = min(0.1, dis.max_time)
        d_chunk, d_chunks = _steps(chunk_time, dt), max(1, math.ceil(dis.max_time / chunk_time))
    else:
        d_chunk, d_chunks = _steps(dis.duration, dt), 1

    out = case.outputs
    sample_freq = _steps(out.sample_interval, dt)
    sample_every = max(1, sample_freq // 5)  # 5 samples per average: wall-force sampling is not free
    sample_repeat = sample_freq // sample_every
    sample_freq = sample_every * sample_repeat
    thermo_every = settle_chunk  # settle checks read thermo values, so they must coincide
    dump_every = _steps(out.dump_interval, dt) if out.dump_interval else None

    margin = 2 * d
    box = {"xlo": -g.radius - margin, "xhi": g.radius + margin,
           "ylo": -g.radius - margin, "yhi": g.radius + margin,
           "zlo": outlet_z - plate_travel - margin, "zhi": top + margin}
    return Derived(
        particle_radius=r, particle_volume=final_mass / rho, particle_mass=final_mass, particle_count=count,
        total_mass=count * final_mass, bed_height_estimate=h_bed, impact_velocity=v_impact,
        pairs=pairs, rayleigh_time=rayleigh, critical_time=t_crit, critical_time_source=source,
        timestep=dt,
        insertion_region={"radius": region_radius, "z_min": z_min, "z_max": z_max},
        insertion_batch=batch, insert_every=insert_every, insertion_speed=INSERTION_SPEED,
        fill_steps=fill_steps, settle_chunk_steps=settle_chunk, settle_max_chunks=settle_chunks,
        static_steps=_steps(s.static_window, dt), open_steps=open_steps,
        discharge_chunk_steps=d_chunk, discharge_max_chunks=d_chunks,
        thermo_every=thermo_every, sample_every=sample_every, sample_repeat=sample_repeat,
        sample_freq=sample_freq, dump_every=dump_every,
        outlet_z=outlet_z, outlet_disc_radius=g.outlet_radius + 2 * d, plate_travel=plate_travel,
        box=box, skin=0.5 * r,
        seeds={"insertion": prime_seed(case.seed, 1), "distribution": prime_seed(case.seed, 3),
               "templates": [prime_seed(case.seed, 10 + k) for k in range(len(p.radii))],
               "shrink": [prime_seed(case.seed, 40 + k) for k in range(len(p.radii))]},
        radii=list(p.radii), number_fractions=list(numbers), mass_fractions=mass_fractions,
        shrink_classes=shrink_classes(p.radii, numbers) if shrink else [],
        type_pairs=type_pairs,
    )
