"""The run plan: everything any engine needs to run a case, engine-neutral and in SI units.

``siloflow.derived.derive(case)`` computes it once per run; the deck step writes it to the run
folder as ``plan.json`` and :meth:`RunPlan.from_json` reads it back, typed (pydantic), so no
consumer reads it as a dict. An engine turns the plan into its own encoding (LIGGGHTS: atom
types for walls, prime seeds, ave/time sampling; see ``siloflow.engine.liggghts.encoding``).

Species are listed in a fixed order: the case's size classes (or its clump shape), then the
dust. Contact parameters are given per pair of species, and between each species and the walls
(``"wall"``) and a slab's front and back faces (``"faces"``).
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import BaseModel, ConfigDict, PrivateAttr, ValidationError, model_serializer

from .case import DEFAULT_TIMESTEP_FRACTION, Analysis, DesignSettings
from .errors import ReadError
from .silos.registry import SILO_KINDS, silo_kind

#: bumped whenever a field changes meaning; a plan of another version is refused
PLAN_VERSION = 1
#: the walls' side of a contact pair, and a slab's front and back faces'
WALL, FACES = "wall", "faces"


class Frozen(BaseModel):
    """A plan record: immutable, no unknown fields."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class Species(Frozen):
    """One kind of grain (SI): a size class, a clump shape, or the dust.

    ``stream`` is ``grains`` (the case's particles) or ``dust`` (inserted beside them at a
    number ratio); ``number_fraction`` is within the stream. A clump's ``volume`` is the union
    volume of its spheres and ``radius`` its largest sphere (contacts); ``spheres`` are its
    [x, y, z, r] in the body frame, m."""

    name: str
    kind: Literal["sphere", "clump"]
    stream: Literal["grains", "dust"]
    radius: float             # m
    bounding_radius: float    # m
    volume: float             # m3
    density: float            # kg/m3, as simulated
    number_fraction: float
    material: Literal["particle", "dust"]   # which material and contact parameters apply
    spheres: list[list[float]] = []

    @property
    def mass(self) -> float:
        """kg."""
        return self.density * self.volume

    @property
    def n_spheres(self) -> int:
        return max(1, len(self.spheres))


class Material(Frozen):
    """Elastic constants of a material (None for the linear contact law, which has none)."""

    youngs_modulus: Optional[float] = None    # Pa
    poisson_ratio: Optional[float] = None


class PairParameters(Frozen):
    """Contact parameters and contact time of one pair: species ``a`` against species ``b``, the
    walls (``"wall"``) or a slab's faces (``"faces"``). Masses are those of whole grains (a clump
    moves as one body), radii those of the touching spheres."""

    name: str
    a: str = ""
    b: str = ""
    m_eff: float          # kg
    r_eff: float          # m
    friction: float
    restitution: float
    rolling_friction: float
    contact_time: float   # s
    y_eff: Optional[float] = None    # Pa (hertz, hooke)
    kn: Optional[float] = None       # N/m (hooke, linear)
    kt: Optional[float] = None       # N/m
    gamman: Optional[float] = None   # 1/s (viscous damping over the reduced mass)
    gammat: Optional[float] = None   # 1/s


class TimeStep(Frozen):
    """The time step (s) and what set it: ``fraction`` of the shortest contact (or Rayleigh) time."""

    dt: float
    fraction: float
    critical_time: float
    critical_time_source: str
    rayleigh_time: Optional[float] = None
    without_dust: Optional[float] = None      # s: what dt would be without the dust (its cost)


class InsertionRegion(Frozen):
    """Where grains are inserted: a vertical cylinder about the axis or, for a slab, a block (m)."""

    shape: Literal["cylinder", "block"]
    z_min: float
    z_max: float
    radius: Optional[float] = None
    xlo: Optional[float] = None
    xhi: Optional[float] = None
    ylo: Optional[float] = None
    yhi: Optional[float] = None


class Mobilise(Frozen):
    """After settling the floor meshes are lowered by ``drop`` (m) at ``speed`` (m/s) in ``steps``,
    then the bed settles again."""

    drop: float
    speed: float
    steps: int
    meshes: list[str]


class Fill(Frozen):
    """The fill: grains inserted in batches from the insertion region (``protocol`` rain: a tall
    region, pour: a thin layer at the top, slowly), then settled (and ``mobilise``d)."""

    count: int                      # grains (clumps count one each)
    dust_count: int
    batch: int                      # grains per batch
    dust_batch: int
    insert_every: int               # steps between batches
    insertion_speed: float          # m/s, downwards
    region: InsertionRegion
    steps: int                      # steps of the whole fill
    frictionless: bool              # paper A: grains poured without friction, restored after
    radii: list[float]              # m, the size classes
    number_fractions: list[float]
    mass_fractions: list[float]
    shrink_classes: list[tuple[float, float]] = []   # paper B: [(radius m, conditional fraction)]
    packing_fraction: float         # expected solid fraction of the bed
    bed_height_estimate: float      # m above the outlet
    impact_velocity: float          # m/s, fastest impact of a grain on the bed
    protocol: str = "rain"
    mobilise: Optional[Mobilise] = None


class Settle(Frozen):
    """Settling: chunks of ``chunk_steps`` until KE/PE < ``ke_pe_ratio``, at most ``max_chunks``."""

    ke_pe_ratio: float
    chunk_steps: int
    max_chunks: int


class Opening(Frozen):
    """The orifice plate moves down by ``travel`` (m) at ``speed`` (m/s) in ``steps``."""

    speed: float
    travel: float
    steps: int


class SteadyStop(Frozen):
    """Stop the discharge once the relative standard error of the mean chunk rate (batch means)
    is below ``precision``: chunks after the first ``skip_chunks`` count, at least ``min_batches``."""

    precision: float
    chunk_time: float               # s, one chunk (= Discharge.chunk_steps x dt)
    skip_chunks: int
    min_batches: int


class Discharge(Frozen):
    """Discharge: ``max_chunks`` chunks of ``chunk_steps``, stopping early (``until_empty``) once
    less than ``empty_mass`` (kg) is left in the silo, or (``steady``) once the flow rate is known."""

    chunk_steps: int
    max_chunks: int
    until_empty: bool
    empty_mass: float
    steady: Optional[SteadyStop] = None


class Outlet(Frozen):
    """Where discharged grains are counted: a horizontal disc of ``radius`` at height ``z`` (m,
    below the orifice plane z = 0)."""

    z: float
    radius: float


class Silo(Frozen):
    """The silo's shape as post-processing and engines need it (m): ``kind`` cylinder, hopper,
    planar (a slab, ``thickness`` deep along y), box or mesh (the user's STL container: ``radius``
    and ``half_width`` the circle about its axis inside its vertical walls, ``outer_radius`` the
    farthest point of its walls); ``half_width`` is the radius or half the width;
    the outlet's centre is at (``outlet_offset``, 0, 0)."""

    kind: Literal[tuple(SILO_KINDS)]       # siloflow.silos.registry
    half_width: float
    height: float                   # of the vertical part
    hopper_height: float            # 0 without a hopper
    outlet_radius: float            # half the outlet width of a slab
    radius: Optional[float] = None
    width: Optional[float] = None
    thickness: Optional[float] = None
    face_friction: Optional[float] = None
    mesh_segments: Optional[int] = None   # facets around a cylinder's circumference
    outlet_offset: float = 0.0            # the outlet's centre at x = outlet_offset (an eccentric outlet)
    periodic_depth: bool = False          # a slab periodic along y over its thickness (no faces)
    depth: Optional[float] = None         # a box's inner extent along y
    outlet: Optional[str] = None          # a box's outlet: rectangle, slot or circle (a mesh silo's: circle or polygon)
    outlet_half_y: Optional[float] = None  # a box's outlet half extent along y (a slot's: half the depth)
    outlet_offset_y: float = 0.0          # a box's (or mesh silo's) outlet centre's y
    outer_radius: Optional[float] = None  # a mesh silo's farthest wall point from the axis (half_width: the nearest)
    section_area: Optional[float] = None       # a mesh silo's vertical walls' cross-section half way up, m2
    section_perimeter: Optional[float] = None  # and its perimeter, m

    @property
    def top(self) -> float:
        return self.hopper_height + self.height

    @property
    def half_depth(self) -> float:
        """Half the extent along y, m."""
        return silo_kind(self.kind).half_depth(self)

    @property
    def hydraulic_diameter(self) -> Optional[float]:
        """A mesh silo's 4 A / P of its vertical walls' cross-section (Janssen's D), m."""
        if self.section_area is None:
            return None
        return 4.0 * self.section_area / self.section_perimeter

    @property
    def reach(self) -> float:
        """Half the extent along x about the axis, m: the half width, or a mesh silo's outer radius."""
        return self.outer_radius if self.outer_radius is not None else self.half_width


class Wall(Frozen):
    """One wall surface, written as ``file`` (STL, m) in the run folder.

    ``role``: ``band`` (a pressure sensor), ``wall`` (side wall not sensed), ``bottom``, ``cone``,
    ``hopper``, ``face`` (a slab's front/back), ``plate`` (the orifice plate), ``insert`` (a user
    mesh) or ``outlet`` (the counting disc, not a wall). A sensor faces ``normal`` (the horizontal
    direction the grains push it) with ``projected_area`` (m2) along it; bands carry their height
    range z0..z1 (m) and, on a cylinder, their angular range theta0..theta1 (rad) and radius."""

    name: str
    role: str
    file: str
    area: float
    n_triangles: int
    band: Optional[int] = None
    sector: Optional[int] = None
    z0: Optional[float] = None
    z1: Optional[float] = None
    theta0: Optional[float] = None
    theta1: Optional[float] = None
    radius: Optional[float] = None
    normal: Optional[tuple[float, float]] = None
    projected_area: Optional[float] = None

    @property
    def is_wall(self) -> bool:
        """Whether grains touch it (the counting disc is not a wall)."""
        return self.role != "outlet"


class Sensors(Frozen):
    """Wall-pressure sensors: ``bands`` heights, each of ``sectors`` sections."""

    bands: int
    sectors: int


class Outputs(Frozen):
    """What the run writes, and how often (steps). Wall forces are averaged over ``sample_steps``
    from ``samples_per_average`` samples ``sample_steps // samples_per_average`` steps apart.
    ``results``: what the case asked for (None: everything its fields ask); ``wall_pressure``:
    the side walls are split into sensor meshes; ``wall_forces``: the walls' forces are sampled
    (wall pressure, the settled bed's force balance)."""

    thermo_every: int
    sample_steps: int
    samples_per_average: int
    dump_every: Optional[int] = None
    vtk: bool = False
    contacts: bool = False          # pair and wall contacts dumped with the particles
    results: Optional[list[str]] = None
    wall_pressure: bool = True
    wall_forces: bool = True


class EngineChoice(Frozen):
    """The case's engine, its MPI ranks, and the case's settings only some engine reads (``options``:
    ``monte_carlo_tries``, the multisphere template's samples of a clump, LIGGGHTS), so that a deck
    writer needs the plan alone. Empty options are left out of plan.json."""

    name: str
    ranks: int
    options: dict[str, int] = {}

    @model_serializer(mode="wrap")
    def _omit_empty_options(self, handler):
        data = handler(self)
        if isinstance(data, dict) and not data.get("options"):
            data.pop("options", None)
        return data


class Profile(Frozen):
    """The numerical profile the run used (``siloflow.profiles``): its settings, and for ``fast``
    the accuracy benchmark's speed-up and 95 % error bounds {quantity: relative bound}, the question
    it was proven for and what the case asks beyond it."""

    name: Literal["custom", "reference", "fast"] = "custom"
    timestep_fraction: float = DEFAULT_TIMESTEP_FRACTION
    stiffness_scale: float = 1.0
    overlap_ratio: Optional[float] = None     # fast: the impact overlap / radius the stiffness was softened to
    speedup: Optional[float] = None
    error_bounds: dict[str, float] = {}
    tolerances: dict[str, float] = {}
    benchmark: str = ""
    question: Optional[str] = None            # fast: the question it was proven for (siloflow.packaged_profile)
    unbounded: list[str] = []                  # fast: benchmarked quantities the case asks that it does not bound
    measured: dict[str, list[float]] = {}     # fast: [relative error, 95 % low, high] measured at it, per quantity


def unbounded_note(unbounded, measured: dict) -> str:
    """What a fast profile leaves unbounded of what a case asks (empty when nothing): each quantity
    with the relative error and 95 % interval the benchmark measured at the profile (``measured``:
    {quantity: [error, low, high]}), and where to get it bounded."""
    if not unbounded:
        return ""
    said = []
    for q in unbounded:
        m = measured.get(q)
        said.append(f"{q} (measured {m[0]:+.1%} [{m[1]:+.1%}, {m[2]:+.1%}] there)" if m else f"{q} (not measured)")
    return ("; not bounded by this profile: " + ", ".join(said)
            + ": for a bounded value run profile reference, or measure this case with siloflow bench")


class Guard(Frozen):
    """The instability guard's limits (``siloflow.guard``), SI. The engine reports, at each thermo
    output, the fastest grain's speed, the deepest pair overlap and the grains outside the walls;
    the run stops when one passes its limit, when the kinetic energy grows by ``energy_growth``
    in a stage without sources, or when a value is not finite."""

    enabled: bool = True
    max_speed: float                 # m/s
    max_overlap: float               # m
    max_overlap_fraction: float      # of the smallest grain radius
    grain_radius: float              # m: the smallest grain radius (not the dust's)
    energy_growth: float
    escape_radius: Optional[float] = None     # m from the axis (cylinder, hopper)
    escape_half_x: Optional[float] = None     # m (planar slab)
    escape_half_y: Optional[float] = None     # m (planar slab)
    escape_z: float                  # m: above it a grain has left through the top


class RunPlan(Frozen):
    """Everything an engine needs to run a case (SI), computed once by ``derive(case)``."""

    plan_version: int = PLAN_VERSION
    siloflow_version: str
    name: str
    engine: EngineChoice
    profile: Optional[Profile] = None          # None: a plan written before profiles existed
    guard: Optional[Guard] = None
    gravity: float                  # m/s2, along -z
    seed: int                       # the case's seed; engines derive theirs from it
    geometry: Silo
    species: list[Species]
    materials: dict[str, Material]  # particle, dust (if any), wall
    contact_model: Literal["hertz", "hooke", "linear"]
    contacts: list[PairParameters]  # every species pair, and each species with the walls (and faces)
    pairs: dict[str, PairParameters]   # particle_particle, particle_wall of the smallest grains
    timestep: TimeStep
    fill: Fill
    settle: Settle
    static_steps: int
    opening: Opening
    discharge: Discharge
    outlet: Outlet
    walls: list[Wall] = []
    sensors: Sensors
    outputs: Outputs
    total_mass: float               # kg of grains and dust
    particle_radius: float          # the largest radius (clumps: bounding sphere), m
    particle_volume: float          # mean volume per grain once the bed has its sizes, m3
    particle_mass: float            # kg
    analysis: Analysis
    design: Optional[DesignSettings] = None      # the EN 1991-4 comparison's bulk solid (post-processing only)
    run_length_fields: dict[str, list[str]] = {}   # stage (and "timestep") -> case fields setting it
    warnings: list[str] = []        # physics warnings, each naming its consequence

    _meshes: Optional[list] = PrivateAttr(default=None)    # the walls' triangles (siloflow.geometry.WallMesh)

    # ---------------------------------------------------------------- views
    @property
    def grains(self) -> list[Species]:
        """The species of the case's particles (size classes or the clump shape)."""
        return [sp for sp in self.species if sp.stream == "grains"]

    @property
    def dust(self) -> Optional[Species]:
        return next((sp for sp in self.species if sp.stream == "dust"), None)

    @property
    def has_clumps(self) -> bool:
        return any(sp.kind == "clump" for sp in self.species)

    @property
    def planar(self) -> bool:
        """A slab (``siloflow.silos.base.SiloKind.slab``)."""
        return silo_kind(self.geometry.kind).slab

    @property
    def dt(self) -> float:
        return self.timestep.dt

    @property
    def expected_atoms(self) -> int:
        """Spheres the fill inserts: every sphere of every clump, and the dust."""
        per_grain = sum(sp.number_fraction * sp.n_spheres for sp in self.grains)
        return round(self.fill.count * per_grain) + self.fill.dust_count

    @property
    def expected_mass(self) -> float:
        """kg the fill inserts: the grains at their number fractions (an expectation where each grain's
        size class is drawn at random), and the dust."""
        grains = self.fill.count * sum(sp.number_fraction * sp.mass for sp in self.grains)
        return float(grains + (self.fill.dust_count * self.dust.mass if self.dust is not None else 0.0))

    def pair(self, a: str, b: str) -> PairParameters:
        """The contact parameters of species ``a`` against ``b`` (a species, ``"wall"`` or ``"faces"``)."""
        for p in self.contacts:
            if (p.a, p.b) in ((a, b), (b, a)):
                return p
        raise KeyError(f"no contact pair {a}-{b} in the plan")

    def planned_steps(self, open_steps: Optional[int] = None) -> dict[str, int]:
        """Upper bound of the steps each stage can take (``open_steps``: an engine's own)."""
        settle = self.settle.chunk_steps * self.settle.max_chunks
        out = {"fill": self.fill.steps, "settle": settle}
        if self.fill.shrink_classes:
            out["shrink"] = settle
        if self.fill.mobilise is not None:
            out["mobilise"] = self.fill.mobilise.steps
            out["resettle"] = settle
        return {**out, "static": self.static_steps,
                "open": self.opening.steps if open_steps is None else open_steps,
                "discharge": self.discharge.chunk_steps * self.discharge.max_chunks}

    @property
    def total_planned_steps(self) -> int:
        return sum(self.planned_steps().values())

    @property
    def meshes(self) -> list:
        """The walls' triangles (``siloflow.geometry.WallMesh``) of a freshly derived plan; a plan read
        back from plan.json has none (``ReadError``): its triangles are the run folder's meshes."""
        if self._meshes is None:
            raise ReadError("this plan was read from plan.json: its wall triangles are in the run folder's meshes/")
        return self._meshes

    # ---------------------------------------------------------------- JSON
    def to_json(self) -> str:
        return self.model_dump_json(indent=1)

    @classmethod
    def from_json(cls, text: str, source: str = "plan.json") -> "RunPlan":
        """Read a plan back, checked (``ReadError`` naming the first bad field)."""
        try:
            plan = cls.model_validate_json(text)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"])
            raise ReadError(f"{source} is not a siloflow run plan ({where}: {first['msg']}); "
                            "was the folder rendered by another siloflow version?") from None
        if plan.plan_version != PLAN_VERSION:
            raise ReadError(f"{source} is a plan of version {plan.plan_version}; this siloflow reads version "
                            f"{PLAN_VERSION}: render the case anew")
        return plan
