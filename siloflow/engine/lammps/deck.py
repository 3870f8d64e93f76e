"""Write a run plan as a LAMMPS deck: ``in.lammps`` (template ``templates/lammps/in.lammps.j2``), the
walls' STL meshes under ``meshes/`` (for ParaView and for the sensors' extents), and the dump layout.

The deck is a list of named sections (``# SILOFLOW_SECTION name``) which siloflow's driver
(:mod:`.driver`) runs in order; the stages' loops, the insertion and the outlet counting are the
driver's. The walls are LAMMPS regions, one ``fix wall/gran/region`` per wall and group of species
sharing its contact parameters:

- cylinder: the side wall (a cylinder open at both ends), the floor (the plane z = 0 joined with a
  large sphere whose cap is exactly the orifice: a union region keeps only the plane's annulus, as
  LAMMPS' ``RegUnion::surface_interior`` drops contact points inside another closed sub-region); an
  eccentric orifice (``geometry.outlet_offset``) moves the sphere, the orifice's edge and the plate;
- conical hopper: the side wall and a cone open at both ends from the orifice to the wall;
- slab: the two vertical walls (a block open along y and z), the front and back faces (a block open
  along x and z), and each inclined hopper wall as a plane joined with the half-space z < 0 (so the
  plane ends at the orifice's edge); a flat floor (``half_angle_deg: 90``) is a block either side of
  the slot, touched from outside; an offset slot (``outlet_offset``) moves the edges, rim and plate;
- the orifice's edge: LAMMPS' union drops the edges where faces meet, and without the orifice's edge
  a grain whose centre is over the orifice falls through whatever it overlaps (measured: the flow
  rate 49 % above LIGGGHTS'). The edge is the side of a vanishingly thin cylinder (slab: block)
  in the orifice, open at both ends, touched from outside: its nearest point to a grain above is
  the edge;
- the orifice plate: a solid disc (slab: a block) under the orifice, grains on its outside, moved
  down at the opening speed through ``travel`` and then removed;
- a mobilised fill (``fill.mobilise``, flat-bottomed cylinders only): the floor's regions (the plane,
  the orifice's sphere and edge) and the closed plate go down by ``drop`` in :func:`mobilise_jumps`
  equal jumps over the stage's steps, each region deleted and defined again lower
  (:func:`floor_commands`), static, under the same wall fixes (the floor's union finds its
  sub-regions again by name): their forces are sampled as before, and the plate opens from the
  lowered floor. Moving the sub-regions with ``move`` instead would leave the union's wall
  velocity unset (``RegUnion::set_velocity`` sets its sub-regions', and the contacts read the
  union's own: measured on 22 Jul 2025, a grain on a union floor whose sub-regions slid sideways at
  1 cm/s was not dragged, and took the union's uninitialised velocity, 5e-321 m/s).

Every value passes the deck filters; the rendered deck may only hold :data:`ALLOWED_COMMANDS`.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import numpy as np

from ...atomic_files import write_text
from ...deck import DeckError, _num, _safe_name, check_commands, template_environment
from ...engines import ENGINE_FILES
from ...geometry import write_stl
from ...plan import FACES, WALL, RunPlan
from ...run_folder import RESTART_FILE, DumpLayout, RunFolder
from ...silos.base import resolve
from ...silos.registry import silo_kind
from .contact_law import CLASSIC_STYLE, classic_args, pair_coeff_args, wall_args

DECK_NAME = "in.lammps"
LOG_NAME = ENGINE_FILES["lammps"].names["log"]
RESUME_LOG_NAME = ENGINE_FILES["lammps"].names["resume_log"]

#: The only commands a siloflow LAMMPS deck may contain (no shell, python, include, ...).
ALLOWED_COMMANDS = frozenset("""
atom_style atom_modify boundary newton comm_modify units processors region create_box read_restart
neighbor neigh_modify pair_style pair_coeff timestep fix group variable thermo_style thermo thermo_modify
dump dump_modify set write_restart delete_atoms unfix molecule compute
""".split())

#: the deck's compute of the lowest atom's height (m): the driver gathers the atoms after a chunk only
#: when a check needs them, or when one may have passed the outlet
LOWEST_Z = "siloflow_zmin"
#: what the deck's ``rigid/local`` compute reports of the clumps' bodies (kg, kg m2)
BODY_QUANTITIES = ("mass", "inertiax", "inertiay", "inertiaz")
_SECTION = re.compile(r"^# SILOFLOW_SECTION (\w+)\s*$")
#: how far below z = 0 the centre of the floor's orifice sphere lies, in silo heights: far enough
#: that its surface below the floor is out of the grains' reach, and its cap is the orifice
HOLE_SPHERE_DEPTH = 10.0
#: the orifice edge's cylinder (or block) height, in grain diameters: grains whose centre is inside it
#: (for a step or two as they fall through) see no edge
RIM_THICKNESS = 1e-6


#: what no line of a siloflow LAMMPS deck holds: quotes and backticks (LAMMPS' own quoting, and the
#: shell of compressed dumps' popen), absolute paths and parent folders (every file is the run folder's)
UNSAFE_TEXT = re.compile(r"[\"'`]|(^|\s)/|\.\.")


def check_deck(text: str) -> None:
    """Refuse a rendered LAMMPS deck holding a command siloflow does not write, a quote, or a path
    leaving the run folder (``DeckError``)."""
    check_commands(text, ALLOWED_COMMANDS)
    for lineno, line in enumerate(text.splitlines(), 1):
        if line.strip() and not line.lstrip().startswith("#") and UNSAFE_TEXT.search(line):
            raise DeckError(f"rendered deck line {lineno} is not allowed: {line.strip()[:120]!r}")


def sections(text: str) -> dict[str, list[str]]:
    """The deck's named sections: name -> its command lines (comments and blank lines dropped)."""
    out: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        m = _SECTION.match(line)
        if m:
            current = out.setdefault(m.group(1), [])
            continue
        stripped = line.strip()
        if current is not None and stripped and not stripped.startswith("#"):
            current.append(stripped)
    return out


@dataclass(frozen=True)
class LammpsWall:
    """One wall surface as LAMMPS regions (the wall fix uses the last of ``regions``); ``kind``
    names which of the plan's walls it carries (see :func:`wall_kind`)."""

    kind: str
    regions: list = field(default_factory=list)     # [(id, style, [args])]
    partner: str = WALL                              # "wall" or "faces": whose contact parameters
    plate: bool = False

    @property
    def region(self) -> str:
        """The region the wall fix uses."""
        return self.regions[-1][0]


def hopper_face(rid: str, point, normal) -> LammpsWall:
    """An inclined hopper wall: the plane through ``point`` (m, on the outlet's edge at z = 0) with
    ``normal`` (into the silo), joined with the half-space z < 0 so that it ends at the outlet."""
    return LammpsWall("hopper", [
        (f"{rid}_plane", "plane", [_n(point[0]), _n(point[1]), _n(0.0), _n(normal[0]), _n(normal[1]), _n(normal[2])]),
        (f"{rid}_below", "plane", [_n(0.0), _n(0.0), _n(0.0), _n(0.0), _n(0.0), _n(-1.0)]),
        (rid, "union", ["2", f"{rid}_plane", f"{rid}_below"])])


def round_hole(x: float, y: float, radius: float, top: float, d: float, floor_dz: float = 0.0,
               rim_kind: str = "bottom") -> list[LammpsWall]:
    """A flat floor at z = ``floor_dz`` with a circular hole of ``radius`` at (x, y) (m): the plane
    joined with a sphere far below whose cap is the hole, and the hole's edge (the side of a
    vanishingly thin cylinder, touched from outside; ``rim_kind`` the wall carrying it). ``top``:
    the silo's top, which sets how deep the sphere lies; ``d`` a grain diameter."""
    depth = HOLE_SPHERE_DEPTH * top
    return [LammpsWall("bottom", [
                ("bottom_plane", "plane", [_n(0.0), _n(0.0), _n(floor_dz), _n(0.0), _n(0.0), _n(1.0)]),
                # the sphere's cap at the floor is the hole whatever the floor's height: its centre moves
                # with the floor, its radius stays
                ("bottom_hole", "sphere", [_n(x), _n(y), _n(floor_dz - depth),
                                           _n(math.sqrt(depth * depth + radius * radius))]),
                ("bottom", "union", ["2", "bottom_plane", "bottom_hole"])]),
            rim(rim_kind, x, y, radius, d, floor_dz)]


def rim(kind: str, x: float, y: float, radius: float, d: float, z: float = 0.0) -> LammpsWall:
    """A round outlet's edge at height ``z`` (a union keeps faces, not the edges where they meet): the
    side of a vanishingly thin cylinder in the outlet, open above and below, touched from outside."""
    return LammpsWall(kind, [("rim", "cylinder", ["z", _n(x), _n(y), _n(radius), _n(z - RIM_THICKNESS * d), _n(z),
                                                  "open", "1", "open", "2", "side", "out"])])


def round_plate(x: float, y: float, radius: float, thick: float, floor_dz: float = 0.0) -> LammpsWall:
    """The plate closing a round outlet at (x, y): a solid disc ``thick`` (m) under the floor at
    z = ``floor_dz``, grains on its outside."""
    return LammpsWall("plate", [("plate", "cylinder", ["z", _n(x), _n(y), _n(radius), _n(floor_dz - thick),
                                                       _n(floor_dz), "side", "out"])], plate=True)


def wall_kind(role: str) -> str:
    """The LAMMPS wall carrying a plan wall of ``role`` (sensor pieces of one surface share it)."""
    return {"band": "side", "wall": "side", "cone": "hopper", "hopper": "hopper", "bottom": "bottom",
            "plate": "plate", "face": "faces"}[role]


def _n(x: float) -> str:
    """A region number, exactly as Python holds it (the floor's sphere needs every digit)."""
    _num(float(x))                      # refuses a non-finite value
    return repr(float(x))


def walls(plan: RunPlan, floor_dz: float = 0.0) -> list[LammpsWall]:
    """The plan's silo as LAMMPS region walls (see the module docstring), built by its kind's
    ``lammps_walls`` (``siloflow.silos``); ``floor_dz``: the flat floor's regions and the plate
    lowered by that much (m, negative down: ``fill.mobilise``)."""
    kind = silo_kind(plan.geometry.kind)
    if not kind.lammps_walls:
        raise ValueError(f"LAMMPS has no region walls for a silo of kind {kind.name} (Engine.check refuses it)")
    return resolve(kind.lammps_walls)(plan, floor_dz)


def slab_walls(plan: RunPlan, floor_dz: float = 0.0) -> list[LammpsWall]:
    """A slab's walls (:func:`walls`): the side walls, the faces, the wedge's planes or a flat floor
    either side of the slot, the slot's edges and the plate."""
    g = plan.geometry
    R, hh, top, ro = g.half_width, g.hopper_height, g.top, g.outlet_radius
    d, thick = _sizes(plan)
    out = []
    if floor_dz:
        raise ValueError("a slab's floor does not move (fill.mobilise needs a flat-bottomed cylinder)")
    half_y = g.half_depth
    out.append(LammpsWall("side", [("side", "block", [_n(-R), _n(R), _n(-half_y - d), _n(half_y + d),
                                                           _n(hh), _n(top), "open", "3", "open", "4",
                                                           "open", "5", "open", "6"])]))
    # the faces go on below the orifice to the box's floor: a falling grain stays in the slab
    floor = plan.outlet.z - plan.opening.travel - 10 * d
    if not g.periodic_depth:                      # periodic along y: no faces
        out.append(LammpsWall("faces", [("faces", "block", [_n(-R - d), _n(R + d), _n(-half_y), _n(half_y),
                                                                  _n(floor), _n(top), "open", "1", "open", "2",
                                                                  "open", "5", "open", "6"])], partner=FACES))
    ex = g.outlet_offset                          # the slot's centre at x = ex
    if hh == 0:
        # a flat floor: a block either side of the slot, grains outside; its top is the floor and
        # its face at the slot the slot's edge (a block's outside has its edges: no rim needed)
        for side, lo, hi in (("left", -R - d, ex - ro), ("right", ex + ro, R + d)):
            out.append(LammpsWall("bottom", [(f"floor_{side}", "block", [
                _n(lo), _n(hi), _n(-half_y - d), _n(half_y + d), _n(-thick), _n(0.0), "side", "out"])]))
    for side, sign in (("left", -1.0), ("right", 1.0)) if hh > 0 else ():
        rid = f"hopper_{side}"
        edge = ex + sign * ro                       # the slot's edge on this side
        run = R - sign * ex - ro                    # from it to the side wall's foot, along x
        length = math.hypot(run, hh)
        nx, nz = hh / length, run / length          # the wall's normal into the silo: (-sign nx, 0, nz)
        out.append(hopper_face(rid, (edge, 0.0), (-sign * nx, 0.0, nz)))
    if hh > 0:
        # the orifice's edges (a union keeps faces, not the edges where they meet): the two sides of a
        # vanishingly thin block across the orifice, open above and below, touched from outside
        out.append(LammpsWall("hopper", [("rim", "block", [_n(ex - ro), _n(ex + ro), _n(-half_y - d),
                                                               _n(half_y + d), _n(-RIM_THICKNESS * d), _n(0.0),
                                                               "open", "3", "open", "4", "open", "5", "open", "6",
                                                               "side", "out"])]))
    out.append(LammpsWall("plate", [("plate", "block", [_n(ex - ro), _n(ex + ro), _n(-half_y - d), _n(half_y + d),
                                                              _n(-thick), _n(0.0), "side", "out"])], plate=True))
    return out


def _sizes(plan: RunPlan) -> tuple[float, float]:
    """A grain diameter and the plate's thickness (two diameters), m."""
    d = 2 * plan.particle_radius
    return d, 2 * d


def box_region_walls(plan: RunPlan, floor_dz: float = 0.0) -> list[LammpsWall]:
    """A box's walls (:func:`walls`, :func:`box_walls`); its floor does not move."""
    if floor_dz:
        raise ValueError("a box's floor does not move (fill.mobilise needs a flat-bottomed cylinder)")
    return box_walls(plan.geometry, *_sizes(plan))


def round_side(plan: RunPlan) -> LammpsWall:
    """A round silo's side wall: a cylinder open at both ends from the hopper's top to the top."""
    g = plan.geometry
    return LammpsWall("side", [("side", "cylinder", ["z", _n(0.0), _n(0.0), _n(g.half_width), _n(g.hopper_height),
                                                     _n(g.top), "open", "1", "open", "2"])])


def cylinder_walls(plan: RunPlan, floor_dz: float = 0.0) -> list[LammpsWall]:
    """A cylinder's walls (:func:`walls`): the side wall, the floor with its round hole and edge at
    (``outlet_offset``, 0), the plate; the floor and plate lowered by ``floor_dz`` (m)."""
    g = plan.geometry
    d, thick = _sizes(plan)
    ex = g.outlet_offset                            # the orifice's centre at (ex, 0)
    return ([round_side(plan)] + round_hole(ex, 0.0, g.outlet_radius, g.top, d, floor_dz)
            + [round_plate(ex, 0.0, g.outlet_radius, thick, floor_dz)])


def hopper_walls(plan: RunPlan, floor_dz: float = 0.0) -> list[LammpsWall]:
    """A hopper's walls (:func:`walls`): the side wall, a right cone open at both ends from the outlet
    to the wall, the outlet's edge and the plate; its outlet neither moves nor lies off the axis."""
    g = plan.geometry
    R, hh, ro = g.half_width, g.hopper_height, g.outlet_radius
    d, thick = _sizes(plan)
    ex = g.outlet_offset
    if floor_dz:
        raise ValueError("a hopper's outlet does not move (fill.mobilise needs a flat-bottomed cylinder)")
    if ex:
        raise ValueError("LAMMPS' cone region is a right cone: no eccentric hopper outlet (Engine.check refuses it)")
    return [round_side(plan),
            LammpsWall("hopper", [("cone", "cone", ["z", _n(0.0), _n(0.0), _n(ro), _n(R), _n(0.0),
                                                    _n(hh), "open", "1", "open", "2"])]),
            rim("hopper", ex, 0.0, ro, d), round_plate(ex, 0.0, ro, thick, floor_dz)]


def box_walls(g, d: float, thick: float) -> list[LammpsWall]:
    """A rectangular silo's walls (``g``: the plan's box, ``d`` a grain diameter, ``thick`` the
    plate's thickness, m): the four vertical walls (a block open at top and bottom); a hopper's faces
    (each a plane through an outlet edge joined with z < 0, so that it ends at the outlet; a slot's
    end walls a block open along x, z); or a flat floor around the outlet (blocks beside a rectangle
    or slot, touched from outside; around a circle the plane z = 0 joined with a sphere whose cap is
    the circle, and the circle's edge); the orifice's edge and the plate."""
    a, b, hh, top = g.half_width, 0.5 * g.depth, g.hopper_height, g.top
    ex, ey, hx, hy = g.outlet_offset, g.outlet_offset_y, g.outlet_radius, g.outlet_half_y
    x0, x1, y0, y1 = ex - hx, ex + hx, ey - hy, ey + hy
    out = [LammpsWall("side", [("side", "block", [_n(-a), _n(a), _n(-b), _n(b), _n(hh), _n(top),
                                                  "open", "5", "open", "6"])])]
    if hh > 0:
        # face through the outlet edge (px, py) at z = 0, rising to the wall at u = -a, a (x) or -b, b (y)
        faces = [("xlo", (1.0, 0.0), x0, -a), ("xhi", (-1.0, 0.0), x1, a)]
        if g.outlet != "slot":
            faces += [("ylo", (0.0, 1.0), y0, -b), ("yhi", (0.0, -1.0), y1, b)]
        for name, (ux, uy), edge, wall in faces:
            run = abs(wall - edge)
            length = math.hypot(run, hh)
            out.append(hopper_face(f"hopper_{name}", (edge, 0.0) if ux else (0.0, edge),
                                   (ux * hh / length, uy * hh / length, run / length)))     # normal into the silo
        out.append(LammpsWall("hopper", [("rim", "block", [_n(x0), _n(x1), _n(y0), _n(y1), _n(-RIM_THICKNESS * d),
                                                           _n(0.0), "open", "5", "open", "6", "side", "out"])]))
    elif g.outlet == "circle":
        out += round_hole(ex, ey, hx, top, d)
    else:
        strips = [("floor_xlo", -a - d, x0, -b - d, b + d), ("floor_xhi", x1, a + d, -b - d, b + d)]
        if g.outlet != "slot":            # a slot spans the depth: nothing before or behind it
            strips += [("floor_ylo", x0, x1, -b - d, y0), ("floor_yhi", x0, x1, y1, b + d)]
        for rid, xa, xb, ya, yb in strips:          # each reaches a diameter past the walls: none is empty
            out.append(LammpsWall("bottom", [(rid, "block", [_n(xa), _n(xb), _n(ya), _n(yb), _n(-thick), _n(0.0),
                                                             "side", "out"])]))
    if g.outlet == "slot":              # a slot's end walls: the wedge's, on below the floor (a grain falls between them)
        out.append(LammpsWall("hopper", [("slot_ends", "block", [              # the plan's slot_end_* walls
            _n(-a - d), _n(a + d), _n(-b), _n(b), _n(-10 * d), _n(hh), "open", "1", "open", "2", "open", "5",
            "open", "6"])]))
    if g.outlet == "circle":
        out.append(round_plate(ex, ey, hx, thick))
    else:
        past = d if g.outlet == "slot" else 0          # a slot's plate reaches into its end walls
        out.append(LammpsWall("plate", [("plate", "block", [_n(x0), _n(x1), _n(y0 - past), _n(y1 + past), _n(-thick),
                                                            _n(0.0), "side", "out"])], plate=True))
    return out


#: the most steps between two of the mobilising floor's jumps, and the most jumps
MOBILISE_JUMP_STEPS = 10
MOBILISE_MAX_JUMPS = 200


def mobilise_jumps(steps: int) -> int:
    """In how many equal jumps the floor goes down over the mobilising stage's ``steps``: one every
    :data:`MOBILISE_JUMP_STEPS` steps (a fraction of a contact's duration at siloflow's time steps:
    a jump is that many steps' travel at the planned speed), and at most :data:`MOBILISE_MAX_JUMPS`
    (then a jump is 1/200 of the drop, at most 1/800 of a diameter)."""
    return max(1, min(MOBILISE_MAX_JUMPS, math.ceil(steps / MOBILISE_JUMP_STEPS)))


def region_command(rid: str, style: str, args: list, moving: bool = False) -> str:
    """The ``region`` command of one wall region (``moving``: the plate, displaced by ``v_plate_dz``),
    as the deck holds it and as the driver issues it when it lowers the floor."""
    return (f"region          {_safe_name(rid)} {_safe_name(style)}" + "".join(f" {a}" for a in args)
            + (" move NULL NULL v_plate_dz" if moving else "") + " units box")


def floor_commands(plan: RunPlan, floor_dz: float) -> list[str]:
    """The commands that put the flat floor's regions (plane, orifice sphere, edge) and the closed
    plate ``floor_dz`` (m) below their place: each deleted and defined anew, static (the plate keeps
    its opening motion ``v_plate_dz``, still 0); the floor's union is left as it is, it finds its
    sub-regions by name when the next run starts (which must set up: the driver's chunks do)."""
    out = []
    for w in walls(plan, floor_dz):
        if w.kind not in ("bottom", "plate"):
            continue
        for rid, style, args in w.regions:
            if style != "union":
                out += [f"region {rid} delete", region_command(rid, style, args, w.plate and rid == w.region)]
    return out


def box(plan: RunPlan, count_every: int) -> dict:
    """The simulation box (m): the silo with two diameters to spare, the plate's travel below, and
    room for the fastest grain to fall for ``count_every`` steps past the counting plane before the
    driver deletes it."""
    g = plan.geometry
    d = 2 * plan.particle_radius
    fall = math.sqrt(plan.fill.insertion_speed ** 2 + 2 * plan.gravity * (g.top - plan.outlet.z))
    lowered = plan.fill.mobilise.drop if plan.fill.mobilise is not None else 0.0     # the plate opens from there
    below = lowered + plan.opening.travel + 2 * d + fall * count_every * plan.dt + 4 * d
    half_y = g.half_depth
    y_margin = 0.0 if g.periodic_depth else 2 * d          # a periodic slab's box is its periodic length
    return {"xlo": -g.half_width - 2 * d, "xhi": g.half_width + 2 * d, "ylo": -half_y - y_margin,
            "yhi": half_y + y_margin, "zlo": plan.outlet.z - below, "zhi": g.top + 2 * d}


def count_every(plan: RunPlan) -> int:
    """The most steps between two of the driver's looks at the run (outlet counting, wall-force
    samples, guard): it looks at every wall-force sample and thermo output."""
    out = plan.outputs
    return max(1, min(out.sample_steps // out.samples_per_average, out.thermo_every))


def species_groups(plan: RunPlan, partner: str) -> list[tuple[str, list[int], str]]:
    """(group, atom types, wall contact text) of the species sharing one set of contact parameters
    against ``partner`` (``"wall"`` or ``"faces"``): one wall fix per group and wall."""
    by_args: dict[str, list[int]] = {}
    for k, sp in enumerate(plan.species):
        by_args.setdefault(wall_args(plan, plan.pair(sp.name, partner)), []).append(k + 1)
    if len(by_args) == 1:
        return [("all", list(range(1, len(plan.species) + 1)), next(iter(by_args)))]
    return [(f"{partner}_group{n + 1}", types, args) for n, (args, types) in enumerate(by_args.items())]


def poured_species(plan: RunPlan) -> int:
    """The index of the species paper B's fill pours (the largest grain), to shrink after settling."""
    return max((k for k, sp in enumerate(plan.species) if sp.stream == "grains"), key=lambda k: plan.species[k].radius)


def clump_spheres(plan: RunPlan, species_index: int) -> tuple[np.ndarray, np.ndarray]:
    """A clump species' sphere centres (n, 3) and radii (n,) in its body frame, m."""
    spheres = np.array(plan.species[species_index].spheres, float)
    return spheres[:, :3], spheres[:, 3]


def deck_context(plan: RunPlan) -> dict:
    """Everything the LAMMPS template places, already computed and checked."""
    f = plan.fill
    pairs = []
    for i, a in enumerate(plan.species):
        for j, b in enumerate(plan.species[i:], start=i):
            p = plan.pair(a.name, b.name)
            pairs.append({"i": i + 1, "j": j + 1, "args": pair_coeff_args(plan, p),
                          "args_fill": pair_coeff_args(plan, p, frictionless=f.frictionless)})
    n_types = len(plan.species)
    if f.shrink_classes:
        # one more atom type marks the grains being assigned a size class while shrinking (as the
        # LIGGGHTS deck uses its wall type); no step runs with it, but LAMMPS wants its coefficients
        n_types += 1
        poured = plan.species[poured_species(plan)]
        for i, a in enumerate(plan.species + [poured]):
            p = plan.pair(a.name, poured.name)
            pairs.append({"i": i + 1, "j": n_types, "args": pair_coeff_args(plan, p),
                          "args_fill": pair_coeff_args(plan, p, frictionless=f.frictionless)})
    groups, fixes, regions = {}, [], []
    mobilise = f.mobilise
    for w in walls(plan):
        regions += [region_command(rid, style, args, w.plate and rid == w.region) for rid, style, args in w.regions]
        for gname, types, args in species_groups(plan, w.partner):
            if gname != "all":
                groups[gname] = types
            suffix = "" if gname == "all" else f"_{gname}"
            fixes.append({"id": f"wall_{w.region}{suffix}", "group": gname, "args": args, "region": w.region,
                          "kind": w.kind, "plate": w.plate})
    radii = f.radii
    dust = plan.dust
    if dust is not None and plan.planar:
        groups["dust"] = [len(plan.species)]
    clumps = [k + 1 for k, sp in enumerate(plan.species) if sp.kind == "clump"]
    free = [k + 1 for k, sp in enumerate(plan.species) if sp.kind != "clump"]
    if clumps:
        groups["clumps"] = clumps
        if free:
            groups["free"] = free
    seeds = [100003 + (plan.seed * 7919 + 104729 * (40 + k)) % 50_000_000 for k in range(len(radii))]
    every = count_every(plan)
    return {
        "name": plan.name, "planar": plan.planar, "box": box(plan, every), "n_types": n_types,
        "boundary_y": "p" if plan.geometry.periodic_depth else "f",     # a slab periodic along y
        "skin": 0.5 * plan.particle_radius, "pairs": pairs, "timestep": plan.dt, "gravity": plan.gravity,
        "classic": classic_args(plan), "classic_fill": classic_args(plan, frictionless=f.frictionless),
        "classic_style": CLASSIC_STYLE, "lowest_z": LOWEST_Z,
        "groups": [{"name": k, "types": v} for k, v in groups.items()], "regions": regions,
        "wall_fixes": fixes, "dust_in_plane": dust is not None and plan.planar, "dust_group": "dust",
        "outlet_z": plan.outlet.z, "dump_every": plan.outputs.dump_every, "restart_file": RESTART_FILE,
        "opening_speed": plan.opening.speed,
        "mobilise": None if mobilise is None else {"drop": mobilise.drop, "steps": mobilise.steps,
                                                   "jumps": mobilise_jumps(mobilise.steps)},
        "mobilised_floor": floor_commands(plan, -mobilise.drop) if mobilise is not None else [],
        "pour_type": poured_species(plan) + 1 if f.shrink_classes else 1,
        "mark_type": n_types,
        "density": plan.grains[0].density,
        "shrink_classes": [{"diameter": 2 * r, "fraction": fr, "seed": seed, "type": radii.index(r) + 1}
                           for (r, fr), seed in zip(f.shrink_classes, seeds)],
        "clumps": bool(clumps), "clump_types": clumps, "pour_region": pour_region(plan, clumps), "body_quantities": BODY_QUANTITIES,
        "free_types": free,
        "molecules": [{"id": f"clump{t}", "file": molecule_file(plan.species[t - 1].name)} for t in clumps],
    }


def pour_region(plan: RunPlan, clump_types: list[int]) -> dict | None:
    """Where ``fix pour`` may put a clump's centre so that the whole clump is inside the insertion
    region (the region holds whole grains, as the spheres' insertion and LIGGGHTS' ``all_in``)."""
    if not clump_types:
        return None
    reach = max(insertion_radius(plan, t - 1) for t in clump_types)
    r = plan.fill.region
    return {"radius": r.radius - reach, "z_min": r.z_min + reach, "z_max": r.z_max - reach}


def molecule_file(species: str) -> str:
    """The run folder's molecule template of a clump species."""
    return f"clump_{species}.mol"


def molecule_text(plan: RunPlan, species_index: int) -> str:
    """LAMMPS molecule template of a clump species: its spheres about the union's centroid, each
    sphere carrying an equal share of the body's mass (the dumps' ``mass`` column sums to the body),
    and a header with the body's mass, centre and inertia from the union of the spheres (not the
    sum of the spheres, which counts their overlaps twice)."""
    from ...clumps import union_centroid, union_inertia
    sp = plan.species[species_index]
    centers, radii = clump_spheres(plan, species_index)
    centroid = union_centroid(centers, radii)
    mass = sp.density * sp.volume
    inertia = stable_digits(sp.density * union_inertia(centers, radii, centroid))
    n = len(radii)
    rel = centers - centroid
    lines = [f"# siloflow clump {sp.name}: union volume {sp.volume!r} m3, density {sp.density!r} kg/m3", "",
             f"{n} atoms", f"{mass!r} mass", "0.0 0.0 0.0 com",
             " ".join(repr(float(v)) for v in (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                                               inertia[0, 2], inertia[1, 2])) + " inertia",
             "", "Coords", ""]
    lines += [f"{k + 1} {float(x)!r} {float(y)!r} {float(z)!r}" for k, (x, y, z) in enumerate(rel)]
    lines += ["", "Types", ""] + [f"{k + 1} {species_index + 1}" for k in range(n)]
    lines += ["", "Diameters", ""] + [f"{k + 1} {2 * float(r)!r}" for k, r in enumerate(radii)]
    lines += ["", "Masses", ""] + [f"{k + 1} {mass / n!r}" for k in range(n)]
    return "\n".join(lines) + "\n"


def stable_digits(inertia: np.ndarray) -> np.ndarray:
    """An inertia tensor (kg m2) rounded to 10 significant digits, its terms below 1e-10 of the
    largest set to 0: its grid integral is good to about 1e-4 (``clumps.union_inertia``), and the
    summation's last digits (the products of a symmetric clump, about 1e-28) change with the numpy
    and BLAS build, which would change the molecule file from one install to the next."""
    scale = float(np.abs(inertia).max())
    out = np.where(np.abs(inertia) < 1e-10 * scale, 0.0, inertia)
    return np.array([[float(f"{v:.10g}") for v in row] for row in out])


def insertion_radius(plan: RunPlan, species_index: int) -> float:
    """The radius (m) of the sphere about the insertion point that holds a grain whatever its
    orientation: a clump's farthest sphere surface from its centroid (or from its spheres' mean,
    whichever is larger), a sphere's radius."""
    sp = plan.species[species_index]
    if sp.kind != "clump":
        return sp.radius
    from ...clumps import union_centroid
    centers, radii = clump_spheres(plan, species_index)
    return float(max((np.linalg.norm(centers - ref, axis=1) + radii).max()
                     for ref in (union_centroid(centers, radii), centers.mean(axis=0))))


def render_deck_text(plan: RunPlan) -> str:
    """The rendered, checked ``in.lammps`` text."""
    try:
        text = template_environment("lammps").get_template("in.lammps.j2").render(deck_context(plan))
    except jinja2.UndefinedError as exc:
        raise DeckError(f"template needs a value siloflow did not provide: {exc}") from exc
    check_deck(text)
    return text


def write_deck(plan: RunPlan, folder: Path) -> None:
    """Write the LAMMPS deck of ``plan`` into the run folder ``folder`` being rendered: the deck,
    the walls' STL meshes, the output folders, the dump layout."""
    folder = Path(folder)
    text = render_deck_text(plan)
    (folder / "meshes").mkdir()
    for sub in ["output", "output/restart"] + (["output/dumps"] if plan.outputs.dump_every else []):
        (folder / sub).mkdir()
    for w in plan.meshes:
        write_stl(w, folder / "meshes" / f"{w.name}.stl")
    write_text(folder / DECK_NAME, text)
    for k, sp in enumerate(plan.species):
        if sp.kind == "clump":
            write_text(folder / molecule_file(sp.name), molecule_text(plan, k))
    RunFolder(folder).write_dump_layout(DumpLayout(
        engine="lammps", types={k + 1: sp.name for k, sp in enumerate(plan.species)},
        contact_columns=[], wall_contact_columns=[], clump_mass="sum"))
