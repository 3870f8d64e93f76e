"""Contact laws measured in LIGGGHTS and LAMMPS, one YAML file per law and scenario.

Each file of tests/contact_laws/ (as LAMMPS' ``unittest/force-styles``) gives a scenario's inputs
(the case it starts from, its materials and particles, the pair, speeds, angles) and its expected
values, each with its tolerance and source: closed forms, or the law integrated, worked out by hand.
Each expected value is checked twice: against siloflow's own (the plan, ``siloflow.contact_physics``
and the law LIGGGHTS documents, integrated here from the plan's numbers), and against what each
engine the file names measures (the contact lines of the deck it renders for the case, run on two
bodies by ``contact_runs``); an engine the file does not name is skipped with the file's reason.
"""
from __future__ import annotations

import copy
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from siloflow import contact_physics as cp
from siloflow.case_file import case_from_dict
from siloflow.derived import derive

from conftest import ROOT
from contact_runs import ENGINES, Body, Setup, run, run_liggghts

LAWS = Path(__file__).parent / "contact_laws"
FILES = sorted(LAWS.glob("*.yaml"))
IDS = [p.stem for p in FILES]
#: the hand values against siloflow's (they are written to 5 or more significant digits)
PHYSICS_REL = 1e-4
#: the approach starts this fraction of the radii sum away from contact
GAP = 0.01
#: time steps per contact time (impacts) and per small oscillation (resting): the laws are measured, not the steps
STEPS_PER_CONTACT = 1000
STEPS_PER_PERIOD = 50


@lru_cache(maxsize=None)
def load(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


@lru_cache(maxsize=None)
def scenario_case(path: Path):
    """(case, plan) of a file: its ``case`` with its ``materials`` and ``particles``."""
    spec = load(path)
    data = yaml.safe_load((ROOT / spec["case"]).read_text())
    data["materials"] = copy.deepcopy(spec["materials"])
    data["particles"] = copy.deepcopy(spec["particles"])
    case = case_from_dict(data)
    return case, derive(case)


def species(plan, name):
    return next(sp for sp in plan.species if sp.name == name)


def tolerance(expected: dict, engine: str, key: str = "rel", default=None) -> float:
    """An expected value's ``rel`` (or ``share``): one number, or one per engine."""
    value = expected.get(key, default)
    return value[engine] if isinstance(value, dict) else value


# ------------------------------------------------------------------ siloflow's values

def law_force(plan, pair):
    """LIGGGHTS' normal force law of a pair, F(d, d') in N: hertz (no limitForce), or
    hooke/stiffness with limitForce on (a total force below 0 is 0)."""
    if plan.contact_model == "hertz":
        ln_e = math.log(pair.restitution)
        beta = ln_e / math.sqrt(ln_e ** 2 + math.pi ** 2)

        def hertz(d, dd):
            sn = 2 * pair.y_eff * math.sqrt(pair.r_eff * d)
            return 2 / 3 * sn * d - 2 * math.sqrt(5 / 6) * beta * math.sqrt(sn * pair.m_eff) * dd
        return hertz
    return lambda d, dd: max(0.0, pair.kn * d + pair.gamman * pair.m_eff * dd)


def law_impact(plan, pair, v: float, gravity: float = 0.0) -> dict:
    """Restitution, contact time (s) and deepest overlap (m) of a head-on impact at ``v`` under
    the pair's law (and ``gravity`` pressing it on), integrated with scipy until the overlap closes."""
    from scipy.integrate import solve_ivp
    force, m = law_force(plan, pair), pair.m_eff
    scale = time_scale(plan, pair, v)
    parted = lambda t, s: s[0]              # noqa: E731
    parted.terminal, parted.direction = True, -1
    deepest = lambda t, s: s[1]             # noqa: E731
    deepest.direction = -1
    sol = solve_ivp(lambda t, s: [s[1], gravity - force(max(s[0], 0.0), s[1]) / m], [0, 10 * scale], [1e-30, v],
                    events=[parted, deepest], rtol=1e-11, atol=1e-18, max_step=scale / 100)
    return {"restitution": -sol.y_events[0][0][1] / v, "contact_time": sol.t_events[0][0],
            "max_overlap": sol.y_events[1][0][0]}


def time_scale(plan, pair, v: float) -> float:
    """The pair's contact time at ``v`` (s): Hertz's elastic 2.87 formula, or the plan's linear one."""
    if plan.contact_model == "hertz":
        return cp.hertz_contact_time(pair.m_eff, pair.r_eff, pair.y_eff, v)
    return pair.contact_time


def siloflow_values(spec: dict, plan, pair) -> dict:
    """What siloflow's plan and contact physics give for every quantity a file may expect."""
    out = {"friction": pair.friction, "tangential_impulse": pair.friction}
    v, g = spec.get("velocity"), spec.get("gravity", 0.0)
    if v is not None:
        out.update(law_impact(plan, pair, v, g))
        if plan.contact_model == "hertz":
            out["elastic_contact_time"] = cp.hertz_contact_time(pair.m_eff, pair.r_eff, pair.y_eff, v)
    sp = species(plan, spec["pair"][0])
    weight = sp.mass * g
    if plan.contact_model == "hertz":          # a sphere resting on a plane: F = 4/3 Y* sqrt(r) d^1.5
        out["static_overlap"] = (weight / (4 / 3 * pair.y_eff * math.sqrt(pair.r_eff))) ** (2 / 3)
    else:
        out["static_overlap"] = weight / pair.kn
    out.update(static_load=weight, deceleration=pair.friction * g, spin_up=2.5 * pair.friction * g)
    if "overlap" in spec and pair.y_eff is not None:     # held spheres: mu_r F_n R* / I
        fn = 4 / 3 * pair.y_eff * math.sqrt(pair.r_eff) * spec["overlap"] ** 1.5
        out["rolling_deceleration"] = pair.rolling_friction * fn * pair.r_eff / (0.4 * sp.mass * sp.radius ** 2)
    return out


# ------------------------------------------------------------------ measurements

def impact(time, gap, vn) -> dict:
    """Restitution, contact time (s, the gap's zero crossings interpolated) and deepest overlap
    (m) from the per-step gap (< 0 in contact) and normal relative speed (approach < 0)."""
    touching = np.flatnonzero(gap < 0)
    assert len(touching) > 50, "the contact is not resolved"
    first, last = touching[0], touching[-1]
    assert np.all(np.diff(touching) == 1), "more than one contact"
    assert first > 0 and last < len(gap) - 2, "the run started or ended in contact"
    start = time[first - 1] + (time[first] - time[first - 1]) * gap[first - 1] / (gap[first - 1] - gap[first])
    end = time[last] + (time[last + 1] - time[last]) * gap[last] / (gap[last] - gap[last + 1])
    return {"restitution": -vn[last + 1] / vn[first - 1], "contact_time": end - start, "max_overlap": -gap.min()}


def approach(spec, plan, pair, angle: float = 0.0) -> Setup:
    """Sphere b coming at sphere a (at rest) along -x at the file's velocity, its centre off a's
    line by (r_a + r_b) sin(angle)."""
    a, b = (species(plan, n) for n in spec["pair"])
    v, reach = spec["velocity"], a.radius + b.radius
    scale = time_scale(plan, pair, v)
    dt = scale / STEPS_PER_CONTACT
    x0 = reach * math.cos(math.radians(angle)) + GAP * reach
    bodies = [Body(a.name, (0.0, 0.0, 0.0)), Body(b.name, (x0, reach * math.sin(math.radians(angle)), 0.0), (-v, 0.0, 0.0))]
    return Setup(bodies, dt, int((GAP * reach / v + 3 * scale) / dt))


def separation(t) -> tuple:
    """Per frame: the centres' distance (m), the unit normal from a to b and the normal relative
    speed (approach < 0)."""
    d = t["x"][:, 1] - t["x"][:, 0]
    dist = np.linalg.norm(d, axis=1)
    n = d / dist[:, None]
    return dist, n, np.einsum("ij,ij->i", t["v"][:, 1] - t["v"][:, 0], n)


def head_on(spec, plan, pair):
    setup = approach(spec, plan, pair)
    reach = sum(species(plan, n).radius for n in spec["pair"])

    def measure(runs):
        dist, _, vn = separation(runs[0])
        return impact(runs[0]["time"], dist - reach, vn)
    return [setup], measure


def wall_drop(spec, plan, pair):
    """A sphere falling (gravity on) onto the floor at the file's velocity."""
    sp = species(plan, spec["pair"][0])
    v, scale = spec["velocity"], time_scale(plan, pair, spec["velocity"])
    dt = scale / STEPS_PER_CONTACT
    setup = Setup([Body(sp.name, (0.0, 0.0, sp.radius * (1 + GAP)), (0.0, 0.0, -v))], dt,
                  int((GAP * sp.radius / v + 3 * scale) / dt), floor=True, gravity=spec["gravity"])
    return [setup], lambda runs: impact(runs[0]["time"], runs[0]["x"][:, 0, 2] - sp.radius, runs[0]["v"][:, 0, 2])


def oblique(spec, plan, pair):
    """A grazing impact. Per step of the contact, sphere b's velocity change against the sliding
    (the contact points' relative velocity across the normal) over its change along the normal
    (``friction``: Coulomb's mu, negative where friction pushes along the sliding), and the
    sums' ratio (``tangential_impulse``)."""
    ra, rb = (species(plan, n).radius for n in spec["pair"])

    def measure(runs):
        t = runs[0]
        dist, n, vn = separation(t)
        impact(t["time"], dist - ra - rb, vn)
        dv = t["v"][1:, 1] - t["v"][:-1, 1]
        along = np.einsum("ij,ij->i", dv, n[:-1])
        k = np.flatnonzero((dist[:-1] < ra + rb) & (along != 0))     # in contact (limitForce: or no force)
        v, w, n = t["v"][k], t["omega"][k], n[k]
        slip = v[:, 1] - v[:, 0] - np.cross(w[:, 1], -rb * n) - np.cross(w[:, 0], ra * n)
        slip -= np.einsum("ij,ij->i", slip, n)[:, None] * n
        against = -np.einsum("ij,ij->i", dv[k], slip / np.linalg.norm(slip, axis=1)[:, None])
        return {"friction": against / np.abs(along[k]), "tangential_impulse": against.sum() / np.abs(along[k]).sum()}
    return [approach(spec, plan, pair, spec["angle"])], measure


def floor_slide(spec, plan, pair):
    """A sphere placed on the floor at its static overlap rests there; set sliding at the file's
    speed, the floor's force on it is -mu m g along x and m g along z until it rolls: it
    decelerates at mu g and spins up at 5/2 mu g / r."""
    sp = species(plan, spec["pair"][0])
    g, r, v0, mu = spec["gravity"], sp.radius, spec["slide_velocity"], pair.friction
    overlap = siloflow_values(spec, plan, pair)["static_overlap"]
    stiffness = 2 * pair.y_eff * math.sqrt(r * overlap) if plan.contact_model == "hertz" else pair.kn
    period = 2 * math.pi * math.sqrt(sp.mass / stiffness)         # the small oscillation's
    dt = period / STEPS_PER_PERIOD
    start = (0.0, 0.0, r - overlap)
    setups = [Setup([Body(sp.name, start)], dt, int(5 * period / dt), floor=True, gravity=g),
              Setup([Body(sp.name, start, (v0, 0.0, 0.0))], dt, int(2.4 * v0 / (7 * mu * g) / dt), floor=True,
                    gravity=g)]

    def measure(runs):
        rest, t = runs
        # from the second step on: LIGGGHTS' first of a fresh contact exceeds the Coulomb limit
        # (measured: 20 x at the setup of hertz_floor_slide, 1.22 x in hooke_floor_slide's first step)
        time, vx, spin, force = t["time"][2:], t["v"][2:, 0, 0], t["omega"][2:, 0, 1], t["wall"][2:, 0]
        slip = vx - spin * r
        sliding = np.arange(np.argmax(slip < 0.05 * v0))               # until it (almost) rolls
        steps = (slip[0] - 0.05 * v0) / (3.5 * mu * g * dt)            # the slip falls at 7/2 mu g
        assert 0.95 * steps < len(sliding) < 1.05 * steps + 2, f"it slid {len(sliding)} steps, not {steps:.0f}"
        return {"static_load": rest["wall"][1:, 0, 2], "static_overlap": r - rest["x"][1:, 0, 2],
                "friction": -force[sliding, 0] / force[sliding, 2],
                "deceleration": -np.polyfit(time[sliding], vx[sliding], 1)[0],
                "spin_up": np.polyfit(time[sliding], spin[sliding] * r, 1)[0]}
    return setups, measure


def rolling(spec, plan, pair):
    """Two spheres held at the file's overlap, counter-rotating about z (rolling, not sliding):
    their spin's deceleration, once the rolling torque is at its limit (the run's second half)."""
    a, b = (species(plan, n) for n in spec["pair"])
    w = spec["spin"]
    dt = pair.contact_time / 50
    setup = Setup([Body(a.name, (0.0, 0.0, 0.0), omega=(0.0, 0.0, w)),
                   Body(b.name, (a.radius + b.radius - spec["overlap"], 0.0, 0.0), omega=(0.0, 0.0, -w))],
                  dt, int(10 * pair.contact_time / dt), hold=True)

    def measure(runs):
        omega = runs[0]["omega"][:, :, 2]
        assert np.allclose(omega[:, 0], -omega[:, 1]), "not equal and opposite: the spheres slide"
        late = slice(len(omega) // 2, None)
        return {"rolling_deceleration": -np.polyfit(runs[0]["time"][late], omega[late, 0], 1)[0]}
    return [setup], measure


#: scenario -> f(spec, plan, pair): (the runs' setups, measure(the runs' per-step arrays) -> values)
SCENARIOS = {"head_on": head_on, "wall_drop": wall_drop, "oblique": oblique, "floor_slide": floor_slide,
             "rolling": rolling}


@lru_cache(maxsize=None)
def prepared(path: Path):
    """(case, plan, the pair, the setups, their measure) of a file."""
    spec = load(path)
    case, plan = scenario_case(path)
    pair = plan.pair(*spec["pair"])
    return (case, plan, pair, *SCENARIOS[spec["scenario"]](spec, plan, pair))


@pytest.fixture(scope="session")
def liggghts_runs(tmp_path_factory):
    """Every file's LIGGGHTS runs, in one LIGGGHTS process (``contact_runs.run_liggghts``)."""
    jobs = {}
    for path in FILES:
        if "liggghts" in load(path)["engines"]:
            case, plan, _, setups, _ = prepared(path)
            jobs[path.stem] = (case, plan, setups)
    return run_liggghts(jobs, tmp_path_factory.mktemp("contact_laws"))


# ------------------------------------------------------------------ the tests

@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_file_states_its_engines_values_and_sources(path):
    """Every file names a known scenario, the engines it runs on (a reason for each other one, and
    for each known failure) and for every expected value its source; a measured one has a tolerance."""
    spec = load(path)
    assert spec["scenario"] in SCENARIOS
    assert set(spec["engines"]) <= set(ENGINES) and spec["engines"]
    for engine in set(ENGINES) - set(spec["engines"]):
        assert spec["skip"][engine].strip(), f"{path.name}: no reason to skip {engine}"
    for engine, reason in spec.get("known_failures", {}).items():
        assert engine in spec["engines"] and reason.strip(), f"{path.name}: known failure on {engine}"
    assert any("rel" in e for e in spec["expected"].values())
    for name, expected in spec["expected"].items():
        assert expected["source"].strip() and "value" in expected, f"{path.name}: {name}"


@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_hand_values_are_siloflows(path):
    """The file's pair constants and expected values, worked out by hand, are siloflow's."""
    spec = load(path)
    _, plan = scenario_case(path)
    pair = plan.pair(*spec["pair"])
    for name, value in spec.get("pair_constants", {}).items():
        assert getattr(pair, name) == pytest.approx(value, rel=PHYSICS_REL), f"{path.name}: pair {name}"
    ours = siloflow_values(spec, plan, pair)
    for name, expected in spec["expected"].items():
        assert ours[name] == pytest.approx(expected["value"], rel=PHYSICS_REL), (
            f"{path.name}: {name} is {ours[name]!r} by siloflow, {expected['value']!r} by hand ({expected['source']})")


@pytest.mark.engine
@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("path", FILES, ids=IDS)
def test_engine_measures_the_expected_values(path, engine, tmp_path, request):
    """The engine, given the contact lines of the deck it renders for the file's case, measures
    every expected value that has a tolerance (a file's known failure is a strict xfail)."""
    spec = load(path)
    if engine not in spec["engines"]:
        pytest.skip(f"{path.stem} on {engine}: {spec['skip'][engine]}")
    if engine in spec.get("known_failures", {}):
        request.applymarker(pytest.mark.xfail(strict=True, reason=spec["known_failures"][engine]))
    case, plan, _, setups, measure = prepared(path)
    if engine == "liggghts":
        runs = request.getfixturevalue("liggghts_runs")[path.stem]
        assert not isinstance(runs, str), f"LIGGGHTS failed:\n{runs}"
    else:
        runs = run(engine, case, plan, tmp_path, setups)
    measured = measure(runs)
    for name, expected in spec["expected"].items():
        if "rel" not in expected:
            continue
        values = np.atleast_1d(measured[name])
        rel = tolerance(expected, engine)
        within = np.abs(values - expected["value"]) <= rel * abs(expected["value"])
        share = tolerance(expected, engine, "share", 1.0)
        assert within.mean() >= share, (
            f"{path.stem} on {engine}: {name} measured {np.median(values)!r} (min {values.min()!r}, max "
            f"{values.max()!r}; {within.mean():.3f} of {len(values)} within {rel} of {expected['value']!r}, "
            f"{share} needed); expected from: {expected['source']}")
