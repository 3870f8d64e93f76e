"""What siloflow's LIGGGHTS decks ask of ``pair/gran/local`` and ``wall/gran/local`` (the column
layouts those computes write are the dump reader's, ``postprocess.dumps.local_columns``; the
sampled tables are read engine-neutrally by ``siloflow.engine.tables``)."""
from __future__ import annotations

from postprocess.dumps import local_columns  # noqa: F401 (the deck's columns)

#: what siloflow decks ask of wall/gran/local (the force is the force on the particle)
WALL_CONTACT_KEYWORDS = ("pos", "id", "force")
#: what siloflow decks ask of pair/gran/local
CONTACT_KEYWORDS = ("pos", "id", "force", "force_normal")
