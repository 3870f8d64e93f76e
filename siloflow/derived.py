"""Everything the deck needs that is computed from the case: masses, contact parameters,
time step, stage lengths, insertion batches, output intervals, seeds, box.

``derive(case)`` returns a ``Derived`` record; it is unit-tested and written to
``derived.json`` beside the deck. All values SI.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

from . import contact_physics as cp
from .case import Case, HopperGeometry, PlanarGeometry
from .errors import CaseError, SetupError

#: speed at which grains are inserted downwards, m/s (keeps batches clear of the region)
INSERTION_SPEED = 1.5

#: planned steps above which a run needs an explicit override (``--allow-long``): LIGGGHTS takes
#: about 1 us per particle and step, so 1e9 steps are days even for a bed of a few hundred grains
#: (the shipped cases plan 6e4-6e8 steps; paper_a_clumps, 40 s of discharge with dust, is the top)
MAX_RUN_STEPS = 1_000_000_000
#: mean Hertz overlap under the bed's weight, relative to the radius, above which a warning is
#: given: the usual DEM guidance keeps it below ~1 %, where the stiffness no longer moves the bulk
#: density (the bed's volume shrinks by about 1.5 overlap / radius)
OVERLAP_WARNING = 0.01
#: time-step fraction above which a warning is given: velocity Verlet is unstable for a linear
#: contact above 2/omega = 0.64 contact times, and a Hertz contact stiffens during the impact
TIMESTEP_FRACTION_WARNING = 0.3
#: contacts per grain in a static packing, for the mean contact force under a pressure: 6 is the
#: upper end (frictional packings have 4-5, so forces up to 1.5 times larger, and force chains carry
#: 2-3 times the mean): the overlap estimate is a typical value, not the largest
STATIC_COORDINATION = 6.0
#: air at 20 C: density kg/m3, dynamic viscosity Pa s (drag estimate; siloflow models no gas)
AIR_DENSITY, AIR_VISCOSITY = 1.2, 1.8e-5
#: air drag at the outlet speed above this fraction of a grain's weight gives a warning
#: (Newton drag goes as (v / v_terminal)^2: 10 % at v_terminal = 3.2 v)
DRAG_WARNING = 0.1


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
class Species:
    """One atom type of grains (SI): size classes, a clump shape, or dust.

    ``stream`` is ``grains`` (the case's particles) or ``dust`` (inserted beside them at
    a number ratio); ``number_fraction`` is within the stream. A clump's ``volume`` is the
    union volume of its spheres and ``radius`` its largest sphere (contacts)."""

    name: str
    type: int
    kind: str                 # "sphere" or "clump"
    stream: str               # "grains" or "dust"
    radius: float             # m
    bounding_radius: float    # m
    volume: float             # m3
    density: float            # kg/m3, as simulated
    number_fraction: float
    material: str             # "particle" or "dust": which contact parameters apply
    spheres: list = field(default_factory=list)   # clumps: [x, y, z, r] per sphere, m

    @property
    def mass(self) -> float:
        return self.density * self.volume

    @property
    def n_spheres(self) -> int:
        return max(1, len(self.spheres))


def species_of(case: Case) -> list[Species]:
    """The atom types of a case's grains: size class k is type k + 1 (in the order of the case's
    radii), a clump shape type 1, dust the type after the grains; the walls come last."""
    p = case.particles
    rho = case.materials.particle.density
    out = []
    if p.kind == "clumps":
        clump = p.clump
        out.append(Species(name="clump", type=1, kind="clump", stream="grains", radius=max(clump.radii),
                           bounding_radius=clump.bounding_radius, volume=clump.volume, density=rho,
                           number_fraction=1.0, material="particle",
                           spheres=[[*c, r] for c, r in zip(clump.centers, clump.radii)]))
    else:
        many = len(p.radii) > 1
        for k, (r, n) in enumerate(zip(p.radii, p.number_fractions)):
            out.append(Species(name=f"size{k + 1}" if many else "grain", type=k + 1, kind="sphere",
                               stream="grains", radius=r, bounding_radius=r, volume=cp.sphere_volume(r),
                               density=rho, number_fraction=n, material="particle"))
    dust = getattr(p, "dust", None)
    if dust is not None:
        out.append(Species(name="dust", type=len(out) + 1, kind="sphere", stream="dust", radius=dust.radius,
                           bounding_radius=dust.radius, volume=cp.sphere_volume(dust.radius),
                           density=dust.run_density, number_fraction=1.0, material="dust"))
    return out


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
    plate_shift: float = 0.0                              # m, sideways travel of the opening plate
    opening_speed: float = 1.0                            # m/s along the plate's path
    species: list = field(default_factory=list)           # [Species], one per atom type
    has_faces: bool = False                               # slab silo: front/back faces, their own type
    dust_count: int = 0
    dust_batch: int = 0
    timestep_without_dust: float | None = None            # s; the dust's cost is this / timestep
    run_length_fields: dict = field(default_factory=dict)  # stage (and "timestep") -> case fields setting it
    warnings: list = field(default_factory=list)          # physics warnings (str), each naming its consequence

    @property
    def wall_type(self) -> int:
        """Atom type of the walls: after the grain types (size classes, clump, dust)."""
        return len(self.species) + 1

    @property
    def grains(self) -> list[Species]:
        """The species of the case's particles (size classes or the clump shape)."""
        return [sp for sp in self.species if sp.stream == "grains"]

    @property
    def dust(self) -> Species | None:
        """The dust species, if any."""
        return next((sp for sp in self.species if sp.stream == "dust"), None)

    @property
    def expected_atoms(self) -> int:
        """Atoms (spheres) the fill inserts: every sphere of every clump, and the dust."""
        per_grain = sum(sp.number_fraction * sp.n_spheres for sp in self.grains)
        return round(self.particle_count * per_grain) + self.dust_count

    @property
    def face_type(self) -> int | None:
        """Atom type of a slab silo's front and back faces (after the walls), or None."""
        return self.wall_type + 1 if self.has_faces else None

    @property
    def n_types(self) -> int:
        return self.wall_type + (1 if self.has_faces else 0)

    @property
    def plate_velocity(self) -> tuple[float, float, float]:
        """Velocity of the orifice plate while the orifice opens, m/s."""
        path = math.hypot(self.plate_travel, self.plate_shift)
        return (self.opening_speed * self.plate_shift / path, 0.0, -self.opening_speed * self.plate_travel / path)

    @property
    def has_clumps(self) -> bool:
        return any(s.kind == "clump" for s in self.species)

    @property
    def mass_weights(self) -> list[float]:
        """Per atom type, the factor that turns LIGGGHTS' per-atom mass into a share of the grain's
        mass: multisphere gives every sphere of a clump the whole clump's mass."""
        return [1.0 / s.n_spheres for s in self.species]

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

    @property
    def total_planned_steps(self) -> int:
        """Upper bound of the steps of the whole run (every stage at its cap)."""
        return sum(self.planned_steps.values())

    def to_json(self) -> dict:
        out = asdict(self)
        out["type_pairs"] = {f"{i}-{j}": asdict(v) for (i, j), v in self.type_pairs.items()}
        out["species"] = [{**asdict(sp), "mass": sp.mass} for sp in self.species]
        out["wall_type"] = self.wall_type
        out["face_type"] = self.face_type
        out["expected_atoms"] = self.expected_atoms
        out["mass_weights"] = self.mass_weights
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
    if isinstance(g, PlanarGeometry):       # trapezoid of the wedge hopper, then the full width
        h_w = min(height, g.hopper_height)
        w_top = g.outlet_width + 2.0 * h_w * math.tan(math.radians(g.half_angle_deg))
        area = 0.5 * (g.outlet_width + w_top) * h_w + g.width * max(0.0, height - g.hopper_height)
        return area * g.thickness
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


def _pair(case: Case, name: str, m_eff: float, r_eff: float, contact, moduli, v_impact: float) -> PairParameters:
    """Contact parameters of one pair with reduced mass and radius; ``contact`` is the case's
    PairContact of the pair, ``moduli`` the (Young's modulus, Poisson ratio) of both sides."""
    m = case.materials
    common = dict(name=name, m_eff=m_eff, r_eff=r_eff, friction=contact.friction,
                  restitution=contact.restitution, rolling_friction=contact.rolling_friction)
    y_eff = None
    if m.model in ("hertz", "hooke"):
        (e1, nu1), (e2, nu2) = moduli
        y_eff = cp.effective_modulus(e1, nu1, e2, nu2)
    if m.model == "hertz":
        return PairParameters(**common, y_eff=y_eff,
                              contact_time=cp.hertz_contact_time(m_eff, r_eff, y_eff, v_impact))
    if m.model == "hooke":
        kn = cp.hooke_kn(m_eff, r_eff, y_eff, m.characteristic_velocity)
        kt = m.tangential_stiffness_ratio * kn
    else:
        kn, kt = contact.kn, contact.kt
    gamman = cp.linear_gamma(kn, m_eff, contact.restitution)
    return PairParameters(**common, y_eff=y_eff, kn=kn, kt=kt, gamman=gamman,
                          gammat=m.tangential_damping_ratio * gamman, contact_time=cp.linear_contact_time(kn, m_eff))


def _contact_of(case: Case, a: str, b: str | None):
    """The case's PairContact between materials ``a`` and ``b`` (None: a wall)."""
    m, dust = case.materials, getattr(case.particles, "dust", None)
    if b is None:
        return m.particle_wall if a == "particle" else dust.dust_wall
    if a == b == "particle":
        return m.particle_particle
    return dust.dust_dust if a == b == "dust" else dust.dust_particle


def _modulus_of(case: Case, material: str | None) -> tuple:
    """(Young's modulus, Poisson ratio) of a material (None: the walls)."""
    m = case.materials
    if material is None:
        return m.wall.youngs_modulus, m.wall.poisson_ratio
    if material == "dust":
        dust = case.particles.dust
        return dust.youngs_modulus, dust.poisson_ratio
    return m.particle.youngs_modulus, m.particle.poisson_ratio


def type_pair_parameters(case: Case, species: list[Species], v_impact: float) -> dict[tuple[int, int], PairParameters]:
    """Contact parameters of every pair of atom types (see :func:`species_of`); the walls are the
    last type and act as infinite mass and radius. Radii are those of the touching spheres;
    masses those of the whole grains (a clump moves as one body)."""
    wall = len(species) + 1
    out = {}
    for a in species:
        for b in species:
            if b.type >= a.type:
                out[(a.type, b.type)] = _pair(
                    case, f"{a.name}-{b.name}", cp.reduced(a.mass, b.mass), cp.reduced(a.radius, b.radius),
                    _contact_of(case, a.material, b.material),
                    (_modulus_of(case, a.material), _modulus_of(case, b.material)), v_impact)
        out[(a.type, wall)] = _pair(case, f"{a.name}-wall", a.mass, a.radius, _contact_of(case, a.material, None),
                                    (_modulus_of(case, a.material), _modulus_of(case, None)), v_impact)
    return out


def critical_time(case: Case, species: list[Species], type_pairs: dict) -> tuple[float, str]:
    """The shortest contact time of any type pair (and, for Hertz, Rayleigh time of any
    species), s, with what set it."""
    candidates = {f"contact time {pp.name}": pp.contact_time for pp in type_pairs.values()}
    if case.materials.model == "hertz":
        for sp in species:
            e, nu = _modulus_of(case, sp.material)
            candidates[f"Rayleigh time of {sp.name}"] = cp.rayleigh_time(sp.radius, sp.density, e, nu)
    source = min(candidates, key=candidates.get)
    return candidates[source], source


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


def _radius_field(case: Case) -> str:
    """The case field of the grains' size."""
    p = case.particles
    if p.kind == "clumps":
        return "particles.width" if p.shape == "wheat" else "particles.spheres"
    return "particles.radius" if p.kind == "spheres" else "particles.radii"


def run_length_fields(case: Case, critical_source: str) -> dict[str, list[str]]:
    """The case fields that set the time step (``"timestep"``) and each stage's length."""
    m, dusty = case.materials, "dust" in critical_source
    size = (["particles.dust.radius", "particles.dust.density", "particles.dust.density_scale"] if dusty
            else [_radius_field(case), "materials.particle.density"])
    if m.model == "linear":
        stiffness = ([f"particles.dust.{k}.kn" for k in ("dust_dust", "dust_particle", "dust_wall")] if dusty
                     else ["materials.particle_particle.kn", "materials.particle_wall.kn"])
    else:
        stiffness = ["particles.dust.youngs_modulus" if dusty else "materials.particle.youngs_modulus"]
        stiffness += ["materials.wall.youngs_modulus"] if "wall" in critical_source else []
        stiffness += ["materials.characteristic_velocity"] if m.model == "hooke" else []
    dis = case.discharge
    out = {"timestep": size + stiffness + ["engine.timestep_fraction"],
           "fill": ["fill.count" if case.fill.count is not None else "fill.height",
                    "fill.batch_volume_fraction", "geometry.height", "gravity"],
           "settle": ["fill.settle.max_time"], "shrink": ["fill.settle.max_time"],
           "static": ["fill.settle.static_window"], "open": ["discharge.opening.speed"],
           "discharge": ["discharge.duration" if dis.duration is not None else "discharge.max_time"]}
    return out


#: LIGGGHTS counts its neighbour and atom-sorting bins in a C int ("Too many neighbor bins",
#: "Too many atom sorting bins"); half of INT_MAX leaves room for its ghost bins
MAX_ENGINE_BINS = 2 ** 30


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


def check_run_length(derived: Derived, allow_long: bool = False) -> int:
    """The planned steps of the whole run (every stage at its cap); raises ``SetupError`` naming
    the case fields that set the time step and the longest stages when they exceed
    ``MAX_RUN_STEPS``, unless ``allow_long`` (the CLI's ``--allow-long``)."""
    total = derived.total_planned_steps
    if total <= MAX_RUN_STEPS or allow_long:
        return total
    fields = derived.run_length_fields
    dt = derived.timestep
    stages = sorted(derived.planned_steps.items(), key=lambda kv: -kv[1])
    longest = [f"{stage} {n:.3g} steps = {n * dt:.3g} s ({', '.join(fields.get(stage, []))})"
               for stage, n in stages if n >= 0.1 * total]
    raise SetupError(
        f"the planned run takes up to {total:.3g} steps, more than the cap of {MAX_RUN_STEPS:.0e}: the "
        f"time step is {dt:.3g} s, set by the {derived.critical_time_source} "
        f"({', '.join(fields.get('timestep', []))}); the longest stages: {'; '.join(longest)}. "
        "Change these fields, or pass --allow-long to run it anyway.")


def bed_pressure(case: Case, bulk_density: float, depth: float) -> float:
    """Vertical pressure at the bottom of a bed ``depth`` m deep, Pa: Janssen's
    rho_b g lambda (1 - exp(-depth / lambda)) with lambda = A / (K sum(mu_wall perimeter)) and
    Jaky's K = 1 - sin(atan(friction)); hydrostatic rho_b g depth without wall friction."""
    g = case.geometry
    m = case.materials
    if isinstance(g, PlanarGeometry):
        area = g.width * g.thickness
        grip = 2 * g.thickness * m.particle_wall.friction + 2 * g.width * g.face_friction
    else:
        area = math.pi * g.radius ** 2
        grip = 2 * math.pi * g.radius * m.particle_wall.friction
    hydrostatic = bulk_density * case.gravity * depth
    k = 1.0 - math.sin(math.atan(m.particle_particle.friction))
    if grip * k <= 0:
        return hydrostatic
    lam = area / (k * grip)
    return min(hydrostatic, bulk_density * case.gravity * lam * -math.expm1(-depth / lam))


def air_drag_fraction(radius: float, density: float, gravity: float, speed: float) -> tuple[float, float]:
    """Air drag on a sphere at ``speed`` m/s as a fraction of its weight, and its terminal speed
    in air, m/s. The drag is at least Stokes' (fraction v / v_S, v_S = 2 rho g r^2 / (9 mu)) and
    Newton's (fraction (v / v_N)^2, v_N = sqrt(8 rho g r / (3 rho_air 0.44))); both are lower
    estimates of the fraction, and the smaller speed an upper estimate of the terminal speed."""
    stokes = 2.0 * density * gravity * radius ** 2 / (9.0 * AIR_VISCOSITY)
    newton = math.sqrt(8.0 * density * gravity * radius / (3.0 * AIR_DENSITY * 0.44))
    return max(speed / stokes, (speed / newton) ** 2), min(stokes, newton)


def physics_warnings(case: Case, d: Derived) -> list[str]:
    """Warnings about values that are valid but have consequences a user should know: overlaps
    under the bed's weight, a coarse time step, air drag the model leaves out. Each names the
    fields and the consequence."""
    out = []
    m, f, g = case.materials, case.fill, case.geometry
    grains = d.grains
    small = min(grains, key=lambda sp: sp.radius)
    # overlap under the bed's weight: mean contact force 4 pi R^2 p / (phi Z) of a packing
    # (Cauchy stress of its contacts), Hertz delta = (3 F / (4 E* sqrt(R*)))^(2/3) or F / kn
    depth = d.bed_height_estimate
    volume = bed_volume(case, depth)
    if depth > 0 and volume > 0:
        p = bed_pressure(case, d.total_mass / volume, depth)
        force = 4.0 * math.pi * small.radius ** 2 * p / (f.packing_fraction * STATIC_COORDINATION)
        pair = d.pairs["particle_particle"]
        if pair.kn is not None:
            overlap = force / pair.kn
            law = f"kn {pair.kn:.3g} N/m"
            remedy = ("materials.particle_particle.kn (overlap ~ 1/kn)" if m.model == "linear" else
                      "materials.particle.youngs_modulus or materials.characteristic_velocity")
        else:
            overlap = (3.0 * force / (4.0 * pair.y_eff * math.sqrt(pair.r_eff))) ** (2.0 / 3.0)
            law = f"Hertz, E* {pair.y_eff:.3g} Pa"
            remedy = "materials.particle.youngs_modulus (overlap ~ E^-2/3)"
        ratio = overlap / small.radius
        if ratio > OVERLAP_WARNING:
            out.append(f"soft grains: under the bed's weight (about {p:.3g} Pa at its bottom, {depth:.3g} m "
                       f"deep) grains overlap by about {ratio:.1%} of their radius ({law}), so the bed is "
                       f"compressed by about {1.5 * ratio:.1%} in volume and its solid fraction and wall "
                       f"pressures are shifted by as much; raise {remedy} if that matters")
    if case.engine.timestep_fraction > TIMESTEP_FRACTION_WARNING:
        out.append(f"engine.timestep_fraction {case.engine.timestep_fraction} resolves the shortest contact "
                   f"({d.critical_time_source}) with only {1 / case.engine.timestep_fraction:.2g} steps: "
                   "velocity Verlet is unstable above 0.64 contact times and Hertz contacts stiffen during "
                   "impact, so contacts may gain energy; 0.1-0.2 is usual")
    # air drag at the outlet speed sqrt(g D_outlet), against the grains' weight (their real density)
    v_out = math.sqrt(case.gravity * 2.0 * g.outlet_radius)
    dust = getattr(case.particles, "dust", None)
    for sp in [small] + ([d.dust] if d.dust is not None else []):
        density = dust.density if sp.stream == "dust" else m.particle.density
        r_v = (3.0 * sp.volume / (4.0 * math.pi)) ** (1.0 / 3.0)        # volume-equivalent sphere
        drag, v_t = air_drag_fraction(r_v, density, case.gravity, v_out)
        if drag > DRAG_WARNING:
            what = "particles.dust" if sp.stream == "dust" else "the grains"
            share = "more than their weight" if drag >= 1 else f"at least {drag:.0%} of their weight"
            out.append(f"air drag: {what} fall at most about {v_t:.3g} m/s in air, so at the outlet speed "
                       f"(about {v_out:.3g} m/s) air drag is {share}; siloflow models no gas, so its "
                       "discharge is faster than the same grains' in air")
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
    planar = isinstance(g, PlanarGeometry)
    p = case.particles
    r = p.max_radius                       # geometry margins use the largest grain (clumps: bounding sphere)
    d = 2 * r
    rho = case.materials.particle.density
    species = species_of(case)
    grains = [sp for sp in species if sp.stream == "grains"]
    dust = next((sp for sp in species if sp.stream == "dust"), None)
    dust_ratio = p.dust.number_ratio if dust is not None else 0.0
    numbers = [sp.number_fraction for sp in grains]
    vol = sum(sp.number_fraction * sp.volume for sp in grains)      # mean volume per grain
    mass = rho * vol
    mass_fractions = [sp.number_fraction * sp.volume for sp in grains]
    mass_fractions = [w / sum(mass_fractions) for w in mass_fractions]
    final_mass = mass                      # mean grain mass once the bed has its size distribution
    shrink = getattr(p, "protocol", "insert") == "shrink_after_settling"
    if shrink:        # the bed is poured as grains of the largest radius
        vol = cp.sphere_volume(r)
        mass = rho * vol
    dust_vol = dust_ratio * dust.volume if dust is not None else 0.0    # dust volume per grain
    f = case.fill
    top = g.hopper_height + g.height
    if f.count is not None:
        count = f.count
    else:
        count = int(f.packing_fraction * bed_volume(case, f.height) / (vol + dust_vol))
        if count < 1:
            raise CaseError([("fill.height", "too low to hold a single particle")])
    dust_count = round(dust_ratio * count)
    if dust is not None and dust_count < 1:
        raise CaseError([("particles.dust.number_ratio", f"{dust_ratio} dust per grain is less than one "
                          f"dust sphere for {count} grains")])
    h_bed = bed_height(case, count * (vol + dust_vol) / f.packing_fraction)

    # insertion region: above the expected bed, below the top
    z_max = f.insertion_z_max if f.insertion_z_max is not None else top - 0.5 * d
    z_min = f.insertion_z_min if f.insertion_z_min is not None else max(
        h_bed + 2 * d, z_max - max(0.3 * g.height, 4 * d), g.hopper_height + d)
    if z_max - z_min < 2 * d:
        raise CaseError([("fill", f"the expected bed ({h_bed:.4g} m at solid fraction "
                          f"{f.packing_fraction}) leaves no room to insert particles below the top "
                          f"({top:.4g} m): fill fewer particles or make the silo taller")])
    pour = f.pour_radius if f.pour_radius is not None else g.half_width      # central or distributed fill
    if planar:
        # centres only (all_in no: a clump's bounding sphere is wider than the slab); wheat is
        # inserted lying flat in the slab, so its half thickness is its sphere radius
        half_t = 0.5 * g.thickness - (0.5 * p.width if p.kind == "clumps" else r)
        half_x = min(pour, g.half_width - 1.05 * r)
        insertion_region = {"shape": "block", "xlo": -half_x, "xhi": half_x,
                            "ylo": -half_t, "yhi": half_t, "z_min": z_min + r, "z_max": z_max - r}
        region_volume = 2 * half_x * g.thickness * (z_max - z_min)
    else:
        region_radius = min(pour, g.radius - 0.6 * r)
        insertion_region = {"shape": "cylinder", "radius": region_radius, "z_min": z_min, "z_max": z_max}
        region_volume = math.pi * region_radius ** 2 * (z_max - z_min)
    batch = max(1, min(count, int(f.batch_volume_fraction * region_volume / (vol + dust_vol))))

    # time step: the shortest contact of any pair of types; dust's cost is reported
    v_impact = cp.free_fall_speed(z_max, case.gravity, INSERTION_SPEED)
    type_pairs = type_pair_parameters(case, species, v_impact)
    if planar:        # the slab's front and back faces: the walls' law with the faces' friction
        faces = len(species) + 2
        for sp in species:
            wall_pair = type_pairs[(sp.type, faces - 1)]
            type_pairs[(sp.type, faces)] = replace(wall_pair, name=f"{sp.name}-faces", friction=g.face_friction)
    smallest = min(grains, key=lambda sp: sp.radius).type          # its contacts are the shortest
    wall_type = len(species) + 1
    pairs = {"particle_particle": replace(type_pairs[(smallest, smallest)], name="particle_particle"),
             "particle_wall": replace(type_pairs[(smallest, wall_type)], name="particle_wall")}
    t_crit, source = critical_time(case, species, type_pairs)
    rayleigh = None
    if case.materials.model == "hertz":
        pm = case.materials.particle
        rayleigh = cp.rayleigh_time(p.min_radius, rho, pm.youngs_modulus, pm.poisson_ratio)
    dt = case.engine.timestep_fraction * t_crit
    dt_without_dust = None
    if dust is not None:
        no_dust = {k: v for k, v in type_pairs.items() if dust.type not in k}
        dt_without_dust = case.engine.timestep_fraction * critical_time(case, grains, no_dust)[0]

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
    plate_travel = 3.0 * abs(outlet_z)
    # clumps cannot be deleted at the counting disc (multisphere refuses delete_atoms): the plate
    # also moves aside, so they fall on out of the box, which removes the whole body
    plate_shift = 2.0 * g.outlet_radius + d if any(sp.kind == "clump" for sp in species) else 0.0
    path = math.hypot(plate_travel, plate_shift)
    v_down = v_open * plate_travel / path
    if v_down <= 1.5 * v_needed:
        raise CaseError([("discharge.opening.speed", f"{v_open} m/s is too slow: the plate must move "
                          f"down faster than {1.5 * v_needed:.3g} m/s to leave the grains behind")])
    open_steps = _steps(path / v_open, dt)

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
    half_y = 0.5 * g.thickness if planar else g.radius
    box = {"xlo": -g.half_width - margin, "xhi": max(g.half_width, plate_shift + g.outlet_radius) + margin,
           "ylo": -half_y - margin, "yhi": half_y + margin,
           "zlo": outlet_z - plate_travel - margin, "zhi": top + margin}
    skin = 0.5 * r
    check_bins(box, r, skin)
    static_steps = _steps(s.static_window, dt)
    if static_steps < 2 * sample_freq:      # the time check of the case can miss by a rounded step
        raise CaseError([("fill.settle.static_window", f"{static_steps} steps hold fewer than two samples of "
                          f"{sample_freq} steps (outputs.sample_interval): no static wall-load sample")])
    derived = Derived(
        particle_radius=r, particle_volume=final_mass / rho, particle_mass=final_mass, particle_count=count,
        total_mass=count * final_mass + (dust_count * dust.mass if dust is not None else 0.0), bed_height_estimate=h_bed, impact_velocity=v_impact,
        pairs=pairs, rayleigh_time=rayleigh, critical_time=t_crit, critical_time_source=source,
        timestep=dt,
        insertion_region=insertion_region,
        insertion_batch=batch, insert_every=insert_every, insertion_speed=INSERTION_SPEED,
        fill_steps=fill_steps, settle_chunk_steps=settle_chunk, settle_max_chunks=settle_chunks,
        static_steps=static_steps, open_steps=open_steps,
        discharge_chunk_steps=d_chunk, discharge_max_chunks=d_chunks,
        thermo_every=thermo_every, sample_every=sample_every, sample_repeat=sample_repeat,
        sample_freq=sample_freq, dump_every=dump_every,
        outlet_z=outlet_z, outlet_disc_radius=g.outlet_radius + 2 * d, plate_travel=plate_travel, plate_shift=plate_shift,
        opening_speed=v_open,
        box=box, skin=skin,
        seeds={"insertion": prime_seed(case.seed, 1), "distribution": prime_seed(case.seed, 3),
               "templates": [prime_seed(case.seed, 10 + k) for k in range(len(species))],
               "dust_insertion": prime_seed(case.seed, 5), "dust_distribution": prime_seed(case.seed, 7),
               "shrink": [prime_seed(case.seed, 40 + k) for k in range(len(p.radii))]},
        radii=list(p.radii), number_fractions=list(numbers), mass_fractions=mass_fractions,
        shrink_classes=shrink_classes(p.radii, numbers) if shrink else [],
        type_pairs=type_pairs, species=species, dust_count=dust_count, has_faces=planar,
        dust_batch=math.ceil(batch * dust_ratio) if dust is not None else 0,
        timestep_without_dust=dt_without_dust,
        run_length_fields=run_length_fields(case, source),
    )
    derived.warnings = physics_warnings(case, derived)
    return derived
