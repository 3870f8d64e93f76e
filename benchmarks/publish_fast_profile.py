"""Write siloflow/fast_profile.json (what ``engine.profile: fast`` applies) from the committed accuracy
benchmark's recommendation, benchmarks/results/accuracy/recommended_profile.json (``make bench-accuracy``).

    python benchmarks/publish_fast_profile.py

tests/test_profiles.py checks that the two agree.
"""
from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "benchmarks" / "results" / "accuracy" / "recommended_profile.json"
TARGET = ROOT / "siloflow" / "fast_profile.json"
KEEP = ("candidate", "timestep_fraction", "stiffness_scale", "speedup", "speedup_lo", "speedup_hi", "error_bounds",
        "rel_errors", "tolerances", "confidence", "seeds", "reference_seeds", "ranks", "benchmark")


def main() -> None:
    rec = json.loads(SOURCE.read_text())
    if rec is None:
        raise SystemExit(f"{SOURCE} recommends nothing: no candidate met the tolerances")
    out = {k: rec[k] for k in KEEP if k in rec}
    out["benchmark"] = (f"benchmarks/cases/accuracy_small.yaml ({rec.get('reference_seeds')} reference runs, "
                        f"{rec.get('seeds')} of the profile; make bench-accuracy)")
    TARGET.write_text(json.dumps(out, indent=1) + "\n")
    print(f"{TARGET}: {out['candidate']} (timestep_fraction {out['timestep_fraction']}, stiffness_scale "
          f"{out['stiffness_scale']})")


if __name__ == "__main__":
    main()
