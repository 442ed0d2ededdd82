"""Run independent jobs on a local process pool or on Ray; report failures with their logs.

Lives here: :class:`JobRunner`, :func:`run_jobs`, :func:`abort_runners`. Not here: the job
and what runs in its worker (:mod:`.worker`: :class:`~.worker.Job`, :class:`~.worker.JobResult`),
the Ray side (:mod:`.ray_backend`), what the jobs do (:mod:`uavris.experiments.training`,
:mod:`uavris.experiments.study.workers`) and the stages that submit them (:mod:`.stages`,
:mod:`uavris.experiments.study.pipeline`).

Each job runs in a worker process (spawned, so torch and numpy start clean) with one thread
in every thread pool (:func:`~.process.configure_threads`) and writes its own log file. A job that
raises is reported and the others go on; the caller decides the exit code from the
returned failures. A worker process that dies (killed by the OOM killer, say) breaks the
local pool and every job running in it: those jobs run once more, each in a process of its
own, and only a job whose process dies again is reported failed ("worker died").

Workers never outlive their command: Ctrl-C and SIGTERM close the runner with ``abort``
(:meth:`JobRunner.close`, :func:`abort_runners`), which stops them, and a worker whose
parent is gone (killed by SIGKILL or the OOM killer, which no handler sees) exits within a
second (:func:`~.worker.new_pool`: each worker watches its parent). The output's lock goes
with the command's process; a worker left running would go on writing into an output that a
rerun may then lock and write too.

Backends: ``local`` (``concurrent.futures`` process pool, the default) and ``ray``
(``pip install 'uavris[ray]'``): without an address a local Ray instance with ``workers``
CPUs is started; with ``ray_address`` the jobs go to that cluster, whose nodes must have
uavris installed but need not share a file system with the driver: each job's files travel
with it (:mod:`.shipping`; what it reads and writes is declared on the :class:`~.worker.Job`). Jobs
are seeded by their own configuration, so both backends give the same results.
"""

from __future__ import annotations

import ctypes
import dataclasses
import heapq
import itertools
import os
import threading
import time
import weakref
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Literal, get_args

from uavris.experiments.engine import ray_backend
from uavris.experiments.engine.process import THREAD_VARIABLES
from uavris.experiments.engine.worker import Job, JobResult, interrupted, new_pool, run_logged

Backend = Literal["local", "ray"]  # where jobs run (--backend)
BACKENDS: tuple[str, ...] = get_args(Backend)
_RUNNERS: weakref.WeakSet[JobRunner] = weakref.WeakSet()  # every runner of this process, for abort_runners
_RUNNERS_LOCK = threading.Lock()  # abort_runners reads _RUNNERS in a thread of its own


def _interrupt_thread(ident: int) -> None:
    """Raise KeyboardInterrupt in the thread ``ident`` at its next Python instruction. With one
    worker a study runs each job in the command's own process, in the thread of the job's stage;
    Ctrl-C and SIGTERM land in the main thread, which waits for that thread, so without this the
    job would run to its end (minutes) before the command stopped. CPython's own call for it
    (``PyThreadState_SetAsyncExc``): compiled code (numba, torch) finishes its current call first."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident), ctypes.py_object(KeyboardInterrupt))


def abort_runners() -> None:
    """Close every job runner of this process with ``abort``: how Ctrl-C and SIGTERM reach the
    workers (:mod:`uavris.cli`). The command's main thread unwinds from the signal, but a
    study's stage threads wait for their jobs, and a study waits for its stage threads before
    it closes the runner: without this, the study would go on until its running stages ended
    (SIGTERM reaches the command alone, and pool workers ignore Ctrl-C: :func:`~.worker.new_pool`).
    A program that calls the library gets the same from :meth:`Pipeline.run
    <uavris.experiments.engine.stages.Pipeline.run>` on KeyboardInterrupt."""
    with _RUNNERS_LOCK:
        runners = list(_RUNNERS)
    for runner in runners:
        runner.close(abort=True)


class JobRunner:
    """Runs jobs on ``workers`` processes (or Ray CPUs) shared by every caller.

    :meth:`run` may be called from several threads at once (the stages of a pipeline that
    run concurrently): all their jobs share the one pool, so at most ``workers`` jobs run at
    a time whoever submitted them, and the waiting job with the highest priority starts
    first. A job's priority is what its caller passes (a study passes the expected length
    of the chain that follows the job's stage) plus the job's own expected cost: the longest
    remaining chain first, and within a stage the longest job first (the Ray backend leaves
    the order to Ray). With one local worker the jobs run in the calling thread, one at a
    time. Each result says which worker slot ran it, and when. Use as a context manager,
    or call :meth:`close`.
    """

    def __init__(self, workers: int, backend: str = "local", ray_address: str | None = None) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        self.workers, self.backend, self.ray_address = max(1, int(workers)), backend, ray_address

        for var in THREAD_VARIABLES:  # the workers this runner starts begin with one thread (configure_threads)
            os.environ.setdefault(var, "1")
        self._lock = threading.Condition()
        # one close at a time: a second (the command's, while a signal's aborts) returns when the
        # workers are stopped, not when the first took the pools, so that the output's lock
        # is released after them
        self._close_lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None
        self._stopping: list[ProcessPoolExecutor] = []  # pools a close took, until they are shut down
        self._solos: set[ProcessPoolExecutor] = set()  # a job whose worker died, run again alone
        self._ray_started = False
        self._waiting: list[tuple[float, int, Job, Future[JobResult] | None]] = []  # heap: (-priority, order, ...)
        self._order = itertools.count()
        self._busy = 0
        self._here: int | None = None  # the thread running a job in this process (one worker), while it runs
        self._free = list(range(self.workers))  # worker slots, lowest first
        self._held = False
        self._closing = False  # close() began (Ctrl-C, or the end): nothing new is started
        self.active: dict[int, tuple[Job, float]] = {}  # running jobs by id: (job, time.time() it started)
        with _RUNNERS_LOCK:
            _RUNNERS.add(self)

    def hold(self) -> None:
        """Queue jobs without starting any until :meth:`release`: the callers about to submit
        all get their jobs in line, and the first to start is the one of highest priority."""
        with self._lock:
            self._held = True

    def release(self) -> None:
        with self._lock:
            if self._held:
                self._held = False
                if self._pool is not None:
                    self._dispatch()
                self._lock.notify_all()

    def __enter__(self) -> JobRunner:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        self.close(abort=exc_type is not None)

    def close(self, abort: bool = False) -> None:
        """Start nothing more and shut the pool down: after the running jobs end, or, with
        ``abort`` (Ctrl-C, SIGTERM or an error), stopping them: the workers ignore Ctrl-C and
        SIGTERM reaches the command alone, so a running job would otherwise run to its end
        while the command waits. Returns once the workers
        have ended, also when another thread's close is shutting them down: an abort then
        stops the jobs that close waits for."""
        with self._lock:
            # jobs finishing while the pool shuts down (an abort stops the workers) start nothing
            self._closing = True
            waiting, self._waiting = self._waiting, []
            self._lock.notify_all()  # callers waiting for their turn in this thread (_run_here) give up
            # a job rerun alone (its worker died) runs in a pool of its own, stopped with the rest
            self._stopping += [p for p in (self._pool, *self._solos) if p is not None]
            self._pool, self._solos = None, set()
            pools = list(self._stopping)
        for _, _, job, fut in waiting:  # their callers (a study's stage threads, on SIGTERM) wait on them
            if fut is not None:
                fut.set_result(interrupted(job))
        if abort:
            with self._lock:  # taken once: a second close (the signal's thread and the pipeline both abort) sends none
                here, self._here = self._here, None
            if here is not None and here != threading.main_thread().ident:
                _interrupt_thread(here)
            for pool in pools:
                for process in list((getattr(pool, "_processes", None) or {}).values()):
                    process.terminate()
        with self._close_lock:
            for pool in pools:
                pool.shutdown(cancel_futures=True)  # once shut down, a no-op
                with self._lock:
                    if pool in self._stopping:
                        self._stopping.remove(pool)
            if self._ray_started:
                ray_backend.shutdown()
                self._ray_started = False

    def run(self, jobs: list[Job], on_done: Callable[[JobResult], None] | None = None,
            priority: float = 0.0, on_queued: Callable[[], None] | None = None) -> list[JobResult]:
        """Run ``jobs``; ``on_queued`` is called once they wait in line (with one worker: the
        first of them), ``on_done`` as each finishes. Returns results in finishing order."""
        if not jobs:
            if on_queued:
                on_queued()
            return []
        if self.backend == "ray":
            if on_queued:
                on_queued()
            self.connect()
            with self._lock:
                refs = ray_backend.submit(jobs, self.ray_address)
            return ray_backend.collect(refs, on_done, self.ray_address)
        if self.workers <= 1:
            return [self._run_here(job, on_done, priority, on_queued if i == 0 else None)
                    for i, job in enumerate(jobs)]
        with self._lock:
            futures: dict[Future[JobResult], Job] = {}
            for job in jobs:
                fut: Future[JobResult] = Future()
                if self._closing:  # a stage that goes on after Ctrl-C or SIGTERM closed the runner
                    fut.set_result(interrupted(job))
                else:
                    heapq.heappush(self._waiting, (-(priority + job.cost), next(self._order), job, fut))
                futures[fut] = job
            if not self._closing:
                if self._pool is None:
                    self._pool = new_pool(self.workers)
                self._dispatch()
        if on_queued:
            on_queued()
        results = []
        for fut in as_completed(futures):
            res = fut.result()
            results.append(res)
            if on_done and not self._closing:  # after close, a line per job would bury the interrupt's one
                on_done(res)
        return results

    def _dispatch(self) -> None:
        """Start waiting jobs, highest priority first, while workers are free (lock held)."""
        while self._busy < self.workers and self._waiting and not self._held and not self._closing:
            _, _, job, outer = heapq.heappop(self._waiting)
            self._busy += 1
            slot = heapq.heappop(self._free)
            assert self._pool is not None and outer is not None
            started = time.time()
            self.active[id(job)] = (job, started)
            self._submit(job, outer, slot, started, self._pool, alone=False)

    def _submit(self, job: Job, outer: Future[JobResult], slot: int, started: float, pool: ProcessPoolExecutor,
                alone: bool) -> None:
        """``job`` on ``pool`` (lock held); a pool broken meanwhile is replaced first."""
        if self._closing:
            outer.set_result(interrupted(job))
            return
        try:
            inner = pool.submit(run_logged, job)
        except BrokenProcessPool:
            pool = self._replace_pool(pool)
            inner = pool.submit(run_logged, job)
        inner.add_done_callback(lambda inner: self._finished(inner, job, outer, slot, started, pool, alone))

    def _replace_pool(self, broken: ProcessPoolExecutor) -> ProcessPoolExecutor:
        """A fresh shared pool in place of ``broken`` (lock held; a no-op if already replaced)."""
        if broken is self._pool:
            broken.shutdown(wait=False)
            self._pool = new_pool(self.workers)
        assert self._pool is not None
        return self._pool

    def _finished(self, inner: Future[JobResult], job: Job, outer: Future[JobResult], slot: int,
                  started: float, pool: ProcessPoolExecutor, alone: bool) -> None:
        try:
            res = inner.result()
        except BrokenProcessPool as e:  # a worker died (the OOM killer, a crash in native code)
            with self._lock:
                if not alone and not self._closing:
                    # The pool fails every job it was running, and cannot say whose worker died: run
                    # this one again in a pool of its own, where it can neither take a neighbour
                    # down nor be taken down by one. Dying there too, it failed.
                    self._replace_pool(pool)
                    solo = new_pool(1)
                    self._solos.add(solo)
                    self._submit(job, outer, slot, started, solo, alone=True)
                    return
            # closing, the pool broke because close(abort=True) stopped its workers
            res = interrupted(job) if self._closing else \
                JobResult(job.name, False, None, f"worker died: {type(e).__name__}: {e}", job.log)
        except BaseException as e:  # noqa: BLE001 - whatever else went wrong with the process
            res = JobResult(job.name, False, None, f"worker died: {type(e).__name__}: {e}", job.log)
        if alone:
            with self._lock:
                self._solos.discard(pool)
            pool.shutdown(wait=False)
        res = dataclasses.replace(res, worker=slot, start=started, end=time.time())
        with self._lock:
            self.active.pop(id(job), None)
            self._busy -= 1
            heapq.heappush(self._free, slot)
            self._dispatch()
        outer.set_result(res)

    def _run_here(self, job: Job, on_done: Callable[[JobResult], None] | None, priority: float,
                  on_queued: Callable[[], None] | None = None) -> JobResult:
        """One job in this thread once no other is running and none of higher priority waits."""
        entry = (-(priority + job.cost), next(self._order), job, None)
        with self._lock:
            if not self._closing:
                heapq.heappush(self._waiting, entry)
        if on_queued:
            on_queued()
        started = self._take_turn(entry)
        if started is None:
            return dataclasses.replace(interrupted(job), worker=0)  # no on_done: as in run()
        try:
            res = run_logged(job, in_command=True)
        finally:
            with self._lock:
                self.active.pop(id(job), None)
                self._busy, self._here = 0, None
                self._lock.notify_all()
        res = dataclasses.replace(res, worker=0, start=started, end=time.time())
        if on_done:
            on_done(res)
        return res

    def _take_turn(self, entry: tuple[float, int, Job, None]) -> float | None:
        """Wait until ``entry``'s job may run in this thread, mark it running and return when it
        started; None once the runner is closed (Ctrl-C or SIGTERM): the job does not start."""
        job = entry[2]
        with self._lock:
            while not self._closing and (self._busy or self._held or self._waiting[0] is not entry):
                self._lock.wait()
            if self._closing:
                return None
            heapq.heappop(self._waiting)
            self._busy, self._here = 1, threading.get_ident()
            started = time.time()
            self.active[id(job)] = (job, started)
            return started

    def connect(self) -> None:
        """Start or join Ray (the Ray backend; a no-op once connected or on the local one): a
        cluster that cannot be reached is one :class:`UavrisError`, before any job is queued."""
        if self.backend != "ray":
            return
        with self._lock:
            if ray_backend.connect(self.workers, self.ray_address):
                self._ray_started = True


def run_jobs(jobs: list[Job], workers: int, on_done: Callable[[JobResult], None] | None = None,
             backend: str = "local", ray_address: str | None = None) -> list[JobResult]:
    """Run ``jobs`` on a :class:`JobRunner` of its own (in this process when ``workers`` <= 1 locally)."""
    with JobRunner(workers, backend, ray_address) as runner:
        return runner.run(jobs, on_done)
