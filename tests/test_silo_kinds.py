"""Silo kinds as plug-ins (issue 58): every kind in the registry provides the whole interface
(docs/new_silo.md), matches the case schema's ``Geometry`` union and the plan's ``Silo.kind``, and
answers the planner and post-processing for a plan of its kind."""
from __future__ import annotations

import inspect
import math
import typing
from pathlib import Path

import numpy as np
import pytest

from siloflow.case import Geometry
from siloflow.case_file import case_from_dict, load_case
from siloflow.derived import bed_volume, derive, measured
from siloflow.plan import Silo
from siloflow.silos.base import FlatSided, SiloKind, resolve
from siloflow.silos.registry import SILO_KINDS, kind_of, silo_kind

ROOT = Path(__file__).resolve().parents[1]
#: a shipped case of each kind (a hopper: quick.yaml's cylinder on a cone, below)
SHIPPED = {"cylinder": ROOT / "decks" / "demo.yaml", "planar": ROOT / "tests" / "data" / "slab_silo.yaml",
           "box": ROOT / "tests" / "data" / "box_silo.yaml", "mesh": ROOT / "decks" / "mesh_quick.yaml"}


def _abstract() -> list[str]:
    """The interface's methods a kind must give: those the base class leaves unimplemented."""
    return [name for name, f in vars(SiloKind).items() if inspect.isfunction(f)
            and "raise NotImplementedError" in inspect.getsource(f)]


def test_the_registry_is_the_case_schemas_and_the_plans_kinds():
    """The case's ``Geometry`` union and the plan's ``Silo.kind`` admit exactly the registered kinds."""
    union = typing.get_args(typing.get_args(Geometry)[0])
    assert {typing.get_args(m.model_fields["kind"].annotation)[0] for m in union} == set(SILO_KINDS)
    assert set(typing.get_args(Silo.model_fields["kind"].annotation)) == set(SILO_KINDS)
    with pytest.raises(KeyError, match="known: cylinder, hopper, planar, box, mesh"):
        silo_kind("sphere")


@pytest.mark.parametrize("name", list(SILO_KINDS))
def test_every_kind_provides_the_whole_interface(name):
    kind = SILO_KINDS[name]
    assert isinstance(kind, SiloKind) and kind.name == name and kind.title
    for method in _abstract():
        assert getattr(type(kind), method) is not getattr(SiloKind, method), f"{name} lacks {method}"
    model = resolve(kind.case_model)
    assert typing.get_args(model.model_fields["kind"].annotation) == (name,)
    assert callable(kind.builder())
    assert callable(resolve(kind.lammps_walls)) if kind.lammps_walls else kind.user_triangles  # LAMMPS refuses it
    assert kind.en1991 in (None, "flat", "hopper")
    assert isinstance(kind.design_refusal("cylinder or hopper"), str)
    assert {"bed_volume", "insertion_region", "silo_fields", "escape_limits", "bed_discs"} <= set(_abstract())


@pytest.fixture(params=["cylinder", "hopper", "planar", "box", "mesh"])
def plan_case(request, quick_dict):
    """(kind, case, plan) of a shipped case of each kind."""
    if request.param == "hopper":
        quick_dict["geometry"] = {"kind": "hopper", "radius": 0.015, "height": 0.3,
                                  "half_angle_deg": 45.0, "outlet_radius": 0.008}
        case = case_from_dict(quick_dict)
    else:
        case = load_case(SHIPPED[request.param])
    return SILO_KINDS[request.param], measured(case), derive(case)


def test_a_kinds_plan_and_post_processing_agree(plan_case):
    """The planner's answers (volume, region, sectors, escape limits) and post-processing's
    (measurement discs, Janssen's D, wall bins) for a derived plan of each kind."""
    kind, case, plan = plan_case
    s = plan.geometry
    assert kind_of(s) is kind and kind_of(case.geometry) is kind
    volumes = [bed_volume(case, h) for h in np.linspace(0.0, s.top, 7)]
    assert volumes[0] == pytest.approx(0.0, abs=1e-12) and all(b > a for a, b in zip(volumes, volumes[1:]))
    region, volume = kind.insertion_region(case.geometry, case.particles, s.half_width, case.particles.max_radius,
                                           0.5 * s.top, s.top)
    assert region["shape"] in ("cylinder", "block") and volume > 0
    assert plan.sensors.sectors == kind.sensor_sectors(case.geometry, case.sensors.sectors)
    limits = kind.escape_limits(case.geometry, 0.0)
    assert set(limits) == {"escape_radius", "escape_half_x", "escape_half_y"}
    assert (limits["escape_radius"] is None) == isinstance(kind, FlatSided)
    assert kind.half_depth(s) == s.half_depth > 0
    discs = kind.bed_discs(s, s.hopper_height, s.top, 2 * plan.particle_radius)
    assert [d[0] for d in discs] == ["bulk_core", "cross_section"] and all(d[2] > 0 for d in discs)
    assert 0 < kind.janssen_diameter(s) < math.inf
    assert kind.inside(s, np.array([[0.0, 0.0, 0.5 * s.top]])).all()
    near, far, pairs = kind.eccentric_sectors(plan.sensors.sectors, 0.001, 0.0)
    assert near not in far and all(0 <= k < plan.sensors.sectors for k in [near, *far])
    if kind.name in ("cylinder", "hopper", "planar", "box"):
        classify, n, spans, radius = kind.wall_bins(s, None, plan.sensors.sectors, plan.particle_radius)
        assert n == plan.sensors.sectors and len(spans) == n and (radius is None) == isinstance(kind, FlatSided)
        on, sector = classify(np.array([s.half_width]), np.array([0.0]), np.array([s.top - 0.01]))
        assert on.all() and 0 <= sector[0] < n


def test_kinds_volumes_and_sections_are_their_formulas(quick_dict):
    """A cylinder's volume pi R^2 h; a box's and a slab's Janssen sections (area, m2, and grip: friction
    times the perimeter it acts on, m)."""
    case = case_from_dict(quick_dict)
    g = case.geometry
    assert silo_kind("cylinder").bed_volume(g, 0.1) == pytest.approx(math.pi * g.radius ** 2 * 0.1)
    box = load_case(SHIPPED["box"]).geometry
    area, grip = silo_kind("box").janssen_section(box, 0.5)
    assert area == pytest.approx(box.width * box.depth) and grip == pytest.approx((box.width + box.depth))
    slab = load_case(SHIPPED["planar"]).geometry
    area, grip = silo_kind("planar").janssen_section(slab, 0.0)
    assert area == pytest.approx(slab.width * slab.thickness) and grip == pytest.approx(2 * slab.width
                                                                                         * slab.face_friction)
