"""Runs of a study within a core budget, each through the run API (:mod:`siloflow.runs`), shared
by the sweep (:mod:`siloflow.sweep`) and the run table (:func:`siloflow.run_table.run_missing`).

A study hands :func:`run_jobs` an order (which :class:`Job` may start now; told of each start and
end) and a core budget. With ``isolate`` each job runs in a worker process of its own, forked from
this one (no command line, no ``siloflow`` subprocess): a new session, its output appended to its
log, SIGTERM stopping it as Ctrl-C stops ``siloflow run`` (the engine stopped, the folder marked
interrupted); jobs go in parallel while their ``ranks`` add up to at most the budget. Without, the
jobs run one after the other in this process. Either way a job ends with :class:`Outcome`: an exit
code as ``siloflow run``'s (0 complete, 1 failed, 130 interrupted). Ctrl-C (or SIGTERM turned into
it) in this process stops the running workers (SIGTERM, SIGKILL of their process group after
``STOP_GRACE`` s), reaps them and is raised again.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Protocol

from .errors import CaseError, SetupError, SiloflowError

#: s between two looks at the running workers
POLL_INTERVAL = 0.05
#: s a stopped worker gets to stop its engine (the engine: 10 s SIGTERM + 5 s SIGKILL) before SIGKILL
STOP_GRACE = 30.0
#: exit codes of a job, as ``siloflow run``'s
COMPLETE, FAILED, INTERRUPTED = 0, 1, 130


@dataclass(frozen=True)
class Job:
    """One run: its ``name``, the MPI ``ranks`` it takes from the budget, ``work`` (called in the
    worker, or here: runs the API; raises ``SiloflowError`` when the run fails) and, for a worker,
    the ``log`` its output is appended to (None: this process's stdout and stderr)."""

    name: str
    work: Callable[[], object]
    ranks: int = 1
    log: Optional[Path] = None


@dataclass(frozen=True)
class Outcome:
    """How a job ended: ``returncode`` 0 (complete), 1 (failed), 130 (interrupted), a signal's
    negative number (killed); ``reason``: the failure's message when it ran here ("" otherwise)."""

    returncode: int
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.returncode == COMPLETE


class Order(Protocol):
    """Which jobs may start, in priority order; told of each start and end."""

    def ready(self) -> list[Job]: ...

    def started(self, job: Job) -> None: ...

    def finished(self, job: Job, outcome: Outcome) -> None: ...


class InOrder:
    """The jobs one after the other, as given."""

    def __init__(self, jobs: list[Job]):
        self.waiting = list(jobs)

    def ready(self) -> list[Job]:
        return self.waiting[:1]

    def started(self, job: Job) -> None:
        self.waiting.remove(job)

    def finished(self, job: Job, outcome: Outcome) -> None:
        pass


def failure_text(exc: SiloflowError) -> str:
    """A siloflow error as ``siloflow run`` prints it: its kind, then its message."""
    kind = "invalid case" if isinstance(exc, CaseError) else type(exc).__name__
    return f"siloflow: {kind}\n{exc}"


def run_here(job: Job) -> Outcome:
    """Run ``job`` in this process: 0, or 1 with the message of the ``SiloflowError`` that failed
    it. Ctrl-C is raised on (the engine is stopped and the folder marked interrupted by then)."""
    try:
        job.work()
    except SiloflowError as exc:
        return Outcome(FAILED, str(exc))
    return Outcome(COMPLETE)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _in_worker(job: Job) -> None:
    """The worker process's body: its own session, output to the log, SIGTERM as Ctrl-C; exits with
    the job's code (a failure's message and an unexpected error's traceback in the log)."""
    os.setsid()                        # the terminal's Ctrl-C reaches the sweep, which stops the workers
    signal.signal(signal.SIGTERM, _raise_interrupt)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    if job.log is not None:
        fd = os.open(job.log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    # new file objects on fds 1 and 2: those inherited may hold a lock another thread of the parent held
    sys.stdout = open(1, "w", encoding="utf-8", errors="replace", buffering=1, closefd=False)
    sys.stderr = open(2, "w", encoding="utf-8", errors="replace", buffering=1, closefd=False)
    os.environ["COLUMNS"] = "200"
    code = COMPLETE
    try:
        job.work()
    except KeyboardInterrupt:
        code = INTERRUPTED
    except SiloflowError as exc:
        print(failure_text(exc), file=sys.stderr)
        code = FAILED
    except SystemExit as exc:          # a job that exits as a command would: its code
        code = exc.code if isinstance(exc.code, int) else COMPLETE if exc.code is None else FAILED
        if not isinstance(exc.code, (int, type(None))):
            print(exc.code, file=sys.stderr)
    except BaseException:              # a bug: its traceback in the log, the run failed
        traceback.print_exc()
        code = FAILED
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)                     # not the parent's exit handlers, copied by the fork


@dataclass
class _Worker:
    job: Job
    process: multiprocessing.process.BaseProcess


def _start(job: Job) -> _Worker:
    try:
        process = multiprocessing.get_context("fork").Process(target=_in_worker, args=(job,), name=job.name,
                                                             daemon=False)
        process.start()
    except OSError as exc:
        raise SetupError(f"cannot start a worker process for {job.name}: {exc.strerror or exc}") from None
    return _Worker(job, process)


def stop(workers: list[_Worker], grace: float = STOP_GRACE) -> None:
    """SIGTERM every running worker (its run stops its engine and marks its folder interrupted) and
    wait for it; SIGKILL its process group after ``grace`` s. Every worker is reaped."""
    for w in workers:
        if w.process.exitcode is None:
            try:
                os.kill(w.process.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + grace
    for w in workers:
        w.process.join(max(0.0, deadline - time.monotonic()))
        if w.process.exitcode is None:
            try:
                os.killpg(w.process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            w.process.join()


def run_jobs(order: Order, cores: int, on_end: Callable[[Job, Outcome], None],
             on_change: Optional[Callable[[list[str]], None]] = None, isolate: bool = True,
             poll: float = POLL_INTERVAL) -> None:
    """Run the jobs ``order`` hands out until it has none left: in worker processes while their
    ranks add up to at most ``cores`` (``isolate``), else one at a time here. ``on_end(job,
    outcome)`` is told of each end, ``on_change(names running)`` of every start and end. Ctrl-C
    stops the running workers (:func:`stop`) and is raised again."""
    if not isolate:
        while True:
            ready = order.ready()
            if not ready:
                return
            job = ready[0]
            order.started(job)
            if on_change is not None:
                on_change([job.name])
            outcome = run_here(job)
            order.finished(job, outcome)
            on_end(job, outcome)
            if on_change is not None:
                on_change([])
    running: dict[str, _Worker] = {}
    try:
        changed = True
        while True:
            for name, w in list(running.items()):
                if w.process.exitcode is not None:
                    w.process.join()
                    del running[name]
                    outcome = Outcome(w.process.exitcode)
                    order.finished(w.job, outcome)
                    on_end(w.job, outcome)
                    changed = True
            free = cores - sum(w.job.ranks for w in running.values())
            for job in order.ready():
                if job.ranks <= free:
                    order.started(job)
                    running[job.name] = _start(job)
                    free -= job.ranks
                    changed = True
            if changed and on_change is not None:
                on_change(sorted(running))
            changed = False
            if not running:
                return
            time.sleep(poll)
    except BaseException:              # Ctrl-C, or a worker that could not start
        stop(list(running.values()))
        raise
