"""What LIGGGHTS' own insertion (``fix insert/rate/region``) did to a fill's batches.

Only clumps and their dust go in this way now (spheres are placed by siloflow: ``siloflow.fill_placement``).
Each batch is placed by random sequential insertion, largest first, and a batch asking for more than
fits comes in short of what it could not place; LIGGGHTS warns "Less insertions than requested".
"""
from __future__ import annotations


def short_batches_note(batches: dict[str, list[int]], short: dict[str, list[int]], planned: dict[str, int]) -> list[str]:
    """The run's warnings for insertion fixes whose batches came in short: ``batches`` what each
    batch of a fix placed, ``short`` what its short ones placed, ``planned`` the planned batch per
    fix (``ins`` grains, ``ins_dust`` dust spheres)."""
    out = []
    for fix, what in (("ins", "grain"), ("ins_dust", "dust")):
        got = short.get(fix) or []
        if not got:
            continue
        placed = f"{min(got)}" if min(got) == max(got) else f"{min(got)}-{max(got)}"
        out.append(f"siloflow: {len(got)} of {len(batches.get(fix, []))} {what} batches came in short (placed "
                   f"{placed}, batches of {planned.get(fix, 0)} planned; LIGGGHTS could not place the rest without "
                   "overlaps): the fill took longer than planned, and dust that came in short went in later than "
                   "its grains; lower fill.batch_volume_fraction (a pour: lengthen fill.pour_time)")
    return out
