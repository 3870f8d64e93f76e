"""One MPI rank of a LAMMPS run: ``mpirun -np N python -m siloflow.engine.lammps.worker FOLDER
[--resume]``, started by :class:`~siloflow.engine.lammps.engine.LammpsEngine`. Rank 0 reports the
progress (``SILOFLOW_PROGRESS stage step total``) and LAMMPS' error (``SILOFLOW_ERROR message``) on
its standard output, which the engine reads."""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    folder = Path(argv[0]).resolve()
    resume = "--resume" in argv[1:]
    from ...run_folder import RunFolder
    from .deck import DECK_NAME, LOG_NAME, RESUME_LOG_NAME, sections
    from .driver import Driver
    from .engine import ERROR, PROGRESS
    from .module import load_lammps
    lammps = load_lammps()
    plan = RunFolder(folder).plan
    text = (folder / DECK_NAME).read_text(encoding="utf-8")
    os.chdir(folder)
    lmp = lammps.lammps(cmdargs=["-log", RESUME_LOG_NAME if resume else LOG_NAME, "-screen", "none", "-nocite"])
    rank = int(lmp.extract_setting("world_rank"))

    def progress(stage: str, step: int, total: int) -> None:
        print(f"{PROGRESS}{stage} {step} {total}", flush=True)

    def interrupted(signum, frame):
        raise KeyboardInterrupt      # the engine's stop (SIGTERM): the driver writes its state on the way out
    signal.signal(signal.SIGTERM, interrupted)
    try:
        Driver(lmp, plan, sections(text), Path("."), progress if rank == 0 else None, rank=rank).run(resume=resume)
    except (Exception, KeyboardInterrupt) as exc:
        # an error may be raised on one rank only (LAMMPS' error->one): whichever rank has it says so,
        # and ends the job at once rather than wait for the others in a collective call
        if not isinstance(exc, KeyboardInterrupt):
            print(f"{ERROR}{' '.join(str(exc).split())} (MPI rank {rank})", flush=True)
        os._exit(1)
    lmp.close()
    lmp.finalize()              # MPI_Finalize: the ranks end together
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
