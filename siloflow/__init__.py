"""siloflow: silo discharge simulations with LIGGGHTS/LAMMPS, from a YAML case file to results."""
__version__ = "0.1.0"
