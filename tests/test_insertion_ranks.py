"""An engine fact behind "MPI ranks are not neutral for wall loads" (README, docs/engine_facts.md).

LIGGGHTS' ``fix insert/rate/region`` with ``overlapcheck yes`` inserts no grain within its radius of a
processor-subdomain border (its default ``check_dist_from_subdomain_border yes``), so grains inserted
on two ranks do not rain into a slab about the border plane, and each batch holds fewer grains. The
test renders the accuracy benchmark's case, runs the fill stage's first insertion on 1 and 2 ranks
and compares where the grains were put.
"""
from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

from siloflow.engine import LiggghtsEngine

from conftest import ROOT

pytestmark = [pytest.mark.engine,
              pytest.mark.skipif(shutil.which("liggghts") is None or shutil.which("mpirun") is None,
                                 reason="LIGGGHTS not installed (make install-engine); CI installs it")]

CASE = ROOT / "benchmarks" / "cases" / "accuracy_small.yaml"


def _first_batch(tmp_path, ranks: int) -> np.ndarray:
    """(id, radius, x, y, z) of the grains of the first insertion on ``ranks`` ranks."""
    data = yaml.safe_load(CASE.read_text())
    # pinned settings (not the published fast profile): dt = 0.1 t_c at 1/100 of the stiffness
    data.update(name=f"ins{ranks}", engine={"ranks": ranks, "timestep_fraction": 0.1, "stiffness_scale": 0.01})
    case = tmp_path / f"ins{ranks}.yaml"
    case.write_text(yaml.safe_dump(data))
    folder = tmp_path / f"r{ranks}"
    subprocess.run([sys.executable, "-m", "siloflow.cli", "render", str(case), "-o", str(folder)],
                   check=True, capture_output=True)
    text = (folder / "in.liggghts").read_text()
    cut = text.index("\nrun ", text.index("SILOFLOW_STAGE fill"))
    (folder / "first.in").write_text(text[:cut] + "\ndump first all custom 1 first.dump id radius x y z\nrun 2\n")
    subprocess.run(LiggghtsEngine().command(ranks, deck="first.in", log="first.log"), cwd=folder, check=True,
                   capture_output=True)
    frame = (folder / "first.dump").read_text().split("ITEM: TIMESTEP")[-1].splitlines()
    start = next(i for i, line in enumerate(frame) if line.startswith("ITEM: ATOMS")) + 1
    return np.loadtxt(frame[start:], ndmin=2)


def test_two_ranks_insert_no_grain_within_its_radius_of_the_subdomain_border(tmp_path):
    one, two = _first_batch(tmp_path, 1), _first_batch(tmp_path, 2)
    near = lambda a: np.mean(np.abs(a[:, 2]) < a[:, 1])       # noqa: E731 (centre within a radius of x = 0)
    # one rank: the rain covers the plane x = 0 like any other (14 % of the grains of this batch)
    assert len(one) > 200 and near(one) > 0.08
    # two ranks (a 2 x 1 x 1 grid split at x = 0): none there, and the batch is smaller
    assert "2 by 1 by 1" in (tmp_path / "r2" / "first.log").read_text()
    assert near(two) == 0.0
    assert len(two) < 0.9 * len(one)
