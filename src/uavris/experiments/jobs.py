"""Run independent jobs on a local process pool or on Ray; report failures with their logs.

Each job runs in its own process (spawned, so torch and numpy start clean) with one torch
thread, writes its own log file, and is retried by nobody: a failed job is reported and
the others go on. The caller decides the exit code from the returned failures.

Backends: ``local`` (``concurrent.futures`` process pool, the default) and ``ray``
(``pip install 'uavris[ray]'``): without an address a local Ray instance with ``workers``
CPUs is started; with ``ray_address`` the jobs go to that cluster, whose nodes must have
uavris installed and see the output directory (a shared file system). Jobs are seeded by
their own configuration, so both backends give the same results.
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable


@dataclass(frozen=True)
class Job:
    """A picklable unit of work: ``fn(*args)`` with its output going to ``log``."""

    name: str
    fn: Callable[..., Any]
    args: tuple[Any, ...]
    log: Path


@dataclass(frozen=True)
class JobResult:
    name: str
    ok: bool
    value: Any
    error: str | None
    log: Path


def _run_logged(job: Job) -> JobResult:
    job.log.parent.mkdir(parents=True, exist_ok=True)
    with open(job.log, "a", encoding="utf-8") as log:
        old_out, old_err = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = log
        try:
            import torch

            torch.set_num_threads(1)
            value = job.fn(*job.args)
            return JobResult(job.name, True, value, None, job.log)
        except BaseException as e:  # noqa: BLE001 - report every failure, keep the pool alive
            traceback.print_exc()
            return JobResult(job.name, False, None, f"{type(e).__name__}: {e}", job.log)
        finally:
            sys.stdout, sys.stderr = old_out, old_err


BACKENDS = ("local", "ray")


def run_jobs(jobs: list[Job], workers: int, on_done: Callable[[JobResult], None] | None = None,
             backend: str = "local", ray_address: str | None = None) -> list[JobResult]:
    """Run ``jobs`` with ``workers`` processes (in this process when ``workers`` <= 1 locally)."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if backend == "ray":
        return _run_ray(jobs, workers, ray_address, on_done)
    results: list[JobResult] = []
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            res = _run_logged(job)
            results.append(res)
            if on_done:
                on_done(res)
        return results
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        futures = {pool.submit(_run_logged, job): job for job in jobs}
        for fut in as_completed(futures):
            job = futures[fut]
            try:
                res = fut.result()
            except BaseException as e:  # noqa: BLE001 - a worker that died (e.g. killed by the OOM killer)
                res = JobResult(job.name, False, None, f"worker died: {type(e).__name__}: {e}", job.log)
            results.append(res)
            if on_done:
                on_done(res)
    return results


def _run_ray(jobs: list[Job], workers: int, address: str | None,
             on_done: Callable[[JobResult], None] | None) -> list[JobResult]:
    try:
        import ray
    except ImportError:
        raise ImportError("the Ray backend needs Ray: pip install 'uavris[ray]'") from None
    if not jobs:
        return []
    started_here = not ray.is_initialized()
    if started_here:
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=max(1, workers), include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(_run_logged)
        refs = {remote.remote(job): job for job in jobs}
        pending = list(refs)
        results: list[JobResult] = []
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                job = refs[ref]
                try:
                    res = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a worker that died
                    res = JobResult(job.name, False, None, f"ray worker died: {type(e).__name__}: {e}", job.log)
                results.append(res)
                if on_done:
                    on_done(res)
        return results
    finally:
        if started_here:
            ray.shutdown()
