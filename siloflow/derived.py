"""Everything a run needs that is computed from the case: species and masses, contact
parameters, time step, stage lengths, insertion batches, output intervals, wall geometry.

``derive(case)`` returns the engine-neutral :class:`~siloflow.plan.RunPlan`, once per run; it is
unit-tested and written to ``plan.json`` beside the deck. All values SI.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from . import contact_physics as cp
from ._version import __version__
from .case import Case
from .errors import CaseError, SetupError
from .plan import (
    FACES,
    WALL,
    Discharge,
    EngineChoice,
    Fill,
    Guard,
    InsertionRegion,
    Material,
    Opening,
    Outlet,
    Outputs,
    PairParameters,
    Profile,
    RunPlan,
    Sensors,
    Settle,
    Silo,
    Species,
    SteadyStop,
    TimeStep,
    Wall,
)
from .silos.registry import kind_of
from .species import INSERTION_SPEED, species_of

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


def measured(case: Case, container=None) -> Case:
    """The case with its mesh silo's walls read and checked (``geometry.kind: mesh``; any other case
    as it is): the files located as the case file gave them, the container measured
    (``siloflow.geometry.read_container``; ``container`` when already read), and the case's checks
    that need the silo's size run. A problem is a ``CaseError`` naming the field."""
    g = case.geometry
    if not kind_of(g).reads_files:
        return case
    from .case.model import shape_problems
    from .geometry import MeshError, Outline, read_container
    if container is None:
        o = g.outlet
        origin = g.origin
        if o.radius is not None:
            outline = Outline((g.outlet_offset, g.outlet_offset_y), radius=o.radius * g.scale)
        else:
            outline = Outline((g.outlet_offset, g.outlet_offset_y),
                              polygon=tuple((x - origin[0], y - origin[1]) for x, y in o.scaled_polygon(g.scale)))
        try:
            container = read_container(g.files, g.scale, outline, origin)
        except MeshError as exc:
            raise CaseError([("geometry.files", str(exc))], case.name) from None
    geometry = g.model_copy()
    geometry._container = container
    case = case.model_copy(update={"geometry": geometry})
    problems = shape_problems(case)
    if problems:
        raise CaseError([("geometry", p) for p in problems], case.name)
    return case


def bed_volume(case: Case, height: float) -> float:
    """Volume of the silo below ``height`` (m above the outlet), m3."""
    return kind_of(case.geometry).bed_volume(case.geometry, height)


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


def _pair(case: Case, a: str, b: str, m_eff: float, r_eff: float, contact, moduli, v_impact: float) -> PairParameters:
    """Contact parameters of the pair ``a``-``b`` with reduced mass and radius; ``contact`` is the
    case's PairContact of the pair, ``moduli`` the (Young's modulus, Poisson ratio) of both sides."""
    m = case.materials
    common = dict(name=f"{a}-{b}", a=a, b=b, m_eff=m_eff, r_eff=r_eff, friction=contact.friction,
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


def contact_pairs(case: Case, species: list[Species], v_impact: float) -> list[PairParameters]:
    """Contact parameters of every pair of species and of each species with the walls, which act
    as infinite mass and radius (and, for a slab, with its faces: the walls' law with the faces'
    friction). Radii are those of the touching spheres; masses those of the whole grains (a clump
    moves as one body)."""
    out = []
    for i, a in enumerate(species):
        for b in species[i:]:
            out.append(_pair(case, a.name, b.name, cp.reduced(a.mass, b.mass), cp.reduced(a.radius, b.radius),
                             _contact_of(case, a.material, b.material),
                             (_modulus_of(case, a.material), _modulus_of(case, b.material)), v_impact))
        out.append(_pair(case, a.name, WALL, a.mass, a.radius, _contact_of(case, a.material, None),
                         (_modulus_of(case, a.material), _modulus_of(case, None)), v_impact))
    g = case.geometry
    if kind_of(g).slab:
        walls = {p.a: p for p in out if p.b == WALL}
        out += [walls[sp.name].model_copy(update={"name": f"{sp.name}-{FACES}", "b": FACES,
                                                  "friction": g.face_friction}) for sp in species]
    return out


def critical_time(case: Case, species: list[Species], pairs: list[PairParameters]) -> tuple[float, str]:
    """The shortest contact time of any pair (and, for Hertz, Rayleigh time of any species), s,
    with what set it."""
    candidates = {f"contact time {pp.name}": pp.contact_time for pp in pairs}
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


def run_length_fields(case: Case, critical_source: str, profile: str = "custom") -> dict[str, list[str]]:
    """The case fields that set the time step (``"timestep"``) and each stage's length (``profile``:
    the case's own; any but custom owns the time step)."""
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
    step = "engine.timestep_fraction" if profile == "custom" else "engine.profile"
    out = {"timestep": size + stiffness + [step],
           "fill": ["fill.count" if case.fill.count is not None else "fill.height",
                    "fill.batch_volume_fraction", "geometry.height", "gravity"],
           "settle": ["fill.settle.max_time"], "shrink": ["fill.settle.max_time"],
           "mobilise": ["fill.mobilise.time"], "resettle": ["fill.settle.max_time"],
           "static": ["fill.settle.static_window"], "open": ["discharge.opening.speed"],
           "discharge": ["discharge.duration" if dis.duration is not None else "discharge.max_time"]}
    return out


def check_run_length(derived: RunPlan, allow_long: bool = False) -> int:
    """The planned steps of the whole run (every stage at its cap); raises ``SetupError`` naming
    the case fields that set the time step and the longest stages when they exceed
    ``MAX_RUN_STEPS``, unless ``allow_long`` (the CLI's ``--allow-long``)."""
    total = derived.total_planned_steps
    if total <= MAX_RUN_STEPS or allow_long:
        return total
    fields = derived.run_length_fields
    dt = derived.dt
    stages = sorted(derived.planned_steps().items(), key=lambda kv: -kv[1])
    longest = [f"{stage} {n:.3g} steps = {n * dt:.3g} s ({', '.join(fields.get(stage, []))})"
               for stage, n in stages if n >= 0.1 * total]
    raise SetupError(
        f"the planned run takes up to {total:.3g} steps, more than the cap of {MAX_RUN_STEPS:.0e}: the "
        f"time step is {dt:.3g} s, set by the {derived.timestep.critical_time_source} "
        f"({', '.join(fields.get('timestep', []))}); the longest stages: {'; '.join(longest)}. "
        "Change these fields, or pass --allow-long to run it anyway.")


def bed_pressure(case: Case, bulk_density: float, depth: float) -> float:
    """Vertical pressure at the bottom of a bed ``depth`` m deep, Pa: Janssen's
    rho_b g lambda (1 - exp(-depth / lambda)) with lambda = A / (K sum(mu_wall perimeter)) and
    Jaky's K = 1 - sin(atan(friction)); hydrostatic rho_b g depth without wall friction."""
    g = case.geometry
    m = case.materials
    area, grip = kind_of(g).janssen_section(g, m.particle_wall.friction)
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


def physics_warnings(case: Case, d: RunPlan) -> list[str]:
    """Warnings about values that are valid but have consequences a user should know: overlaps
    under the bed's weight, a coarse time step, air drag the model leaves out. Each names the
    fields and the consequence."""
    out = []
    m, f, g = case.materials, case.fill, case.geometry
    grains = d.grains
    small = min(grains, key=lambda sp: sp.radius)
    # overlap under the bed's weight: mean contact force 4 pi R^2 p / (phi Z) of a packing
    # (Cauchy stress of its contacts), Hertz delta = (3 F / (4 E* sqrt(R*)))^(2/3) or F / kn
    depth = d.fill.bed_height_estimate
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
        owner = ("engine.timestep_fraction" if d.profile is None or d.profile.name == "custom"
                 else f"engine.profile {d.profile.name}'s time step")
        out.append(f"{owner} {case.engine.timestep_fraction} resolves the shortest contact "
                   f"({d.timestep.critical_time_source}) with only {1 / case.engine.timestep_fraction:.2g} steps: "
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


def _engine_options(case) -> dict[str, int]:
    """The case's settings only some engine reads (``EngineChoice.options``)."""
    tries = getattr(case.particles, "monte_carlo_tries", None)
    out = {} if tries is None else {"monte_carlo_tries": tries}
    if case.engine.side_walls == "primitive" and case.engine.name == "liggghts":
        out["primitive_side_walls"] = 1           # LIGGGHTS' primitive side walls (engine.liggghts.side_walls)
    return out


@dataclass(frozen=True)
class GrainBudget:
    """What the fill's amount and batches need of the species: ``species`` (every one), ``grains``
    and ``dust`` (None without), ``dust_ratio`` (dust spheres per grain), ``number_fractions`` of
    the grains, their ``mass_fractions``, ``poured_volume`` (m3, mean volume of a grain as poured:
    the largest sphere when the bed shrinks after settling), ``dust_volume`` (m3 of dust per grain),
    ``grain_mass`` (kg, mean mass once the bed has its size distribution), ``shrink``."""

    species: list[Species]
    grains: list[Species]
    dust: Optional[Species]
    dust_ratio: float
    number_fractions: list[float]
    mass_fractions: list[float]
    poured_volume: float
    dust_volume: float
    grain_mass: float
    shrink: bool

    @property
    def volume_per_grain(self) -> float:
        """Solid volume inserted per grain, dust included, m3."""
        return self.poured_volume + self.dust_volume


def plan_species(case: Case) -> GrainBudget:
    """The species of the case and the volumes and masses the fill is planned with."""
    p = case.particles
    rho = case.materials.particle.density
    species = species_of(case)
    grains = [sp for sp in species if sp.stream == "grains"]
    dust = next((sp for sp in species if sp.stream == "dust"), None)
    dust_ratio = p.dust.number_ratio if dust is not None else 0.0
    vol = sum(sp.number_fraction * sp.volume for sp in grains)      # mean volume per grain
    mass_fractions = [sp.number_fraction * sp.volume for sp in grains]
    shrink = getattr(p, "protocol", "insert") == "shrink_after_settling"
    return GrainBudget(species=species, grains=grains, dust=dust, dust_ratio=dust_ratio,
                       number_fractions=[sp.number_fraction for sp in grains],
                       mass_fractions=[w / sum(mass_fractions) for w in mass_fractions],
                       poured_volume=cp.sphere_volume(p.max_radius) if shrink else vol,  # poured as the largest
                       dust_volume=dust_ratio * dust.volume if dust is not None else 0.0,
                       grain_mass=rho * vol, shrink=shrink)


def plan_amount(case: Case, budget: GrainBudget) -> tuple[int, int, float]:
    """The grains and dust spheres the fill inserts, and the expected bed's height (m):
    ``fill.count``, else as many as ``fill.height`` holds at ``fill.packing_fraction``."""
    f = case.fill
    if f.count is not None:
        count = f.count
    else:
        count = int(f.packing_fraction * bed_volume(case, f.height) / budget.volume_per_grain)
        if count < 1:
            raise CaseError([("fill.height", f"too low to hold a single particle at fill.packing_fraction "
                                             f"{f.packing_fraction:g}")])
    dust_count = round(budget.dust_ratio * count)
    if budget.dust is not None and dust_count < 1:
        raise CaseError([("particles.dust.number_ratio", f"{budget.dust_ratio} dust per grain is less than one "
                          f"dust sphere for {count} grains (fill.count)")])
    return count, dust_count, bed_height(case, count * budget.volume_per_grain / f.packing_fraction)


def plan_insertion(case: Case, h_bed: float) -> tuple[float, float, dict, float]:
    """The insertion heights z_min, z_max (m) above the expected bed ``h_bed`` (m) and below the
    top, the region between them (``InsertionRegion`` fields) and its volume (m3); ``CaseError``
    when the bed leaves it no room."""
    f, g, p = case.fill, case.geometry, case.particles
    r = p.max_radius                       # geometry margins use the largest grain (clumps: bounding sphere)
    d = 2 * r
    top = g.hopper_height + g.height
    z_max = f.insertion_z_max if f.insertion_z_max is not None else top - 0.5 * d
    z_min = f.insertion_z_min if f.insertion_z_min is not None else max(
        h_bed + 2 * d, z_max - max(0.3 * g.height, 4 * d), g.hopper_height + d)
    if f.protocol == "pour" and f.insertion_z_min is None:      # a thin layer at a fixed height
        z_min = max(z_min, z_max - POUR_LAYER * d)
    if z_max - z_min < 2 * d:
        amount = "fill.height" if f.height is not None else "fill.count"
        raise CaseError([("fill", f"the expected bed ({h_bed:.4g} m: {amount} at fill.packing_fraction "
                          f"{f.packing_fraction}) leaves no room to insert particles below the top "
                          f"({top:.4g} m): fill fewer particles or make the silo taller (geometry.height)")])
    pour = f.pour_radius if f.pour_radius is not None else g.half_width      # central or distributed fill
    return (z_min, z_max) + kind_of(g).insertion_region(g, p, pour, r, z_min, z_max)


def plan_timestep(case: Case, budget: GrainBudget, v_impact: float) -> tuple[TimeStep, list[PairParameters], dict]:
    """The time step (the shortest contact of any pair of species at impact speed ``v_impact``,
    m/s, times ``engine.timestep_fraction``; dust's cost reported), every pair's contact parameters,
    and the smallest grain's with itself and the walls (``particle_particle``, ``particle_wall``)."""
    species, grains, dust = budget.species, budget.grains, budget.dust
    contacts = contact_pairs(case, species, v_impact)
    smallest = min(grains, key=lambda sp: sp.radius).name          # its contacts are the shortest
    by_names = {(c.a, c.b): c for c in contacts}
    pairs = {"particle_particle": by_names[(smallest, smallest)].model_copy(update={"name": "particle_particle"}),
             "particle_wall": by_names[(smallest, WALL)].model_copy(update={"name": "particle_wall"})}
    t_crit, source = critical_time(case, species, contacts)
    rayleigh = None
    if case.materials.model == "hertz":
        pm = case.materials.particle
        rayleigh = cp.rayleigh_time(case.particles.min_radius, pm.density, pm.youngs_modulus, pm.poisson_ratio)
    dt_without_dust = None
    if dust is not None:
        no_dust = [c for c in contacts if dust.name not in (c.a, c.b)]
        dt_without_dust = case.engine.timestep_fraction * critical_time(case, grains, no_dust)[0]
    timestep = TimeStep(dt=case.engine.timestep_fraction * t_crit, fraction=case.engine.timestep_fraction,
                        critical_time=t_crit, critical_time_source=source, rayleigh_time=rayleigh,
                        without_dust=dt_without_dust)
    return timestep, contacts, pairs



def plan_fill(case: Case, budget: GrainBudget, count: int, dust_count: int, h_bed: float,
              insertion: tuple[float, float, dict, float], dt: float, v_impact: float) -> Fill:
    """The fill's batches: as many grains as ``fill.batch_volume_fraction`` of the insertion region
    holds (:func:`plan_insertion`'s ``insertion``; a pour: one small batch per clearing time over
    ``fill.pour_time``), each leaving the region before the next comes; the steps of the whole fill
    (``dt`` s, grains inserted at ``v_impact`` m/s)."""
    f, p = case.fill, case.particles
    z_min, z_max, region, region_volume = insertion
    batch = max(1, min(count, int(f.batch_volume_fraction * region_volume / budget.volume_per_grain)))
    h_region = z_max - z_min
    t_clear = (-INSERTION_SPEED + math.sqrt(INSERTION_SPEED ** 2 + 2 * case.gravity * h_region)) / case.gravity
    insert_every = _steps(1.1 * t_clear, dt)
    if f.protocol == "pour":        # small batches, one per clearing time, over the pour time
        wanted = math.ceil(count / max(1, math.floor(f.pour_time / (insert_every * dt))))
        if wanted > batch:
            raise CaseError([("fill.pour_time", f"{f.pour_time} s is too short to pour {count} grains through a "
                              f"layer {POUR_LAYER} grains deep: at most {batch} per {insert_every * dt:.3g} s fit, "
                              f"so the pour takes at least {math.ceil(count / batch) * insert_every * dt:.3g} s")])
        batch = max(1, wanted)
    n_batches = math.ceil(count / batch)
    t_fall = (-INSERTION_SPEED + math.sqrt(INSERTION_SPEED ** 2 + 2 * case.gravity * z_max)) / case.gravity
    fill_steps = n_batches * insert_every + _steps(1.5 * t_fall, dt)
    return Fill(count=count, dust_count=dust_count, batch=batch,
                dust_batch=math.ceil(batch * budget.dust_ratio) if budget.dust is not None else 0,
                insert_every=insert_every, insertion_speed=INSERTION_SPEED,
                region=InsertionRegion(**region), steps=fill_steps, frictionless=f.frictionless,
                radii=list(p.radii), number_fractions=list(budget.number_fractions),
                mass_fractions=budget.mass_fractions,
                shrink_classes=shrink_classes(p.radii, budget.number_fractions) if budget.shrink else [],
                packing_fraction=f.packing_fraction, bed_height_estimate=h_bed, impact_velocity=v_impact)


def plan_settle(case: Case, dt: float) -> Settle:
    """The settling's checks: one every ``fill.settle.check_interval`` (``dt`` s steps), up to its
    ``max_time``."""
    s = case.fill.settle
    return Settle(ke_pe_ratio=s.ke_pe_ratio, chunk_steps=_steps(s.check_interval, dt),
                  max_chunks=max(1, math.ceil(s.max_time / s.check_interval)))


def plan_opening(case: Case, dt: float) -> tuple[Outlet, Opening]:
    """The counting disc two grain diameters below the orifice, over the outlet, and the plate's
    opening: down three times as far, faster than the grains fall after it (``CaseError`` if not)."""
    d = 2 * case.particles.max_radius
    outlet_z = -2.0 * d
    v_open = case.discharge.opening.speed
    plate_travel = 3.0 * abs(outlet_z)
    check_opening(case.gravity, v_open, outlet_z)
    return (Outlet(z=outlet_z, radius=kind_of(case.geometry).outlet_reach(case.geometry) + 2 * d),
            Opening(speed=v_open, travel=plate_travel, steps=_steps(plate_travel / v_open, dt)))


def plan_discharge(case: Case, dt: float, total_mass: float) -> Discharge:
    """The discharge's chunks (``dt`` s steps): 0.1 s ones until empty (``empty_fraction`` of
    ``total_mass``, kg, left), batches until steady, or one of ``discharge.duration``."""
    dis = case.discharge
    steady = None
    if dis.until_empty:
        chunk_time = min(0.1, dis.max_time)
        d_chunk, d_chunks = _steps(chunk_time, dt), max(1, math.ceil(dis.max_time / chunk_time))
    elif dis.until_steady:
        d_chunk = _steps(dis.batch_time, dt)
        d_chunks = max(1, math.ceil(dis.max_time / dis.batch_time))
        steady = SteadyStop(precision=dis.precision, chunk_time=d_chunk * dt,
                            skip_chunks=math.ceil(dis.startup_time / (d_chunk * dt) - 1e-9),
                            min_batches=dis.min_batches)
    else:
        d_chunk, d_chunks = _steps(dis.duration, dt), 1
    return Discharge(chunk_steps=d_chunk, max_chunks=d_chunks, until_empty=dis.until_empty, steady=steady,
                     empty_mass=dis.empty_fraction * total_mass)


def plan_outputs(case: Case, dt: float, thermo_every: int) -> Outputs:
    """What the deck writes and how often (``dt`` s steps): wall-force averages of 5 samples per
    ``outputs.sample_interval``, thermo every ``thermo_every`` steps (the settling's checks read it),
    dumps as the results need them (:func:`result_needs`)."""
    out = case.outputs
    needs = result_needs(case)
    sample_freq = _steps(out.sample_interval, dt)
    sample_every = max(1, sample_freq // 5)  # 5 samples per average: wall-force sampling is not free
    sample_repeat = sample_freq // sample_every
    sample_freq = sample_every * sample_repeat
    dump_every = None
    if needs["dumps"]:              # outputs.dump_interval, else as often as the frame analyses need
        dump_every = _steps(out.dump_interval or auto_dump_interval(case), dt)
    return Outputs(thermo_every=thermo_every, sample_steps=sample_freq, samples_per_average=sample_repeat,
                   dump_every=dump_every, vtk=bool(dump_every and needs["vtk"]),
                   contacts=bool(dump_every and needs["contacts"]), results=out.results,
                   wall_pressure=needs["wall_pressure"], wall_forces=needs["wall_forces"])


def plan_static(case: Case, dt: float, outputs: Outputs) -> int:
    """The static window's steps (``dt`` s each): at least two of the outputs' samples, else
    ``CaseError``."""
    static_steps = _steps(case.fill.settle.static_window, dt)
    if static_steps < 2 * outputs.sample_steps:      # the time check of the case can miss by a rounded step
        raise CaseError([("fill.settle.static_window", f"{static_steps} steps hold fewer than two samples of "
                          f"{outputs.sample_steps} steps (outputs.sample_interval): no static wall-load sample")])
    return static_steps


def plan_silo(case: Case) -> Silo:
    """The plan's silo: the fields every kind has, and its kind's own (``SiloKind.silo_fields``)."""
    g = case.geometry
    return Silo(kind=g.kind, half_width=g.half_width, height=g.height, hopper_height=g.hopper_height,
                outlet_radius=g.outlet_radius, outlet_offset=g.outlet_offset, **kind_of(g).silo_fields(g))


def plan_materials(case: Case, dust: bool) -> dict[str, Material]:
    """The elastic constants of the particles, the walls and (``dust``) the dust."""
    names = {"particle": "particle", "wall": None}
    if dust:
        names["dust"] = "dust"
    return {name: Material(youngs_modulus=_modulus_of(case, m)[0], poisson_ratio=_modulus_of(case, m)[1])
            for name, m in names.items()}


def plan_walls(case: Case, plan: RunPlan) -> RunPlan:
    """The plan with its walls (their meshes generated and the inserts' read: :func:`wall_meshes`),
    the floor's lowering (``fill.mobilise``) or the fill protocol, the sensor bands counted and the
    physics warnings; ``CaseError`` for a dump interval longer than the whole run."""
    f, out, dt = case.fill, case.outputs, plan.dt
    meshes = wall_meshes(case, plan, sensors=plan.outputs.wall_pressure)
    walls = [Wall(**m.info()) for m in meshes]
    if f.mobilise is not None or f.protocol != "rain":
        plan = plan.model_copy(update={"fill": plan.fill.model_copy(update={
            "protocol": f.protocol, "mobilise": mobilise_plan(case, meshes, dt)})})
    total = plan.total_planned_steps
    dump_every = plan.outputs.dump_every
    if out.dump_interval is not None and dump_every is not None and dump_every > total:
        raise CaseError([("outputs.dump_interval", f"{out.dump_interval:g} s is longer than the whole run (at most "
                          f"{total * dt:.4g} s with every stage at its cap): no frame would be written after the "
                          "first; give a shorter interval, or none (the frame analyses then choose one)")])
    plan = plan.model_copy(update={
        "walls": walls, "warnings": physics_warnings(case, plan),
        "sensors": Sensors(bands=len([w for w in walls if w.role == "band"]) // plan.sensors.sectors,
                           sectors=plan.sensors.sectors)})
    plan._meshes = meshes
    return plan


def plan_profile(settings: dict) -> Profile:
    """The engine profile's settings as the plan records them (``siloflow.profiles.profile_settings``)."""
    return Profile(name=settings["profile"], timestep_fraction=settings["timestep_fraction"],
                   stiffness_scale=settings["stiffness_scale"], overlap_ratio=settings.get("overlap_ratio"),
                   speedup=settings.get("speedup"),
                   error_bounds=settings.get("error_bounds", {}), tolerances=settings.get("tolerances", {}),
                   benchmark=settings.get("benchmark", ""), question=settings.get("question"),
                   unbounded=settings.get("unbounded", []), measured=settings.get("measured", {}))


def plan_sensors(case: Case) -> Sensors:
    """The sensor sectors per band (the kind's: ``SiloKind.sensor_sectors``); the bands are counted
    once the walls are cut (:func:`plan_walls`)."""
    return Sensors(bands=0, sectors=kind_of(case.geometry).sensor_sectors(case.geometry, case.sensors.sectors))


def derive(case: Case) -> RunPlan:
    """The run plan of a case: every value any engine needs, computed once, with the walls' meshes
    (generated, and the inserts' read from their files and checked); one planner per section
    (``plan_*``), in the order their checks run.

    Raises
    ------
    CaseError
        when the case is valid on its own but cannot be run as stated (bed too high
        for the insertion region, opening too slow, ...), naming the field.
    """
    from .profiles import effective_case, profile_settings
    case = measured(case)                  # a mesh silo's walls read once, here
    settings = profile_settings(case)
    # the profile's time step and stiffness, applied once here (a changed case is validated anew: the
    # walls read are handed on)
    container = case.geometry.container if kind_of(case.geometry).reads_files else None
    case = measured(effective_case(case, settings), container)
    budget = plan_species(case)
    count, dust_count, h_bed = plan_amount(case, budget)
    insertion = plan_insertion(case, h_bed)
    v_impact = cp.free_fall_speed(insertion[1], case.gravity, INSERTION_SPEED)
    timestep, contacts, pairs = plan_timestep(case, budget, v_impact)
    dt = timestep.dt
    fill = plan_fill(case, budget, count, dust_count, h_bed, insertion, dt, v_impact)
    settle = plan_settle(case, dt)
    outlet, opening = plan_opening(case, dt)
    total_mass = count * budget.grain_mass + (dust_count * budget.dust.mass if budget.dust is not None else 0.0)
    discharge = plan_discharge(case, dt, total_mass)
    outputs = plan_outputs(case, dt, settle.chunk_steps)  # settle checks read thermo values: they coincide
    static_steps = plan_static(case, dt, outputs)
    plan = RunPlan(
        siloflow_version=__version__, name=case.name,
        engine=EngineChoice(name=case.engine.name, ranks=case.engine.ranks, options=_engine_options(case)),
        profile=plan_profile(settings),
        guard=guard_limits(case, budget.species, opening.speed, outlet.z - opening.travel),
        gravity=case.gravity, seed=case.seed, geometry=plan_silo(case), species=budget.species,
        materials=plan_materials(case, budget.dust is not None), contact_model=case.materials.model, contacts=contacts, pairs=pairs,
        timestep=timestep, fill=fill, settle=settle, static_steps=static_steps, opening=opening,
        discharge=discharge, outlet=outlet, sensors=plan_sensors(case), outputs=outputs, total_mass=total_mass,
        particle_radius=case.particles.max_radius, particle_volume=budget.grain_mass / case.materials.particle.density,
        particle_mass=budget.grain_mass, analysis=case.analysis, design=case.design,
        run_length_fields=run_length_fields(case, timestep.critical_time_source, settings["profile"]),
    )
    return plan_walls(case, plan)


def wall_meshes(case: Case, plan: RunPlan, sensors: bool) -> list:
    """The walls' meshes (``siloflow.geometry.WallMesh``) of the plan's silo, sensor bands as the
    case's ``sensors`` asks (side walls merged into one without ``sensors``), then the case's
    user walls, the counting mesh last. A wall that cannot be triangulated well, or a user mesh
    that cannot be used, is a ``CaseError`` naming the case fields to change."""
    from .geometry import (
        MeshError,
        MeshQualityError,
        band_boundaries,
        silo_meshes,
        user_wall,
    )
    s = case.sensors
    bounds = band_boundaries(case.geometry.height, s.bands, s.heights)
    container = case.geometry.container if kind_of(case.geometry).reads_files else None
    try:
        meshes = silo_meshes(plan.geometry, bounds, plan.sensors.sectors, plan.outlet.z, plan.outlet.radius, sensors,
                             container)
    except MeshError as exc:            # a mesh silo's walls that cannot be cut into sensors
        raise CaseError([("sensors", f"the walls of geometry.files cannot be cut into sensors: {exc}")],
                        case.name) from None
    except MeshQualityError as exc:
        fields = shaping_fields(case, exc.role, exc.kind)
        raise CaseError([(fields[0], f"the wall mesh '{exc.wall}' cannot be triangulated for LIGGGHTS: "
                          f"{exc.reason}; change {' or '.join(fields)}")], case.name) from None
    problems, inserts = [], []
    for k, ins in enumerate(case.inserts):
        try:
            inserts.append(user_wall(ins.mesh_name, ins.file, ins.scale, plan.geometry))
        except MeshError as exc:
            problems.append((f"inserts[{k}].file", str(exc)))
    if problems:
        raise CaseError(problems, case.name)
    return meshes[:-1] + inserts + meshes[-1:]


def shaping_fields(case: Case, role: str, kind: str = "angle") -> list[str]:
    """The case fields that shape a wall of ``role``, the likeliest culprit first (for ``kind``
    'edge', a too short edge: the outlet's size, which sets the hopper's shortest sides)."""
    sensors = "sensors.heights" if case.sensors.heights is not None else "sensors.bands"
    return kind_of(case.geometry).shaping_fields(case.geometry, role, kind, sensors)


def own_overlap(species: Species) -> float:
    """The deepest overlap of two spheres of one clump, m (0 for a sphere): LIGGGHTS lists a clump's own
    overlapping spheres among the pair contacts (seen in a clump discharge: 3 mm for paper A's wheat),
    so the guard's overlap limit stands on top of it."""
    deepest = 0.0
    for i, a in enumerate(species.spheres):
        for b in species.spheres[i + 1:]:
            deepest = max(deepest, a[3] + b[3] - math.dist(a[:3], b[:3]))
    return deepest


def guard_limits(case: Case, species: list, v_open: float, z_lowest: float) -> Guard:
    """The instability guard's limits (``engine.guard``), SI. The fastest a grain can move in a silo
    driven by gravity alone is its insertion speed plus the free fall from the top to the lowest
    point it can reach (the plate's end), plus the plate's own speed: ``speed_factor`` times that
    is energy from nowhere. Overlaps are measured against the smallest grain (not the dust: a grain
    pressing a dust sphere may overlap it by more than the dust's radius in a sound run)."""
    gs, g = case.engine.guard, case.geometry
    top = g.hopper_height + g.height
    fall = math.sqrt(INSERTION_SPEED ** 2 + 2.0 * case.gravity * (top - z_lowest))
    r_min = min(sp.radius for sp in species if sp.stream == "grains")     # dust: watched by speed and escapes
    margin = gs.escape_margin * 2.0 * case.particles.max_radius
    return Guard(enabled=gs.enabled, max_speed=gs.speed_factor * (fall + v_open),
                 max_overlap=gs.max_overlap * r_min + max(map(own_overlap, species)),
                 max_overlap_fraction=gs.max_overlap, grain_radius=r_min,
                 energy_growth=gs.energy_growth,
                 escape_z=top + margin, **kind_of(g).escape_limits(g, margin))


#: depth of a pour's insertion layer at the top of the silo, grain diameters
POUR_LAYER = 3.0


def mobilise_plan(case: Case, meshes, dt: float):
    """The floor's lowering after settling (None without ``fill.mobilise``): the floor meshes
    (bottom and orifice plate), drop (m), speed (m/s), steps."""
    mob = case.fill.mobilise
    if mob is None:
        return None
    from .plan import Mobilise as MobilisePlan
    drop = mob.floor_drop * 2 * case.particles.max_radius
    steps = _steps(mob.time, dt)
    return MobilisePlan(drop=drop, speed=drop / (steps * dt), steps=steps,
                        meshes=[m.name for m in meshes if m.role in ("bottom", "plate")])


#: dump frames the frame analyses need over the discharge, when the case sets no dump interval:
#: the free surface's fit and the coarse-graining's time average (paper B averages 50 and more)
FRAMES_FOR = {"free_surface": 20, "porosity": 20, "coordination": 20, "force_chains": 5, "vtk": 20,
              "coarse_graining": 50}


def result_needs(case: Case) -> dict[str, bool]:
    """What the deck must hold for the results the case asks for (``outputs.results``; unset:
    everything its other fields ask): sensor meshes, wall-force sampling, dumps, contact dumps, VTK."""
    out = case.outputs
    if out.results is None:
        return {"wall_pressure": True, "wall_forces": True, "dumps": out.dump_interval is not None,
                "contacts": out.contacts, "vtk": out.vtk}
    r = set(out.results)
    frames = r & set(FRAMES_FOR)
    return {"wall_pressure": "wall_pressure" in r, "wall_forces": bool(r & {"wall_pressure", "force_balance"}),
            "dumps": bool(frames), "contacts": bool(r & {"coordination", "force_chains", "coarse_graining"}),
            "vtk": "vtk" in r}


def auto_dump_interval(case: Case) -> float:
    """The dump interval (s) when results need frames and the case sets none: the discharge
    (its cap, for until_empty) over the frames the most demanding result needs, and no longer
    than the static window (so a frame shows the settled bed before the orifice opens)."""
    dis = case.discharge
    span = dis.duration if dis.duration is not None else dis.max_time
    frames = max(FRAMES_FOR[k] for k in case.outputs.results if k in FRAMES_FOR)
    return min(case.fill.settle.static_window, span / frames)


def check_opening(gravity: float, speed: float, outlet_z: float, down: float = 1.0) -> None:
    """Refuse an opening plate too slow to leave the grains behind (``CaseError``): its downward
    speed (``down`` of ``speed``, m/s, when it also moves aside) must outrun grains falling from
    rest to the counting disc at ``outlet_z`` (m) by half as much again."""
    v_needed = math.sqrt(gravity * abs(outlet_z) / 2.0)
    if speed * down <= 1.5 * v_needed:
        raise CaseError([("discharge.opening.speed", f"{speed} m/s is too slow: the plate must move "
                          f"down faster than {1.5 * v_needed:.3g} m/s to leave the grains behind (they fall "
                          f"after it under gravity {gravity:g} m/s2)")])
