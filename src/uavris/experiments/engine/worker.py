"""What runs in a job's worker process: the job, its result, its run with its output in its log,
and the watch that ends a worker once the command that started it is gone.

Lives here: :class:`Job`, :class:`JobResult`, :func:`run_logged` (every backend runs a job
through it), :func:`new_pool` (a local pool of spawned workers that watch their parent). Not
here: the runner that queues jobs on a pool or Ray (:mod:`.jobs`, :mod:`.ray_backend`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from uavris.experiments.engine.process import configure_threads


@dataclass(frozen=True)
class Job:
    """A picklable unit of work: ``fn(*args)`` with its output going to ``log``; ``cost`` is
    its expected duration on one core (s, :mod:`.costs`), which orders and weighs it.
    ``reads`` and ``writes``: the files and folders it reads and writes besides its log
    (writes it may resume from included), which go to a cluster node with it and come back."""

    name: str
    fn: Callable[..., Any]
    args: tuple[Any, ...]
    log: Path
    cost: float = 0.0
    reads: tuple[Path, ...] = ()
    writes: tuple[Path, ...] = ()


@dataclass(frozen=True)
class JobResult:
    name: str
    ok: bool
    value: Any
    error: str | None
    log: Path
    worker: int | None = None  # the worker slot that ran it (0 .. workers-1; None on Ray)
    start: float = float("nan")  # time.time() when it started and ended
    end: float = float("nan")


def run_logged(job: Job, in_command: bool = False) -> JobResult:
    """Run ``job`` with its output in its log; a failure is its result. ``in_command``: it runs
    in the command's own process (one worker), where Ctrl-C or SIGTERM is the command's to
    stop on, not this job's failure (the next job would start)."""
    job.log.parent.mkdir(parents=True, exist_ok=True)
    with open(job.log, "a", encoding="utf-8") as log:
        old_out, old_err = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = log
        try:
            configure_threads()
            value = job.fn(*job.args)
            return JobResult(job.name, True, value, None, job.log)
        except BaseException as e:  # noqa: BLE001 - report every failure, keep the pool alive
            if in_command and isinstance(e, KeyboardInterrupt):
                raise
            traceback.print_exc()
            return JobResult(job.name, False, None, f"{type(e).__name__}: {e}", job.log)
        finally:
            sys.stdout, sys.stderr = old_out, old_err


PARENT_POLL_S = 1.0  # how often a worker checks that the command that started it still runs
ORPHANED_EXIT = 143  # a worker's exit status once its command is gone (as if stopped by SIGTERM)


def _watch_parent(parent: int) -> None:
    """Pool initializer: once per worker, a thread that ends the worker when ``parent`` (the
    command's process) is gone. A command killed by SIGKILL or the OOM killer cannot stop its
    workers, and they would finish their jobs into an output whose lock went with it.

    The worker ignores SIGINT: Ctrl-C reaches the terminal's whole process group, and the
    command stops its workers itself (:func:`~.jobs.abort_runners`). A worker left to raise
    KeyboardInterrupt while it waits for a job prints ``Process SpawnProcess-N:`` and a
    traceback beside the command's one line.

    Not ``prctl(PR_SET_PDEATHSIG)``: Linux sends that when the *thread* that started the
    worker ends, and a worker is started by whichever thread submitted to the pool (a stage's
    thread in a study, which ends long before the study). The parent's pid comes from the
    command, not ``os.getppid()`` here, so that a parent that died before this ran is seen."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_when_orphaned, args=(parent,), name="uavris-parent-watch", daemon=True).start()


def _exit_when_orphaned(parent: int, poll_s: float = PARENT_POLL_S) -> None:
    """Exit this process once it is no longer ``parent``'s child (it was re-parented to init or
    a subreaper). ``os._exit``: no cleanup of a job that nobody will read."""
    while os.getppid() == parent:
        time.sleep(poll_s)
    os._exit(ORPHANED_EXIT)


def new_pool(workers: int) -> ProcessPoolExecutor:
    """A process pool whose workers are spawned (torch and numpy start clean) and watch their parent."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                               initializer=_watch_parent, initargs=(os.getpid(),))


def interrupted(job: Job) -> JobResult:
    """The result of a job that the runner's close kept from starting or stopped."""
    return JobResult(job.name, False, None, "interrupted", job.log)
