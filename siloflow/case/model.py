"""The whole case: every section together and the checks across them."""
from __future__ import annotations

import math
from typing import Optional

from pydantic import Field, model_validator

from ..packaged_profile import packaged_fast_profile
from ..silos.registry import silo_kind
from .analysis import Analysis, DesignSettings, WallInsert
from .engine_settings import EngineSettings
from .fields import MIN_GRAVITY, Int, Positive, SafeName, Strict
from .geometry import MAX_HOPPER_HEIGHT, MAX_WALL_HEIGHT, Geometry, WallSensors
from .materials import Materials, _contact_problems
from .outputs import RESULTS, Outputs
from .particles import Particles
from .stages import Discharge, Fill, Settle

STATIC_WINDOW_SAMPLES = 20


def default_static_window(sample_interval: float, check_interval: float) -> float:
    """The static window (s) when the case sets none: ``STATIC_WINDOW_SAMPLES`` wall-force samples
    of ``sample_interval`` (s), and at least two settling checks of ``check_interval`` (s), the
    time over which the bed was judged settled."""
    return max(STATIC_WINDOW_SAMPLES * sample_interval, 2 * check_interval)


def _with_static_window(data):
    """The raw case ``data`` with ``fill.settle.static_window`` set to its default if it is not
    given (a copy; anything malformed is left for validation to name)."""
    if not isinstance(data, dict) or not isinstance(data.get("fill"), dict):
        return data
    fill = dict(data["fill"])
    settle = fill.get("settle", {})
    if not isinstance(settle, dict) or settle.get("static_window") is not None:
        return data
    outputs = data.get("outputs", {})
    sample = outputs.get("sample_interval") if isinstance(outputs, dict) else None
    sample = sample if sample is not None else Outputs.model_fields["sample_interval"].default
    check = settle.get("check_interval", Settle.model_fields["check_interval"].default)
    if isinstance(sample, bool) or isinstance(check, bool) or not all(
            isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (sample, check)):
        return data
    fill["settle"] = {**settle, "static_window": min(default_static_window(float(sample), float(check)), 100.0)}
    return {**data, "fill": fill}


def _with_fast_profile(data):
    """A case asking for ``engine.profile: fast`` without a pinned one gets the packaged profile
    proven for what its ``outputs.results`` ask (``siloflow.packaged_profile.choose_profile``); a
    results list the schema will refuse picks none here (the schema names the field)."""
    if not isinstance(data, dict):
        return data
    engine, outputs = data.get("engine"), data.get("outputs")
    if not isinstance(engine, dict) or engine.get("profile") != "fast" or engine.get("fast_profile") is not None:
        return data
    results = outputs.get("results") if isinstance(outputs, dict) else None
    if results is not None and not (isinstance(results, list) and all(r in RESULTS for r in results)):
        return data
    return {**data, "engine": {**engine, "fast_profile": packaged_fast_profile(results)}}


class Case(Strict):
    """A complete, validated silo case (``Case.from_yaml(path)``, ``Case.model_validate(dict)``)."""

    @model_validator(mode="before")
    @classmethod
    def _default_static_window(cls, data):
        return _with_fast_profile(_with_static_window(data))

    @classmethod
    def from_yaml(cls, path) -> "Case":
        """Read and validate a YAML case file (``siloflow.case_file.load_case``, read by
        ``siloflow.case_reader``); ``CaseError`` lists every problem with its field path."""
        from ..case_reader import read_case
        return read_case(Case, path)

    def with_changes(self, changes: dict) -> "Case":
        """A new case: this one with ``changes`` ({dotted field path: value}, e.g.
        ``{"geometry.orifice_radius": 0.006, "fill.count": 500}``) applied, validated again whole:
        every field's and every cross-section check runs, as for a case file. A value may be a
        plain value, a dict (a whole section) or a section's model. The case is frozen and
        ``model_copy(update=...)`` would skip validation; this does not. A change that the schema
        refuses (an unknown field, a value out of range, a section that no longer fits another)
        raises ``CaseError`` naming each field with its problem; nothing else is changed."""
        from pydantic import BaseModel

        from ..case_reader import validate_case
        from ..errors import CaseError
        if not isinstance(changes, dict):
            raise CaseError([("(changes)", f"give a dict of dotted field paths and values, not "
                                           f"{type(changes).__name__}")], "Case.with_changes")
        data = self.model_dump(mode="json", exclude_unset=True)   # the case as given: defaults re-derived
        settle = self.fill.settle
        timing = {"outputs", "outputs.sample_interval", "fill", "fill.settle", "fill.settle.check_interval"}
        if settle.static_window == min(default_static_window(self.outputs.sample_interval, settle.check_interval),
                                       100.0) and timing & set(changes) and not {
                "fill", "fill.settle", "fill.settle.static_window"} & set(changes):
            data["fill"]["settle"].pop("static_window", None)   # the default static window follows its intervals
        for path, value in changes.items():
            _set_path(data, path, value.model_dump(mode="json", exclude_unset=True)
                      if isinstance(value, BaseModel) else value)
        return validate_case(Case, data, "Case.with_changes")

    name: SafeName
    description: str = Field("", max_length=2000, description="free text, never written into a deck")
    gravity: Positive = Field(9.81, ge=MIN_GRAVITY, le=1000, description="m/s2, acting along -z")
    geometry: Geometry
    sensors: WallSensors
    materials: Materials
    particles: Particles
    fill: Fill
    discharge: Discharge
    outputs: Outputs = Outputs()
    engine: EngineSettings = EngineSettings()
    analysis: Analysis = Analysis()
    inserts: list[WallInsert] = Field(default_factory=list, max_length=20,
                                      description="extra walls from STL files (inserts, baffles)")
    seed: Int = Field(12345, ge=0, le=2**31 - 1)
    design: Optional[DesignSettings] = Field(None, description="EN 1991-4 design loads' bulk solid "
                                             "(siloflow design); post-processing only")

    @model_validator(mode="after")
    def _consistent(self):
        g, p, f = self.geometry, self.particles, self.fill
        problems = []
        problems += _particle_problems(self)
        d = 2 * p.max_radius
        field = {"spheres": "particles.radius", "clumps": "particles.length"}.get(p.kind, "particles.radii")
        if p.max_radius >= g.outlet_radius:
            problems.append(f"{field} ({p.max_radius:.6g} m) must be smaller than the outlet's half width "
                            f"({g.outlet_radius} m, {_outlet_fields(g)}): nothing could leave")
        kind = silo_kind(g.kind)
        problems += kind.particle_problems(g, p)
        if f.mobilise is not None and not kind.mobile_floor:
            problems.append(f"fill.mobilise lowers a flat floor: it needs geometry.kind cylinder, not {g.kind} "
                            "(a hopper or slab floor cannot move down without opening a gap at its walls)")
        zmin, zmax = f.insertion_z_min, f.insertion_z_max
        if zmin is not None and zmax is not None and zmax - zmin < 2 * d:
            problems.append("fill.insertion_z_max must exceed insertion_z_min by 2 particle diameters")
        if not kind.reads_files or g.measured:      # a mesh silo's size is known once its files are read
            problems += shape_problems(self)
        names = [i.name for i in self.inserts]
        if len(set(names)) != len(names):
            problems.append("inserts: names must be unique")
        problems += _sampling_problems(self)
        if problems:
            raise ValueError("; ".join(problems))
        return self


def _wall_height_field(g) -> str:
    """The field that sets a geometry's vertical wall height, for messages."""
    return silo_kind(g.kind).wall_height_field(g)


def _outlet_fields(g) -> str:
    """The fields that size a geometry's outlet, for messages."""
    return silo_kind(g.kind).outlet_fields(g)


def shape_problems(case: "Case") -> list[str]:
    """The checks that need the silo's size (its half width, hopper and wall heights): of a mesh
    silo, once its files are read (``siloflow.derived.measured``)."""
    g, p, f = case.geometry, case.particles, case.fill
    d = 2 * p.max_radius
    field = {"spheres": "particles.radius", "clumps": "particles.length"}.get(p.kind, "particles.radii")
    problems = []
    if silo_kind(g.kind).reads_files and (g.height > MAX_WALL_HEIGHT or g.hopper_height > MAX_HOPPER_HEIGHT):
        problems.append(f"geometry.scale ({g.scale:g}) makes the walls of geometry.files {g.height:.4g} m tall above a "
                        f"floor or hopper {g.hopper_height:.4g} m tall: at most {MAX_WALL_HEIGHT:g} m and "
                        f"{MAX_HOPPER_HEIGHT:g} m, as a cylinder's (is the scale right? 0.001 for mm)")
    if 3 * d > g.half_width:
        problems.append(f"{field} ({p.max_radius:.6g} m) is too large for a silo of half width "
                        f"{g.half_width:.6g} m (need >= 3 particle diameters)")
    top = g.hopper_height + g.height
    if f.height is not None and f.height >= top:
        problems.append(f"fill.height ({f.height} m) must be below the top of the silo ({top:.6g} m: the hopper and "
                        f"{_wall_height_field(g)})")
    zmin, zmax = f.insertion_z_min, f.insertion_z_max
    if zmax is not None and zmax > top:
        problems.append(f"fill.insertion_z_max ({zmax} m) is above the top of the silo ({top:.6g} m)")
    if zmin is not None and zmin < g.hopper_height:
        problems.append(f"fill.insertion_z_min ({zmin} m) must be above the hopper "
                        f"({g.hopper_height:.6g} m)")
    if f.pour_radius is not None and not 2 * d <= f.pour_radius <= g.half_width:
        problems.append(f"fill.pour_radius ({f.pour_radius} m) must be between two grain diameters "
                        f"({2 * d:.6g} m) and the silo's half width ({g.half_width:.6g} m)")
    # (a mesh silo's height holds its STL's float32 rounding: 1e-6 of it is not above)
    if case.sensors.heights is not None and case.sensors.heights[-1] > g.height * (1 + 1e-6):
        problems.append(f"sensors.heights: last boundary ({case.sensors.heights[-1]} m) is above "
                        f"the vertical wall ({_wall_height_field(g)}, {g.height:.6g} m)")
    return problems


def _set_path(data: dict, path, value) -> None:
    """Set ``value`` at the dotted ``path`` of the case dict ``data`` (missing sections made);
    ``CaseError`` when the path is not a dotted name or runs through a value that is not a section."""
    from ..errors import CaseError
    keys = path.split(".") if isinstance(path, str) else []
    if not keys or not all(keys):
        raise CaseError([(str(path), "not a dotted field path such as geometry.orifice_radius")], "Case.with_changes")
    node = data
    for depth, key in enumerate(keys[:-1]):
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            raise CaseError([(".".join(keys[:depth + 1]), f"is a {type(node).__name__}, not a section: "
                                                          f"{path} cannot be set inside it")], "Case.with_changes")
    node[keys[-1]] = value


def _sampling_problems(case: "Case") -> list[str]:
    """The sample interval must fit the stages it measures: the discharge (flow rate, dynamic
    wall loads) and the static window (post-processing averages only samples taken wholly inside
    it, which needs two intervals)."""
    si, dis, static = case.outputs.sample_interval, case.discharge, case.fill.settle.static_window
    field, t_dis = ("discharge.duration", dis.duration) if dis.duration is not None else \
        ("discharge.max_time", dis.max_time)
    problems = []
    if si > t_dis:
        problems.append(f"outputs.sample_interval ({si} s) is longer than the discharge ({field} {t_dis} s): "
                        "no sample of the flow or the dynamic wall loads would be written")
    if static < 2 * si:
        problems.append(f"fill.settle.static_window ({static} s) must be at least two "
                        f"outputs.sample_interval (2 x {si} s): the static wall loads are averaged over "
                        "samples taken wholly inside the window")
    return problems


def _particle_problems(case: "Case") -> list[str]:
    """Cross-section checks of the particles: dust contact laws and sizes."""
    p, model = case.particles, case.materials.model
    problems = []
    dust = getattr(p, "dust", None)
    if dust is not None:
        for name in ("dust_dust", "dust_particle", "dust_wall"):
            problems += _contact_problems(model, f"particles.dust.{name}", getattr(dust, name))
        if model != "linear" and dust.youngs_modulus is None:
            problems.append(f"particles.dust.youngs_modulus is required by model '{model}'")
        if dust.radius >= p.min_radius:
            problems.append(f"particles.dust.radius ({dust.radius} m) must be smaller than the grains "
                            f"({p.min_radius} m)")
    return problems                 # what an engine cannot do is its own check: Engine.check
