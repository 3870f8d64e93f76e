"""The engines siloflow knows, by name: ``"module:class"`` of each, imported only when a case asks
for it (``siloflow.engine.get_engine``). The case schema takes its ``engine.name`` values from here,
so a new engine is one line in this table (and its subpackage under ``siloflow/engine/``)."""
ENGINES = {"liggghts": "siloflow.engine.liggghts.engine:LiggghtsEngine",
           "lammps": "siloflow.engine.lammps.engine:LammpsEngine"}
