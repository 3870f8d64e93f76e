"""The demo (decks/demo.yaml, ``make demo``) is the silo issue 35 asks for: slender, at least 15
grains across, at least 5 sensor bands under the bed, a mobilised bed, a real material run with
the fast profile without softening, and no physics warning. Its results (resolved flow rate,
static errors, Janssen fit, EN verdicts) are checked by running it: ``make demo``."""
from pathlib import Path

from siloflow.case_file import load_case
from siloflow.derived import derive

DEMO = Path(__file__).resolve().parents[1] / "decks" / "demo.yaml"


def test_demo_is_a_slender_silo_fifteen_grains_across_with_five_bands_under_its_bed():
    case = load_case(DEMO)
    plan = derive(case)
    diameter = 2.0 * case.geometry.radius
    assert diameter / (2.0 * case.particles.radius) >= 15.0
    bed = plan.fill.bed_height_estimate
    assert bed / diameter >= 2.0                                   # EN 1991-4: slender, h_c / d_c >= 2
    tops = case.sensors.heights[1:]
    assert sum(top <= bed for top in tops) >= 5                    # bands wholly under the bed
    assert case.fill.mobilise is not None


def test_demo_runs_the_fast_profile_on_its_material_s_own_stiffness_and_warns_about_nothing():
    case = load_case(DEMO)
    plan = derive(case)
    assert case.engine.profile == "fast"
    assert plan.profile.name == "fast" and plan.profile.stiffness_scale == 1.0
    assert plan.warnings == []
