"""The dust time-step remedy, measured: the same clumps + dust silo run with the dust at its own
density and with the dust density scaled (``particles.dust.density_scale``), plus a second seed
at the true density to show the run-to-run noise any change must exceed.

Prints, per run: time step, engine wall time, dust mass share, static wall pressure of the
lowest band, steady flow rate Wf and settled bulk solid fraction, and their ratios to the
unscaled run. One run each (a noisy machine: read the ratios).

    python benchmarks/dust_density_scaling.py [case.yaml] [scale ...]

Default case: tests/data/clump_silo.yaml (600 wheat clumps, 60 dust balls, Hertz), scales 25,
200 and 1000. About 10 minutes on this machine (multisphere runs on one core). A variant that
fails (e.g. a bed that no longer settles in the allowed time) is reported as such.
"""
from __future__ import annotations

import copy
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from postprocess.first_results import analyse  # noqa: E402
from siloflow.case import case_from_dict  # noqa: E402
from siloflow.derived import derive  # noqa: E402
from siloflow.engine import LiggghtsEngine  # noqa: E402
from siloflow.errors import EngineRunError  # noqa: E402


def measure(data: dict, folder: Path) -> dict:
    case = case_from_dict(data)
    d = derive(case)
    record = LiggghtsEngine().run(case, folder)
    summary = analyse(folder)
    dust_mass = d.dust_count * d.dust.mass
    fa = summary.get("frame_analyses", {})
    return {"scale": case.particles.dust.density_scale, "seed": case.seed, "dt": d.timestep,
            "dt_without_dust": d.timestep_without_dust, "wall_s": record.wall_time,
            "dust_mass_share": dust_mass / d.total_mass,
            "p_static_band0": summary["bands"][0]["static_pressure"],
            "flow_rate": summary["flow_rate"]["rate"],
            "bulk_phi": fa.get("bulk_solid_fraction") if isinstance(fa.get("bulk_solid_fraction"), float) else float("nan")}


def main(case_file: Path, scales: list[float]) -> None:
    base = yaml.safe_load(case_file.read_text())
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        variants = [(1.0, base["seed"]), (1.0, base["seed"] + 1)] + [(s, base["seed"]) for s in scales]
        for k, (scale, seed) in enumerate(variants):
            data = copy.deepcopy(base)
            data["particles"]["dust"]["density_scale"] = scale
            data["seed"] = seed
            try:
                runs.append(measure(data, Path(tmp) / f"run{k}"))
            except EngineRunError as exc:          # a failed variant is a result too: say what failed
                print(f"density_scale {scale:g} seed {seed}: FAILED: {str(exc).splitlines()[0]}", flush=True)
                continue
            r = runs[-1]
            print(f"density_scale {scale:g} seed {seed}: dt {r['dt']:.3g} s (without dust {r['dt_without_dust']:.3g} s), "
                  f"engine {r['wall_s']:.1f} s, dust {100 * r['dust_mass_share']:.2f} % of the mass", flush=True)
    ref = runs[0]
    print(f"\n{'scale':>7} {'seed':>6} {'dt/dt1':>7} {'time/t1':>8} {'dust %':>7} {'p0 (Pa)':>9} {'p0/p0_1':>8} "
          f"{'Wf (g/s)':>9} {'Wf/Wf_1':>8} {'phi':>6}")
    for r in runs:
        print(f"{r['scale']:>7g} {r['seed']:>6} {r['dt'] / ref['dt']:>7.2f} {r['wall_s'] / ref['wall_s']:>8.2f} "
              f"{100 * r['dust_mass_share']:>7.2f} {r['p_static_band0']:>9.1f} {r['p_static_band0'] / ref['p_static_band0']:>8.3f} "
              f"{1000 * r['flow_rate']:>9.2f} {r['flow_rate'] / ref['flow_rate']:>8.3f} {r['bulk_phi']:>6.3f}")
    print("\nthe second seed at density_scale 1 is the noise: a change smaller than its ratio is not measured")


if __name__ == "__main__":
    args = sys.argv[1:]
    case = Path(args[0]) if args and args[0].endswith(".yaml") else ROOT / "tests" / "data" / "clump_silo.yaml"
    scales = [float(a) for a in args if not a.endswith(".yaml")] or [25.0, 200.0, 1000.0]
    main(case, scales)
