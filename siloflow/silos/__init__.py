"""Silo kinds as plug-ins (issue 58): each ``geometry.kind`` is one module here, holding what is
particular to it (its bed volume, insertion region, plan fields, sensors, the engines' primitive
walls, what post-processing asks of it); :mod:`siloflow.silos.registry` finds one by name.

The kinds import nothing of siloflow but its errors, so that the case, the planner, the decks and
post-processing may all ask them (``docs/new_silo.md``)."""
