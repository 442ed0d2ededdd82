"""How ``reproduce`` runs its stages' jobs: priorities, a progress bar weighed by work, the schedule.

Lives here: :class:`StudyContext`, shared by the stages of one invocation (which run in
threads of this process): the one :class:`~uavris.experiments.engine.jobs.JobRunner`, the priority
of each stage's jobs (the expected length of the chain after the stage, from
:meth:`~uavris.experiments.engine.stages.Pipeline.downstream`), the progress bar, and the record of
which worker ran which job when (the report's schedule). Not here: the stages
(:mod:`.reproduce`), the cost model (:mod:`.costs`), the processes (:mod:`.jobs`).

The bar counts expected seconds of one core, not jobs: a job adds its expected cost when
it finishes, a finished stage the rest of its estimate, so a seconds-long expert and a
minutes-long SAC run weigh what they cost. Its ETA is not the bar's rate but a replay of
what is left (:func:`~uavris.experiments.engine.forecast.eta_seconds`), recorded once a minute in
``schedule.json`` beside tqdm's rate-based one so a run can be checked against its end.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any, Callable

from uavris.errors import UavrisError
from uavris.experiments.engine.forecast import Speeds, eta_seconds
from uavris.experiments.engine.jobs import JobRunner
from uavris.experiments.engine.stages import Pipeline, StageRecord
from uavris.experiments.engine.worker import Job, JobResult

HOLD_LIMIT_S = 30.0  # the longest the runner waits for the first stages to queue their jobs
TICK_S = 2.0  # how often the bar counts the running jobs' progress and redraws its ETA
ETA_LOG_S = 60.0  # how often the ETA is recorded for schedule.json


def stage_line(rec: StageRecord) -> str:
    """What the progress bar prints when a stage ends: a stage finished by an earlier invocation
    is "done earlier" with the wall clock it took then (not a time this invocation spent)."""
    if rec.status == "skipped":
        return f"stage {rec.name} [{rec.key}]: done earlier ({rec.wall_s / 60:.1f} min then), skipped"
    extra = f" ({rec.error})" if rec.error else ""
    return f"stage {rec.name} [{rec.key}]: {rec.status} in {rec.wall_s / 60:.1f} min{extra}"


class StudyContext:
    """The job runner, priorities, progress and schedule shared by a pipeline's stages."""

    def __init__(self, workers: int, backend: str, ray_address: str | None, bar: Any = None,
                 device: str = "cpu", reuse: bool = True) -> None:
        self.workers, self.backend, self.ray_address, self.bar = workers, backend, ray_address, bar
        self.device = device
        self.reuse = reuse  # whether stages may take results kept by an earlier run (False: a run with --force)
        self.runner = JobRunner(workers, backend, ray_address)
        self.failures: list[JobResult] = []
        self.jobs: list[tuple[str, JobResult]] = []  # (stage, result) of every job run, in finishing order
        self._after: dict[str, float] = {}
        self._expected: dict[str, float] = {}
        self._credited: dict[str, float] = {}
        self._job_costs: dict[tuple[str, str], float] = {}
        self._first: set[str] = set()
        self._stages: dict[str, tuple[tuple[str, ...], tuple[float, ...]]] = {}
        self._ended: set[str] = set()
        self._open: dict[str, dict[str, Job]] = {}  # per stage, its submitted jobs not finished yet
        self._speeds = Speeds()  # how long this run's finished jobs took against their expected cost
        self.eta_log: list[tuple[float, float, float]] = []  # (time.time(), our ETA, tqdm's rate ETA) in s
        self._closed = threading.Event()
        self._lock = threading.Lock()

    def plan(self, pipeline: Pipeline) -> None:
        """Priorities and the progress bar's total from the pipeline's expected costs. The runner
        starts nothing until every stage ready at the start has queued its first jobs (or ended),
        so that the first job to run is the one that heads the longest chain, not the first queued."""
        self._after = pipeline.downstream(self.workers)
        self._expected = {name: sum(st.costs) if st.progress_s is None else st.progress_s
                          for name, st in pipeline.stages.items()}
        self._credited = {name: 0.0 for name in pipeline.stages}
        # the ETA's jobs: a stage whose jobs are not known yet weighs its progress estimate
        self._stages = {name: (st.deps, st.costs if st.progress_s is None or not sum(st.costs) else
                               tuple(c * st.progress_s / sum(st.costs) for c in st.costs))
                        for name, st in pipeline.stages.items()}
        self._first = {name for name, st in pipeline.stages.items() if not st.deps}
        if self._first:
            self.runner.hold()
            timer = threading.Timer(HOLD_LIMIT_S, self.runner.release)  # never more than this
            timer.daemon = True  # a study stopped meanwhile exits at once, not when the timer fires
            timer.start()
        if self.bar is not None:
            self.bar.total = sum(self._expected.values())
            self.bar.refresh()
            threading.Thread(target=self._tick, daemon=True).start()

    def _arrived(self, stage: str) -> None:
        """``stage`` queued its jobs or ended: release the runner once every first stage has (lock held)."""
        self._first.discard(stage)
        if not self._first:
            self.runner.release()

    def _tick(self) -> None:
        """Every few seconds, count the running jobs' elapsed time (up to their expected cost) as
        done work, so that a long job moves the bar while it runs, and redraw the ETA."""
        logged = 0.0
        while not self._closed.wait(TICK_S):
            with self._lock:
                now = time.time()
                eta = self._draw(now)
                if now - logged >= ETA_LOG_S:
                    logged = now
                    self.eta_log.append((now, eta, self._rate_eta()))

    def eta(self, now: float) -> float:
        """Seconds until the study ends, from what is left of it (lock held):
        :func:`~uavris.experiments.engine.forecast.eta_seconds` with this run's measured speed."""
        active = list(self.runner.active.values())
        running_ids = {id(job) for job, _ in active}
        stage_of = {id(j): name for name, jobs in self._open.items() if name not in self._ended for j in jobs.values()}
        running = [(stage_of[id(job)], job.cost, now - start) for job, start in active if id(job) in stage_of]
        stages = {}
        for name, (deps, costs) in self._stages.items():
            if name in self._ended:
                continue
            if name in self._open:
                costs = tuple(j.cost for j in self._open[name].values() if id(j) not in running_ids)
            stages[name] = (deps, costs)
        return eta_seconds(stages, self._after, self.workers, self._ended, running, self._speeds)

    def _rate_eta(self) -> float:
        """tqdm's own ETA for comparison: the work left over the rate of the work so far (lock held)."""
        elapsed = self.bar.format_dict.get("elapsed", 0.0) if hasattr(self.bar, "format_dict") else 0.0
        if not self.bar.n or not elapsed:
            return float("nan")
        return (self.bar.total - self.bar.n) / (self.bar.n / elapsed)

    def _draw(self, now: float) -> float:
        """The bar's count (credited work plus the running jobs' elapsed time up to their cost,
        never past the total, which tqdm would print as 0%) and its ETA, which it returns (lock held)."""
        partial = sum(min(now - start, job.cost) for job, start in list(self.runner.active.values()))
        self.bar.n = min(self.bar.total, sum(self._credited.values()) + partial)
        eta = self.eta(now) if self._stages else 0.0
        self.bar.postfix = f"ETA {_clock(eta)}" if self._stages else ""
        self.bar.refresh()
        return eta

    def priority(self, stage: str) -> float:
        """Expected seconds of the longest chain after ``stage`` (its jobs add their own cost)."""
        return self._after.get(stage, 0.0)

    def job_done(self, stage: str) -> Callable[[JobResult], None]:
        """The callback of ``stage``'s jobs: progress, a line, the schedule and failures."""
        def done(res: JobResult) -> None:
            with self._lock:
                self.jobs.append((stage, res))
                if not res.ok:
                    self.failures.append(res)
                self._open.get(stage, {}).pop(res.name, None)
                self._speeds.add(stage, self._job_costs.get((stage, res.name), 0.0), res.end - res.start)
                if self.bar is not None:
                    self._credit(stage, self._job_costs.get((stage, res.name), 0.0))
                    status = "done" if res.ok else f"FAILED ({res.error}); log: {res.log}"
                    self.bar.write(f"  job {res.name}: {status}")
        return done

    def submit(self, stage: str, jobs: list[Job]) -> list[JobResult]:
        """Run ``stage``'s jobs at its priority; returns their results in finishing order."""
        with self._lock:
            self._job_costs.update({(stage, j.name): j.cost for j in jobs})
            self._open.setdefault(stage, {}).update({j.name: j for j in jobs})
            if self.bar is not None and jobs:  # every stage submits its jobs at once: now its work is known
                known = sum(j.cost for j in jobs) + self._credited.get(stage, 0.0)
                self.bar.total += known - self._expected.get(stage, 0.0)
                self._expected[stage] = known
        return self.runner.run(jobs, self.job_done(stage), self.priority(stage), lambda: self._queued(stage))

    def _queued(self, stage: str) -> None:
        with self._lock:
            self._arrived(stage)

    def run_all(self, stage: str, jobs: list[Job], what: str = "job") -> list[JobResult]:
        """:meth:`submit`, then one :class:`UavrisError` naming every failed job and its log."""
        results = self.submit(stage, jobs)
        failures = [r for r in results if not r.ok]
        if failures:
            raise UavrisError(f"{len(failures)} {what}(s) failed: "
                              + "; ".join(f"{f.name} ({f.error}; log {f.log})" for f in failures))
        return results

    def run_one(self, stage: str, fn: Any, args: tuple[Any, ...], log: Path, cost: float,
                reads: tuple[Path, ...] = (), writes: tuple[Path, ...] = ()) -> Any:
        """One job of a stage (reading and writing the files of :class:`~.worker.Job`); its value,
        or a :class:`UavrisError` naming its log when it failed."""
        [res] = self.submit(stage, [Job(stage, fn, args, log, cost, reads, writes)])
        if not res.ok:
            raise UavrisError(f"{res.error}; log {res.log}")
        return res.value

    def stage_done(self, rec: StageRecord) -> None:
        """A stage ended: the bar gets the rest of its expected cost. A stage finished by an
        earlier invocation leaves the bar's total instead: the bar and its ETA count this
        invocation's work (crediting it would make a resumed run look nearly done at once)."""
        with self._lock:
            self._arrived(rec.name)
            self._ended.add(rec.name)
            if self.bar is not None:
                left = self._expected.get(rec.name, 0.0) - self._credited.get(rec.name, 0.0)
                if rec.status == "skipped":
                    self.bar.total = max(self.bar.n, self.bar.total - left)
                    self._expected[rec.name] = self._credited.get(rec.name, 0.0)
                    self._draw(time.time())
                else:
                    self._credit(rec.name, left)
                self.bar.write(stage_line(rec))

    def _credit(self, stage: str, amount: float) -> None:
        """Move the bar by ``amount`` expected seconds of ``stage``, never past its estimate (lock held)."""
        left = self._expected.get(stage, 0.0) - self._credited.get(stage, 0.0)
        step = max(0.0, min(amount, left))
        self._credited[stage] = self._credited.get(stage, 0.0) + step
        self._draw(time.time())

    def schedule(self, origin: float) -> list[dict[str, Any]]:
        """Every job of this invocation: stage, job, worker slot, its expected cost, start and end
        (s after ``origin``)."""
        with self._lock:
            return [{"stage": s, "job": r.name, "worker": r.worker, "ok": r.ok,
                     "cost": self._job_costs.get((s, r.name), 0.0),
                     "start": r.start - origin, "end": r.end - origin} for s, r in self.jobs]

    def etas(self, origin: float) -> list[dict[str, float | None]]:
        """The ETA the bar showed, once a minute: when (s after ``origin``), ours and tqdm's
        rate-based one (s; None before the rate is known)."""
        with self._lock:
            return [{"t": t - origin, "eta": ours, "rate_eta": None if rate != rate else rate}
                    for t, ours, rate in self.eta_log]

    def close(self) -> None:
        """Stop the runner; a study whose every stage ended leaves its bar at 100%."""
        self._closed.set()
        self.runner.release()
        self.runner.close()
        if self.bar is not None:
            with self._lock:
                if self._stages and self._ended >= set(self._stages):
                    self.bar.n, self.bar.postfix = self.bar.total, ""
                    self.bar.refresh()


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(max(0.0, seconds))), 60)
    return f"{minutes // 60}:{minutes % 60:02d}:{secs:02d}" if minutes >= 60 else f"{minutes:02d}:{secs:02d}"


__all__ = ["StudyContext", "stage_line"]
