"""Write siloflow/fast_profile.json (what ``engine.profile: fast`` applies) from the committed accuracy
benchmark's recommendations, benchmarks/results/accuracy/recommended_profile.json (``make bench-accuracy``):
one profile per question (``siloflow.packaged_profile.QUESTIONS``: the flow rate alone, with the static
wall pressure, everything).

    python benchmarks/publish_fast_profile.py

A question's recommendation is published only when it is faster than the reference, met its
tolerances, and its check with new seeds (``siloflow bench --validate``) covered every bounded
quantity, put each error inside its bound and lost no run; a question without one is left out (said
here), and a case asking it runs the profile bounding the most of what it asks. Nothing is written
unless the recommendation of flow rate and static pressure is published. tests/test_profiles.py checks
that the two files agree.
"""
from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "benchmarks" / "results" / "accuracy" / "recommended_profile.json"
TARGET = ROOT / "siloflow" / "fast_profile.json"
KEEP = ("candidate", "timestep_fraction", "overlap_ratio", "stiffness_scale", "speedup", "speedup_lo", "speedup_hi",
        "error_bounds", "rel_errors", "measured", "tolerances", "confidence", "seeds", "reference_seeds",
        "fill_only_seeds", "ranks", "validation")
#: the question that must be published (what a case asking for everything ran before there were questions)
REQUIRED = "flow_rate_and_static_pressure"


def refusal(rec: dict | None) -> str | None:
    """Why a recommendation cannot be published (None: it can)."""
    if rec is None or rec.get("candidate") == "reference":
        return "nothing faster than the reference is proven within the tolerances"
    if not rec.get("meets_tolerances"):
        return "the recommendation does not meet its tolerances"
    checks = rec.get("validation") or []
    checked = {c["quantity"] for c in checks if c["inside"]}
    if not checks or set(rec.get("error_bounds", {})) - checked:
        return "the recommendation was not confirmed with new seeds (siloflow bench --validate)"
    if any(c.get("failed") for c in checks):
        return "runs of the recommendation's new seeds failed (runs.csv says why)"
    return None


def published(rec: dict) -> dict:
    """The record of one question's profile as fast_profile.json holds it."""
    out = {k: rec[k] for k in KEEP if k in rec}
    fills = f" (and {rec['fill_only_seeds']} fill-only fills of the profile)" if rec.get("fill_only_seeds") else ""
    out["benchmark"] = (f"benchmarks/cases/accuracy_small.yaml, {rec.get('reference_seeds')} reference runs and "
                        f"{rec.get('seeds')} of the profile{fills}, checked with new fills ("
                        + ", ".join(f"{c['quantity']} {c['n']}" for c in rec["validation"]) + ") (make bench-accuracy)")
    return out


def main() -> None:
    rec = json.loads(SOURCE.read_text())
    questions = (rec or {}).get("questions") or {}
    if REQUIRED not in questions:
        raise SystemExit(f"{SOURCE}: no recommendation for {REQUIRED} (a bench concluded by an older siloflow: "
                         "siloflow bench --conclude rewrites it)")
    profiles = {}
    for question, r in questions.items():
        why = refusal(r)
        if why is None:
            profiles[question] = published(r)
        elif question == REQUIRED:
            raise SystemExit(f"{SOURCE}: {question}: {why}")
        else:
            print(f"{question}: not published: {why}")
    TARGET.write_text(json.dumps({"profiles": profiles}, indent=1) + "\n")
    for question, p in profiles.items():
        print(f"{TARGET}: {question}: {p['candidate']} (timestep_fraction {p['timestep_fraction']}, impact overlap "
              f"{p['overlap_ratio']:.3g} of the radius, {p['speedup']:.3g}x)")


if __name__ == "__main__":
    main()
