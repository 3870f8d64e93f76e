"""benchmarks/static_bands.py's force balance of the settled bed: what it reads from a run folder, how it
counts beds with reversed wall friction, and that its comparison finds a shift it should and none it
should not (synthetic ensembles; no engine)."""
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sb():
    spec = importlib.util.spec_from_file_location("static_bands", ROOT / "benchmarks" / "static_bands.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _folder(tmp_path, share, weight=785.0, load=784.0, walls=None):
    (tmp_path / "results").mkdir(parents=True)
    fb = None if share is None else {"weight_N": weight, "wall_and_bottom_load_N": load, "wall_friction_share": share}
    (tmp_path / "results" / "summary.json").write_text(json.dumps({"force_balance": fb}))
    walls = walls if walls is not None else [
        {"name": "band00_s00", "role": "band", "area": 0.03}, {"name": "bottom", "role": "bottom", "area": 0.03},
        {"name": "plate", "role": "plate", "area": 0.019}, {"name": "outlet", "role": "outlet", "area": 0.06}]
    (tmp_path / "plan.json").write_text(json.dumps({"walls": walls}))
    return tmp_path


def test_the_floor_carries_the_load_less_the_side_walls_friction(sb, tmp_path):
    b = sb.balance_of(_folder(tmp_path, share=0.05))
    assert b["wall_friction_share"] == 0.05
    assert b["floor_load"] == pytest.approx(784.0 - 0.05 * 785.0)
    assert b["floor_area"] == pytest.approx(0.049)          # bottom and plate, not the band or the outlet


def test_reversed_friction_puts_more_than_the_load_on_the_floor(sb, tmp_path):
    assert sb.balance_of(_folder(tmp_path, share=-0.03))["floor_load"] == pytest.approx(784.0 + 0.03 * 785.0)


def test_a_run_without_a_force_balance_gives_nan_not_zero(sb, tmp_path):
    b = sb.balance_of(_folder(tmp_path, share=None, walls=[]))
    assert all(math.isnan(b[k]) for k in ("wall_friction_share", "floor_load", "floor_area"))


def test_reversed_beds_counts_negative_shares_with_a_wilson_interval(sb):
    r = sb.reversed_beds(pd.Series([0.05, -0.01, 0.02, np.nan, -0.02, 0.07]))
    assert (r["reversed"], r["beds"]) == (2, 5)
    assert r["reversed_lo"] < 0.4 < r["reversed_hi"]
    none = sb.reversed_beds(pd.Series([0.05] * 40))
    # Wilson's upper end for 0 of 40 at 95 %: z^2 / (n + z^2)
    assert none["reversed"] == 0 and none["reversed_hi"] == pytest.approx(1.96 ** 2 / (40 + 1.96 ** 2), rel=1e-3)
    assert math.isnan(sb.reversed_beds(pd.Series([], dtype=float))["reversed_fraction"])


def _ensemble(name, seeds, share, rng, ratio=1.0):
    """Synthetic settled beds: the floor takes the weight less the wall friction, the bottom band's
    pressure is ``ratio`` times the floor's mean pressure (a Janssen-like lateral ratio) plus noise."""
    s = rng.normal(share, 0.03, len(seeds))
    floor = 785.0 * (1 - s)
    band0 = 0.6 * ratio * floor / 0.049 * rng.normal(1.0, 0.02, len(seeds))
    return pd.DataFrame({"candidate": name, "seed": seeds, "wall_s": 10.0, "machine": "m",
                         "stiffness_scale": 1.0 if name == "reference" else 0.01,
                         "timestep_fraction": 0.02 if name == "reference" else 0.1,
                         "wall_friction_share": s, "floor_load": floor, "band0_pressure": band0,
                         "band0_floor_ratio": band0 * 0.049 / floor})


def test_the_comparison_resolves_a_friction_shift_and_not_a_lateral_ratio_it_lacks(sb):
    rng = np.random.default_rng(3)
    seeds = list(range(100, 140))
    runs = pd.concat([_ensemble("reference", seeds, 0.06, rng), _ensemble("soft", seeds, 0.0, rng)],
                     ignore_index=True)
    t = sb.friction_table(runs).set_index(["candidate", "quantity"])
    share = t.loc[("soft", "wall_friction_share")]
    assert share.resolved and share.ci_hi < 0                       # the walls carry less
    assert t.loc[("soft", "floor_load")].resolved and t.loc[("soft", "floor_load")].rel_error > 0
    assert not t.loc[("soft", "band0_floor_ratio")].resolved         # the over-load is the floor's, not K's
    assert t.loc[("soft", "wall_friction_share")].beds == 40
    assert t.loc[("soft", "wall_friction_share")].reversed > t.loc[("reference", "wall_friction_share")].reversed


def test_softness_order_puts_the_reference_first(sb):
    runs = pd.DataFrame({"candidate": ["b", "reference", "a"], "stiffness_scale": [0.01, 1.0, 0.1],
                         "timestep_fraction": [0.1, 0.02, 0.2]})
    assert sb._by_softness(runs, ["a", "b", "reference"]) == ["reference", "a", "b"]


def test_a_folder_without_its_summary_gives_nan(sb, tmp_path):
    b = sb.balance_of(tmp_path)
    assert all(math.isnan(b[k]) for k in ("wall_friction_share", "floor_load", "floor_area"))
