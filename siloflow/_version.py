"""siloflow's version, in a module of its own: the run plan and the manifest record it, and the
modules that write them import it from here, not from the package (whose ``__init__`` loads
``siloflow.runs`` on demand, the top of the import graph)."""
__version__ = "0.1.0"
