"""Jobs on Ray (``--backend ray``, ``pip install 'uavris[ray]'``): a local instance of ``workers``
CPUs, or the cluster at ``ray_address``, whose nodes need not share a file system with the
driver (each job's files travel with it, :mod:`.shipping`).

Lives here: :func:`connect` (start or join Ray, a cluster that cannot be reached one line),
:func:`submit` and :func:`collect` (the jobs sent and their results as they come back: a job
whose worker or node is lost runs again, a job that fails returns its error), :func:`shutdown`.
Not here: the runner that chooses the backend (:mod:`.jobs`), the job itself (:mod:`.worker`).
Ray is imported where it is used: it is an extra.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import threading
from typing import Any, Callable, Iterator

from uavris.errors import UavrisError
from uavris.experiments.engine import shipping
from uavris.experiments.engine.worker import Job, JobResult, run_logged

RAY_SYSTEM_RETRIES = 3  # per job, for system failures only (a lost worker process or node)


def _ray() -> Any:
    """The ``ray`` module, imported on first use (the ray extra); one line where it is not installed."""
    try:
        import ray
    except ImportError:
        raise UavrisError("the Ray backend needs Ray: pip install 'uavris[ray]'") from None
    return ray


def connect(workers: int, ray_address: str | None) -> bool:
    """Start a local Ray instance of ``workers`` CPUs (no address) or join the cluster at
    ``ray_address``; False where Ray is already connected in this process. A cluster that cannot
    be reached is one :class:`UavrisError`, before any job is queued."""
    ray = _ray()
    with _sigterm_kept():
        if ray.is_initialized():
            return False
        if not ray_address:
            # "local": a new instance even where `ray start` left this machine's address behind
            ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False)
        else:
            _reachable(ray_address)
            try:
                ray.init(address=ray_address, log_to_driver=False)
            except (ConnectionError, RuntimeError) as e:
                first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                raise UavrisError(f"cannot join the Ray cluster at {ray_address}: {first} (a cluster "
                                  "with token authentication needs RAY_AUTH_MODE=token and its RAY_AUTH_TOKEN "
                                  "here too)") from None
    return True


def submit(jobs: list[Job], ray_address: str | None) -> dict[Any, Job]:
    """``jobs`` sent to Ray, by their result's reference. A job whose worker or node is lost (a
    preempted cluster node) is run again elsewhere, where it resumes from the checkpoints it had;
    a job that fails is not: it returns its error as a result. On a cluster every job must
    declare the files it writes (they come back with its result)."""
    ray = _ray()
    options = {"num_cpus": 1, "max_retries": RAY_SYSTEM_RETRIES, "retry_exceptions": False}
    if not ray_address:
        return {ray.remote(**options)(run_logged).remote(job): job for job in jobs}
    undeclared = [job.name for job in jobs if not job.writes]
    if undeclared:
        raise ValueError(f"jobs {undeclared} declare no files they write; a cluster cannot run them")
    remote = ray.remote(**options)(shipping.run_shipped)
    return {remote.remote(job, shipping.pack((*job.reads, *shipping.outputs(job))), run_logged): job for job in jobs}


def collect(refs: dict[Any, Job], on_done: Callable[[JobResult], None] | None,
            ray_address: str | None) -> list[JobResult]:
    """The results of :func:`submit`'s jobs as they end (``on_done`` called on each); on a cluster
    the files each wrote are written here. A worker that died is its job's failure."""
    ray = _ray()
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
            else:
                if ray_address:
                    res, files = res
                    try:
                        shipping.unpack(files, shipping.outputs(job), exact=shipping.outputs(job))
                    except (OSError, ValueError) as e:
                        res = JobResult(job.name, False, None, f"its files could not be written here: {e}", job.log)
            results.append(res)
            if on_done:
                on_done(res)
    return results


def shutdown() -> None:
    """Leave Ray (a local instance stops)."""
    _ray().shutdown()


@contextlib.contextmanager
def _sigterm_kept() -> Iterator[None]:
    """The process's SIGTERM handler as it was before the block: ``ray.init`` replaces it with
    one that exits at once (status 1 or 15, no line), which would skip the command's own
    (:mod:`uavris.cli`: the one line, exit status 143, the workers stopped first)."""
    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread sets handlers (Ray leaves them alone there too)
        return

    previous = signal.getsignal(signal.SIGTERM)
    try:
        yield
    finally:
        if previous is not None:  # None: set outside Python, which cannot be put back
            signal.signal(signal.SIGTERM, previous)


def _reachable(address: str) -> None:
    """One line when nothing answers at a cluster's ``HOST:PORT`` (Ray itself would retry for
    minutes); other forms of address (``ray://``, ``auto``) are left to Ray."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or "/" in address:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=10).close()
    except OSError as e:
        raise UavrisError(f"cannot reach the Ray cluster at {address}: {e.strerror or e} (is `ray start --head` "
                          "running there, and is the port open?)") from None
