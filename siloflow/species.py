"""The species of a case's grains as the run plan lists them, and the speed the fill inserts them
at: what the run plan (:mod:`siloflow.derived`) and the numerical profiles (:mod:`siloflow.profiles`,
the fill's impact overlap) both start from, so neither imports the other for it.
"""
from __future__ import annotations

from . import contact_physics as cp
from .case import Case
from .plan import Species

#: speed at which grains are inserted downwards, m/s (keeps batches clear of the region)
INSERTION_SPEED = 1.5


def species_of(case: Case) -> list[Species]:
    """The species of a case's grains, in the plan's order: the size classes (in the order of the
    case's radii) or the clump shape, then the dust."""
    p = case.particles
    rho = case.materials.particle.density
    out = []
    if p.kind == "clumps":
        clump = p.clump
        out.append(Species(name="clump", kind="clump", stream="grains", radius=max(clump.radii),
                           bounding_radius=clump.bounding_radius, volume=clump.volume, density=rho,
                           number_fraction=1.0, material="particle",
                           spheres=[[*c, r] for c, r in zip(clump.centers, clump.radii)]))
    else:
        many = len(p.radii) > 1
        for k, (r, n) in enumerate(zip(p.radii, p.number_fractions)):
            out.append(Species(name=f"size{k + 1}" if many else "grain", kind="sphere",
                               stream="grains", radius=r, bounding_radius=r, volume=cp.sphere_volume(r),
                               density=rho, number_fraction=n, material="particle"))
    dust = getattr(p, "dust", None)
    if dust is not None:
        out.append(Species(name="dust", kind="sphere", stream="dust", radius=dust.radius,
                           bounding_radius=dust.radius, volume=cp.sphere_volume(dust.radius),
                           density=dust.run_density, number_fraction=1.0, material="dust"))
    return out
