"""Write siloflow/fast_profile.json (what ``engine.profile: fast`` applies) from the committed accuracy
benchmark's recommendation, benchmarks/results/accuracy/recommended_profile.json (``make bench-accuracy``).

    python benchmarks/publish_fast_profile.py

It refuses a recommendation that is the reference itself (nothing faster proven), that did not meet
its tolerances, or whose check with new seeds (``siloflow bench --validate``) is missing for a bounded
quantity or put its error outside the bound, or any of whose new seeds' runs failed. tests/test_profiles.py checks that the two files agree.
"""
from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "benchmarks" / "results" / "accuracy" / "recommended_profile.json"
TARGET = ROOT / "siloflow" / "fast_profile.json"
KEEP = ("candidate", "timestep_fraction", "overlap_ratio", "stiffness_scale", "speedup", "speedup_lo", "speedup_hi",
        "error_bounds", "rel_errors", "tolerances", "confidence", "seeds", "reference_seeds", "fill_only_seeds", "ranks",
        "validation")


def main() -> None:
    rec = json.loads(SOURCE.read_text())
    if rec is None or rec.get("candidate") == "reference":
        raise SystemExit(f"{SOURCE}: nothing faster than the reference is proven within the tolerances")
    if not rec.get("meets_tolerances"):
        raise SystemExit(f"{SOURCE}: the recommendation does not meet its tolerances")
    checks = rec.get("validation") or []
    checked = {c["quantity"] for c in checks if c["inside"]}
    if not checks or set(rec.get("error_bounds", {})) - checked:
        raise SystemExit(f"{SOURCE}: the recommendation was not confirmed with new seeds (siloflow bench --validate)")
    if any(c.get("failed") for c in checks):
        raise SystemExit(f"{SOURCE}: runs of the recommendation's new seeds failed (runs.csv says why)")
    out = {k: rec[k] for k in KEEP if k in rec}
    fills = f" (and {rec['fill_only_seeds']} fill-only fills of the profile)" if rec.get("fill_only_seeds") else ""
    out["benchmark"] = (f"benchmarks/cases/accuracy_small.yaml, {rec.get('reference_seeds')} reference runs and "
                        f"{rec.get('seeds')} of the profile{fills}, checked with new fills ("
                        + ", ".join(f"{c['quantity']} {c['n']}" for c in checks) + ") (make bench-accuracy)")
    TARGET.write_text(json.dumps(out, indent=1) + "\n")
    print(f"{TARGET}: {out['candidate']} (timestep_fraction {out['timestep_fraction']}, impact overlap "
          f"{out['overlap_ratio']:.3g} of the radius)")


if __name__ == "__main__":
    main()
