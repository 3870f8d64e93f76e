"""The instability guard (issue 16): each signal trips on its own, names itself and its fix, and a
deliberately unstable run is stopped by it within seconds, not at the end."""
from __future__ import annotations

import copy
import math
import time

import pytest
import yaml

from siloflow.case_file import case_from_dict
from siloflow.derived import derive
from siloflow.engine.liggghts.log import LogState
from siloflow.guard import ENERGY_FLOOR, RunGuard
from siloflow.plan import Guard

from conftest import SMALL

LIMITS = Guard(max_speed=5.0, max_overlap=1e-4, max_overlap_fraction=0.1, grain_radius=1e-3, energy_growth=10.0,
               escape_radius=0.02, escape_z=0.2)


def guard(**changes):
    return RunGuard(LIMITS.model_copy(update=changes))


def test_quiet_rows_pass():
    g = guard()
    for step in range(0, 1000, 100):
        assert g.check("settle", step, ke=1e-6, pe=1.0, speed=0.1, overlap=1e-5, escaped=0, lost=0) is None


@pytest.mark.parametrize("signal,values,words,calm", [
    ("speed", dict(speed=5.1), "faster than 5 m/s", dict(speed=4.9)),
    ("overlap", dict(overlap=1.2e-4), "0.12 of the smallest radius", dict(overlap=0.9e-4)),
    ("escape", dict(escaped=2.0), "2 grain(s) are beyond the walls", dict(escaped=0.0)),
    ("escape", dict(lost=3), "3 atom(s) left the simulation", dict(lost=0)),
    ("not_finite", dict(ke=math.nan), "kinetic energy is nan", None),
    ("not_finite", dict(speed=math.inf), "fastest speed is inf", None),
])
def test_each_signal_trips_and_names_itself(signal, values, words, calm):
    row = dict(ke=1e-6, pe=1.0, speed=0.1, overlap=1e-5, escaped=0.0, lost=0)
    trip = guard().check("discharge", 500, **{**row, **values})
    assert trip is not None and trip.signal == signal and trip.step == 500 and trip.stage == "discharge"
    assert words in trip.message and "engine.timestep_fraction" in trip.fix
    if calm is not None:                  # just inside the limit it does not trip
        assert guard().check("discharge", 500, **{**row, **calm}) is None


def test_no_contact_yet_is_not_an_overlap():
    """LIGGGHTS reduces an empty contact list to -1e20: no contact, no trip."""
    assert guard().check("fill", 0, ke=0.0, pe=0.0, speed=-1e20, overlap=-1e20, escaped=0.0) is None


def test_energy_growth_trips_only_where_nothing_feeds_it():
    pe = 1.0
    for stage, trips in (("settle", True), ("static", True), ("discharge", False), ("fill", False), ("shrink", False)):
        g = guard()
        assert g.check(stage, 0, ke=1e-4 * pe, pe=pe) is None
        trip = g.check(stage, 100, ke=20 * ENERGY_FLOOR * pe, pe=pe)
        assert (trip is not None and trip.signal == "energy") is trips, stage
    # growth that stays below the floor (a settled bed's jitter) does not trip
    g = guard()
    g.check("static", 0, ke=1e-8, pe=pe)
    assert g.check("static", 100, ke=1e-5, pe=pe) is None
    # a new stage starts a new minimum
    g = guard()
    g.check("settle", 0, ke=1e-6, pe=pe)
    assert g.check("static", 10, ke=0.5 * ENERGY_FLOOR * pe, pe=pe) is None


def test_a_disabled_guard_never_trips():
    assert guard(enabled=False).check("settle", 0, ke=math.nan, pe=1.0, speed=1e9) is None


THERMO = "{step} 0.1 {atoms} {ke} 1.0 0.5 {out_mass} {out_count} {speed} {overlap} {escaped}"


def test_the_log_reader_hands_thermo_rows_to_the_guard_and_stops_the_run():
    state = LogState(guard=guard(), count_lost=True)
    state.feed("SILOFLOW_STAGE settle 1000")
    state.feed(THERMO.format(step=10, atoms=100, ke=1e-6, out_mass=0, out_count=0, speed=0.1, overlap=1e-5, escaped=0))
    state.feed("SILOFLOW_INSERTED 100")
    assert not state.fatal
    state.feed(THERMO.format(step=20, atoms=90, ke=1e-6, out_mass=0.1, out_count=4, speed=0.1, overlap=1e-5, escaped=0))
    assert state.fatal and state.guard_trip.signal == "escape"          # 100 - 90 - 4 = 6 atoms lost
    assert "6 atom(s)" in state.errors[-1] and state.errors[-1].startswith("siloflow guard (escape)")


def test_clumps_count_no_lost_atoms():
    """Clumps are not deleted at the outlet (they fall out of the box): atom counts prove nothing."""
    state = LogState(guard=guard(), count_lost=False)
    state.feed("SILOFLOW_INSERTED 100")
    state.feed(THERMO.format(step=20, atoms=50, ke=1e-6, out_mass=0.1, out_count=4, speed=0.1, overlap=1e-5, escaped=0))
    assert not state.fatal


def test_old_thermo_rows_without_guard_columns_are_read_as_before():
    state = LogState(guard=guard())
    assert state.feed("100 0.1 50 1e-6 1.0 0.5 0 0")
    assert state.step == 100 and not state.fatal


def test_the_plan_sets_the_limits_from_the_case():
    data = yaml.safe_load(SMALL.read_text())
    data["engine"]["guard"] = {"max_overlap": 0.2, "speed_factor": 3.0, "escape_margin": 2.0}
    plan = derive(case_from_dict(data))
    g, r = plan.guard, data["particles"]["radius"]
    assert g.max_overlap == pytest.approx(0.2 * r)
    top = data["geometry"]["height"]
    fall = math.sqrt(1.5 ** 2 + 2 * 9.81 * (top - (plan.outlet.z - plan.opening.travel)))
    assert g.max_speed == pytest.approx(3.0 * (fall + plan.opening.speed))
    assert g.escape_radius == pytest.approx(data["geometry"]["radius"] + 2.0 * 2 * r)
    assert g.escape_z == pytest.approx(top + 4 * r)


@pytest.mark.engine
def test_a_deliberately_unstable_run_is_stopped_by_the_guard_in_seconds(tmp_path):
    """dt = t_c on the small silo: velocity Verlet is unstable above 0.64 t_c. The guard stops the engine
    at its first thermo output after the blow-up, in the fill, with a message naming the signal and the fix."""
    import siloflow
    from siloflow.errors import EngineRunError
    from siloflow.run_folder import RunFolder
    data = yaml.safe_load(SMALL.read_text())
    data.update(name="unstable")
    data["fill"]["count"] = 600
    data["engine"] = {"ranks": 1, "timestep_fraction": 1.0}
    t0 = time.perf_counter()
    with pytest.raises(EngineRunError) as info:
        siloflow.run(data, tmp_path / "run")
    elapsed = time.perf_counter() - t0
    message = str(info.value)
    assert "stopped by siloflow's guard" in message and "lower engine.timestep_fraction" in message
    rec = RunFolder(tmp_path / "run").record
    assert rec.guard["signal"] in ("speed", "overlap", "escape", "not_finite", "energy")
    assert rec.guard["stage"] == "fill"
    planned = derive(case_from_dict(data)).total_planned_steps
    assert rec.guard["step"] < 0.1 * planned               # stopped early, not at the end
    assert elapsed < 60
    assert RunFolder(tmp_path / "run").state["state"] == "failed"


@pytest.mark.engine
def test_the_same_case_at_a_stable_step_passes_the_guard(tmp_path):
    import siloflow
    data = yaml.safe_load(SMALL.read_text())
    data.update(name="stable")
    data["fill"]["count"] = 600
    data["discharge"] = {"duration": 0.2}
    data["outputs"] = {"sample_interval": 0.005, "results": ["flow_rate", "force_balance"]}
    data["engine"] = {"ranks": 1, "timestep_fraction": 0.2}
    run = siloflow.run(data, tmp_path / "run")
    assert run.state == "complete" and run.record.guard is None


def test_a_few_grains_straying_in_the_fill_are_left_to_the_run_check():
    """A pour loses a few grains to splashes (recorded by the run's check, up to 1 %): not an instability."""
    assert guard().check("fill", 100, ke=1.0, pe=1.0, escaped=3.0, atoms=1000) is None
    assert guard().check("fill", 100, ke=1.0, pe=1.0, escaped=30.0, atoms=1000).signal == "escape"
    assert guard().check("settle", 100, ke=1e-6, pe=1.0, escaped=1.0, atoms=1000).signal == "escape"


def test_the_overlap_limit_is_a_fraction_of_the_smallest_grain_on_top_of_a_clumps_own_overlap():
    """Not of the dust's radius; and a clump's own spheres overlap by design (wheat: 2 + 2 - 1 = 3 mm
    for spheres of 2 mm radius 1 mm apart), which LIGGGHTS lists among the pair contacts."""
    data = yaml.safe_load((SMALL.parent / "clump_silo.yaml").read_text())
    plan = derive(case_from_dict(data))
    clump = plan.grains[0]
    r_grain = clump.radius
    assert plan.dust is not None and plan.dust.radius < r_grain
    spheres = clump.spheres
    own = max(a[3] + b[3] - math.dist(a[:3], b[:3]) for i, a in enumerate(spheres) for b in spheres[i + 1:])
    assert own > r_grain
    assert plan.guard.max_overlap == pytest.approx(plan.guard.max_overlap_fraction * r_grain + own)
    spheres_plan = derive(case_from_dict(yaml.safe_load(SMALL.read_text())))
    assert spheres_plan.guard.max_overlap == pytest.approx(0.5 * spheres_plan.grains[0].radius)


def test_the_guard_keeps_the_largest_speed_and_overlap_it_saw():
    """What the stability envelope reads from the run record (how near its limits a stable run ran)."""
    g = guard()
    assert g.peak_record() is None
    g.check("fill", 0, ke=0.0, pe=0.0, speed=-1e20, overlap=-1e20)          # nothing inserted yet
    g.check("fill", 10, ke=1.0, pe=1.0, speed=2.0, overlap=-1e20)           # no contact yet
    assert g.peak_record() == {"max_speed": 2.0, "max_overlap": 0.0}
    g.check("settle", 20, ke=1e-6, pe=1.0, speed=0.5, overlap=3e-5)
    assert g.peak_record() == {"max_speed": 2.0, "max_overlap": 3e-5}
    off = guard(enabled=False)
    off.check("settle", 0, ke=1e-6, pe=1.0, speed=9.0, overlap=5e-4)
    assert off.peak_record() == {"max_speed": 9.0, "max_overlap": 5e-4}


def test_a_bed_that_never_settles_at_a_long_step_is_told_to_shorten_it():
    """At 0.5 t_c the accuracy bench's beds kept jittering (KE/PE above 1e-4 after 1 s): the message names the
    time step and its fix first; at a short step it says what it always said."""
    from types import SimpleNamespace
    from siloflow.engine.processes import RESTLESS_FRACTION, not_settled
    what, cause, fix = not_settled(4.8e-4, SimpleNamespace(timestep=SimpleNamespace(fraction=0.5)))
    assert "did not settle" in what and "0.00048" in what
    assert "0.5 of the critical time" in cause and "stability edge" in cause
    assert fix.startswith(f"lower engine.timestep_fraction to {RESTLESS_FRACTION:g} or less")
    what, cause, fix = not_settled(4.8e-4, SimpleNamespace(timestep=SimpleNamespace(fraction=0.1)))
    assert "stability edge" not in cause and fix == "raise fill.settle.max_time or fill.settle.ke_pe_ratio"


def test_rows_before_any_grain_leave_no_peak_speed():
    """LIGGGHTS' max over no atoms is -1e20: a run stopped before its first grain has no peaks (the stability
    envelope had printed a speed ratio of -1.5e19 for such runs)."""
    from siloflow.guard import RunGuard
    from siloflow.plan import Guard
    limits = Guard(enabled=True, max_speed=10.0, max_overlap=1e-3, max_overlap_fraction=0.5, grain_radius=2e-3,
                   energy_growth=10.0, escape_z=1.0)
    guard = RunGuard(limits)
    assert guard.check("fill", 0, 0.0, 0.0, speed=-1e20, overlap=-1e20) is None
    assert guard.peak_record() is None
    guard.check("fill", 100, 1e-3, 1.0, speed=2.0, overlap=1e-4)
    assert guard.peak_record() == {"max_speed": 2.0, "max_overlap": 1e-4}
