"""Clumps and dust without the engine: union volumes against independent Monte Carlo and
closed forms, the schema's refusals, the deck, time-step reporting and clump porosity."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from postprocess.porosity import MeasureRegion, Porosity, grain_weights
from siloflow.case_file import case_from_dict, load_case
from siloflow.clumps import ClumpShape, union_area, union_volume, wheat_grain
from siloflow.engine.liggghts.deck import render_deck_text
from siloflow.engine.liggghts.encoding import encode
from siloflow.derived import derive
from siloflow.errors import CaseError

from conftest import ROOT, set_path
from test_post_analyses import frame_of

CLUMPS = ROOT / "tests" / "data" / "clump_silo.yaml"


def monte_carlo_volume(centers, radii, n: int, seed: int) -> tuple[float, float]:
    """Union volume by uniform sampling of the bounding box: (estimate, standard error), m3."""
    c, r = np.asarray(centers, float), np.asarray(radii, float)
    lo, hi = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(n // 500_000):
        p = lo + rng.random((500_000, 3)) * (hi - lo)
        inside = np.zeros(len(p), bool)
        for ci, ri in zip(c, r):
            inside |= ((p - ci) ** 2).sum(axis=1) < ri * ri
        hits += int(inside.sum())
    box = float(np.prod(hi - lo))
    f = hits / n
    return f * box, box * math.sqrt(f * (1 - f) / n)


def lens_volume(R: float, r: float, d: float) -> float:
    return math.pi * (R + r - d) ** 2 * (d * d + 2 * d * r - 3 * r * r + 2 * d * R + 6 * r * R - 3 * R * R) / (12 * d)


def test_wheat_grain_union_volume_closed_form_and_monte_carlo():
    grain = wheat_grain(6e-3, 4e-3)
    ext = np.asarray(grain.centers)[:, 0]
    assert (ext.max() - ext.min()) + 2 * grain.radii[0] == pytest.approx(6e-3)      # 6 mm long
    assert 2 * max(grain.radii) == pytest.approx(4e-3)                            # 4 mm wide
    # three equal spheres 1 mm apart: the outer pair's lens lies inside the middle sphere
    exact = 3 * 4 / 3 * math.pi * 2e-3 ** 3 - 2 * lens_volume(2e-3, 2e-3, 1e-3)
    assert grain.volume == pytest.approx(exact, rel=1e-9)
    mc, err = monte_carlo_volume(grain.centers, grain.radii, 4_000_000, seed=1)
    assert abs(grain.volume - mc) < 4 * err


@pytest.mark.parametrize("seed", [2, 3, 4])
def test_union_volume_of_random_clumps_matches_monte_carlo(seed):
    rng = np.random.default_rng(seed)
    centers = rng.normal(size=(6, 3)) * 0.6
    radii = rng.uniform(0.3, 0.9, 6)
    v = union_volume(centers, radii)
    mc, err = monte_carlo_volume(centers, radii, 3_000_000, seed=seed + 10)
    assert abs(v - mc) < 4 * err, (v, mc, err)
    # invariant under rotation and translation
    rot = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    assert union_volume(centers @ rot.T + 5.0, radii) == pytest.approx(v, rel=1e-8)


def test_union_volume_limits():
    assert union_volume([[0, 0, 0]], [2.0]) == pytest.approx(4 / 3 * math.pi * 8, rel=1e-12)
    assert union_volume([[0, 0, 0], [3, 0, 0]], [1.0, 1.0]) == pytest.approx(8 / 3 * math.pi, rel=1e-10)
    assert union_volume([[0, 0, 0], [0.2, 0.1, 0]], [1.0, 0.3]) == pytest.approx(4 / 3 * math.pi, rel=1e-10)
    assert union_volume([[0, 0, 0], [1.1, 0, 0]], [1.0, 0.6]) == pytest.approx(
        4 / 3 * math.pi * (1 + 0.216) - lens_volume(1.0, 0.6, 1.1), rel=1e-9)


def test_union_area_matches_closed_form_and_monte_carlo():
    R, d = 2.0, 1.0
    lens = 2 * R * R * math.acos(d / (2 * R)) - d / 2 * math.sqrt(4 * R * R - d * d)
    assert union_area([[-1, 0], [0, 0], [1, 0]], [2, 2, 2]) == pytest.approx(12 * math.pi - 2 * lens, rel=1e-12)
    rng = np.random.default_rng(5)
    c, r = rng.normal(size=(7, 2)), rng.uniform(0.3, 1.0, 7)
    lo, hi = (c - r[:, None]).min(0), (c + r[:, None]).max(0)
    p = lo + rng.random((2_000_000, 2)) * (hi - lo)
    inside = np.zeros(len(p), bool)
    for ci, ri in zip(c, r):
        inside |= ((p - ci) ** 2).sum(1) < ri * ri
    box, f = float(np.prod(hi - lo)), inside.mean()
    assert abs(union_area(c, r) - f * box) < 4 * box * math.sqrt(f * (1 - f) / len(p))


def test_clump_shape_checks():
    with pytest.raises(ValueError, match="same sphere"):
        ClumpShape(centers=((0, 0, 0), (0, 0, 0)), radii=(1.0, 1.0))
    assert not ClumpShape(centers=((0, 0, 0), (3, 0, 0)), radii=(1.0, 1.0)).connected()
    with pytest.raises(ValueError, match="overlap"):
        wheat_grain(13e-3, 4e-3)


# ---------------------------------------------------------------- schema, derived, deck
def clump_dict():
    import yaml
    return yaml.safe_load(CLUMPS.read_text())


def linear_paper_a_contacts(data: dict) -> dict:
    """Switch a clump case dict to paper A's linear springs (grains, dust, walls); returns its dust."""
    data["materials"] = {"model": "linear", "particle": {"density": 1000.0},
                         "particle_particle": {"friction": 0.3, "kn": 1.6e5, "kt": 0.8e5},
                         "particle_wall": {"friction": 0.62, "kn": 2.9e5, "kt": 1.45e5}}
    dust = data["particles"]["dust"]
    del dust["youngs_modulus"]
    dust.update(dust_dust={"friction": 0.3, "kn": 1.6e6, "kt": 0.8e6},
                dust_particle={"friction": 0.3, "kn": 2.9e5, "kt": 1.45e5},
                dust_wall={"friction": 0.3, "kn": 1.6e6, "kt": 0.8e6}, density_scale=1.0)
    return dust


def test_liggghts_runs_clumps_on_one_rank_only(tmp_path, write_case):
    """What an engine cannot do is its own check (Engine.check), told by validate, render and run
    before anything is written, naming the field; the case itself is valid."""
    from typer.testing import CliRunner

    from siloflow.cli import app
    from siloflow.engine import LiggghtsEngine
    data = clump_dict()
    data["engine"]["ranks"] = 2
    case = case_from_dict(data)
    assert [f for f, _ in LiggghtsEngine().check(case)] == ["engine.ranks"]
    path = write_case(data)
    for args in (["validate", str(path)], ["render", str(path), "-o", str(tmp_path / "deck")]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 1 and "engine.ranks" in result.output and "one rank" in result.output
    assert not (tmp_path / "deck").exists()
    with pytest.raises(CaseError, match="engine.ranks"):
        LiggghtsEngine().prepare(case, tmp_path / "deck")
    data["engine"]["ranks"] = 1
    assert LiggghtsEngine().check(case_from_dict(data)) == []


@pytest.mark.parametrize("path,value,field", [
    ("particles.dust.radius", 0.003, "particles.dust.radius"),
    ("particles.dust.dust_dust", {"friction": 0.3, "kn": 1e5, "kt": 5e4}, "particles.dust.dust_dust"),
    ("particles.dust.youngs_modulus", None, "particles.dust.youngs_modulus"),
    ("particles.length", 0.013, "particles"),
    ("particles.spheres", [{"center": [0, 0, 0], "radius": 0.002}, {"center": [0.001, 0, 0], "radius": 0.002}],
     "particles"),
])
def test_clump_and_dust_input_is_refused_naming_the_field(path, value, field):
    data = clump_dict()
    set_path(data, path, value)
    with pytest.raises(CaseError) as info:
        case_from_dict(data)
    assert any(field in f"{p} {m}" for p, m in info.value.problems), info.value.problems


def test_explicit_clump_spheres_and_linear_dust_contacts():
    data = clump_dict()
    data["particles"].update(shape="spheres", spheres=[{"center": [0, 0, 0], "radius": 0.002},
                                                      {"center": [0.0015, 0, 0], "radius": 0.0015}])
    dust = linear_paper_a_contacts(data)
    case = case_from_dict(data)
    d = derive(case)
    assert d.species[0].volume == pytest.approx(union_volume([[0, 0, 0], [0.0015, 0, 0]], [0.002, 0.0015]))
    # dust-dust uses its own springs and the dust mass; dust-grain the grain-dust springs
    enc = encode(d)
    dd, dg = enc.type_pairs[(2, 2)], enc.type_pairs[(1, 2)]
    m_dust = 2000.0 * 4 / 3 * math.pi * 0.00025 ** 3
    assert dd.kn == 1.6e6 and dd.m_eff == pytest.approx(m_dust / 2)
    assert dg.kn == 2.9e5 and dg.m_eff == pytest.approx(d.species[0].mass * m_dust / (d.species[0].mass + m_dust))
    assert enc.type_pairs[(2, 3)].kn == 1.6e6                             # dust-wall
    # the time step comes from the shortest contact, the dust's, and says by how much
    assert d.timestep.critical_time_source == "contact time dust-dust"
    assert d.dt == pytest.approx(case.engine.timestep_fraction * math.pi * math.sqrt(m_dust / 2 / 1.6e6))
    assert d.timestep.without_dust / d.dt > 10


def test_dust_density_scaling_lengthens_the_time_step_as_its_square_root():
    data = clump_dict()
    dust = linear_paper_a_contacts(data)
    steps = {}
    for scale in (1.0, 4.0):
        dust["density_scale"] = scale
        steps[scale] = derive(case_from_dict(data)).dt
    assert steps[4.0] / steps[1.0] == pytest.approx(2.0, rel=1e-9)


def test_clump_deck_uses_multisphere_and_keeps_dust_on_its_own_integrator():
    case = load_case(CLUMPS)
    d = derive(case)
    text = render_deck_text(d)
    line = next(ln for ln in text.splitlines() if "particletemplate/multisphere" in ln)
    assert "nspheres 3" in line and "ntry 200000" in line and "density constant 1000" in line
    assert "fix             integrate all multisphere" in text
    assert "fix             integrate_dust dust nve/sphere" in text
    assert "nve/sphere" not in text.replace("integrate_dust dust nve/sphere", "")
    assert "delete_atoms" not in text                         # refused by multisphere
    assert "output/dumps/dump.*.txt id type mol x" in text    # body ids for per-body analyses
    assert "(type==1)*0.3333333333+(type==2)*1" in text       # a clump weighed once
    enc = encode(d)
    vx, _, vz = enc.plate_velocity
    assert vx > 0 and vz < 0 and math.hypot(vx, vz) == pytest.approx(case.discharge.opening.speed)
    assert enc.box["xhi"] > enc.plate_shift + case.geometry.outlet_radius     # the plate stays in the box


# ---------------------------------------------------------------- porosity of clumps
def test_porosity_of_clumps_counts_each_union_once():
    from postprocess import porosity
    porosity._UNION_CACHE.clear()       # shapes are cached to 1e-4 of a radius: start from exact ones
    grain = wheat_grain()
    rng = np.random.default_rng(7)
    centers = np.array([(x, y, z) for x in range(4) for y in range(4) for z in range(4)], float) * 0.01
    pos, rad, mol = [], [], []
    for k, c in enumerate(centers):
        rot = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
        pos += list(np.asarray(grain.centers) @ rot.T + c)
        rad += list(grain.radii)
        mol += [k + 1] * 3
    frame = frame_of(np.array(pos), np.array(rad), mol=np.array(mol))
    w = grain_weights(frame)
    np.testing.assert_allclose(w, grain.volume / grain.sphere_volume_sum, rtol=1e-6)
    region = MeasureRegion("all", "sphere", (0.015, 0.015, 0.015), 0.05)      # holds every clump
    phi = Porosity([region]).run([frame]).table.solid_fraction.iloc[0]
    assert phi * region.measure == pytest.approx(len(centers) * grain.volume, rel=1e-6)


def test_the_dust_bench_plans_each_variant_per_seed_and_keeps_the_true_time_step():
    """benchmarks/dust_density_scaling.py: the true density (the compared-with), each scale at its own
    time step and at the true density's; one run of each per seed, all named apart."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("dust_bench", ROOT / "benchmarks" / "dust_density_scaling.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    base = yaml.safe_load(CLUMPS.read_text())
    planned = bench.planned_runs(base, [25.0], 2, keep_dt=True)
    assert [p.key["candidate"] for p in planned] == ["true_density", "x25", "x25_dt1"] * 2
    assert [p.key["seed"] for p in planned] == [base["seed"]] * 3 + [base["seed"] + 1] * 3
    assert len({p.case["name"] for p in planned}) == 6
    true, fast, same = (derive(case_from_dict(p.case)) for p in planned[:3])
    assert fast.dt / true.dt == pytest.approx(5.0, rel=0.05)            # x25: the dust's step x sqrt(25)
    assert same.dt == pytest.approx(true.dt, rel=1e-9)                  # the true density's step, heavier dust
    assert same.dust.mass == pytest.approx(25 * true.dust.mass)
