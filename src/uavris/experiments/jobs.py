"""Run independent jobs on a local process pool, report failures with their log paths.

Each job runs in its own process (spawned, so torch and numpy start clean) with one torch
thread, writes its own log file, and is retried by nobody: a failed job is reported and
the others go on. The caller decides the exit code from the returned failures.
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


def run_jobs(jobs: list[Job], workers: int, on_done: Callable[[JobResult], None] | None = None) -> list[JobResult]:
    """Run ``jobs`` with ``workers`` processes (in this process when ``workers`` <= 1)."""
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
