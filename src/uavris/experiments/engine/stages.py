"""Resumable stages keyed by the hash of their resolved configuration.

Lives here: :class:`Stage`, :func:`stage_key`, :class:`StageRecord` and :class:`Pipeline`.
Not here: the study's stages (:mod:`.reproduce`), the processes their jobs run on
(:mod:`.jobs`) and the resume of a training run within a stage (:mod:`uavris.runs`).

A stage's key hashes its own configuration together with the keys of the stages it
depends on, so changing a parameter invalidates exactly that stage and everything
downstream of it, and nothing else. A stage runs in ``OUT/stages/NAME-KEY/`` and is
finished when ``stage.json`` exists there (written last, atomically). That record is the
same, byte for byte, for the same inputs: the stage's wall clock goes to ``timing.json``
beside it (:data:`uavris.runs.TIMING_FILE`, added to what the stage's own code measured
there), and an undefined number (NaN, an interval over one sample) is written as JSON
``null``, never as ``NaN``, which is not JSON. A rerun skips finished stages, and an
unfinished one is run again in the same folder, where the training code resumes from its
checkpoints. Stages whose inputs are ready run concurrently (:meth:`Pipeline.run`), the
longest remaining chain first (:meth:`Pipeline.downstream`).
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

from uavris.errors import ConfigError
from uavris.experiments.engine.jobs import abort_runners
from uavris.io import read_json, to_plain, write_json
from uavris.runs import TIMING_FILE, read_timing


@dataclass
class Stage:
    """One step of a pipeline: ``run(stage_dir, deps)`` with ``deps`` mapping names to dirs;
    ``costs``: the expected seconds of each of its jobs on one core (:mod:`.costs`), which
    order the jobs; ``progress_s``: the work the progress bar expects of it, when that is
    not their sum (a stage whose jobs are not known yet); ``group``: what the stage belongs
    to, for its reader (a study's track), not part of its key."""

    name: str
    config: dict[str, Any]
    run: Callable[[Path, dict[str, Path]], dict[str, Any] | None]
    deps: tuple[str, ...] = ()
    costs: tuple[float, ...] = ()
    progress_s: float | None = None
    group: str = ""
    key: str = field(default="", init=False)

    def duration(self, workers: int) -> float:
        """Expected wall clock of the stage on ``workers`` free workers: its longest job, or its
        work spread over the workers, whichever is longer."""
        return max(max(self.costs, default=0.0), sum(self.costs) / max(1, workers))


def json_numbers(obj: Any) -> Any:
    """``obj`` as plain values with every NaN and infinity as None: JSON has no NaN (Python's
    ``json`` writes a bare ``NaN`` that strict readers refuse), and a reader of a stage's record
    takes None for "undefined" as the tables do (:mod:`uavris.experiments.display.tables`)."""
    obj = to_plain(obj)
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_numbers(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [json_numbers(v) for v in obj]
    return obj


def stage_key(config: dict[str, Any], dep_keys: list[str]) -> str:
    blob = json.dumps({"config": to_plain(config), "deps": dep_keys}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


@dataclass
class StageRecord:
    name: str
    key: str
    directory: Path
    status: str  # "done", "skipped" (finished earlier), "failed"
    wall_s: float
    result: dict[str, Any] | None
    error: str | None = None
    start: float = float("nan")  # time.time() when it started and ended in this invocation
    end: float = float("nan")


def study_folder(stage_dir: Path) -> Path:
    """The folder of the study whose stage folder is ``stage_dir`` (:meth:`Pipeline.directory`)."""
    return Path(stage_dir).parent.parent


class Pipeline:
    """Stages in dependency order, each skipped when its keyed folder is finished."""

    def __init__(self, out: Path, stages: list[Stage]) -> None:
        self.out = Path(out)
        self.stages: dict[str, Stage] = {}
        for st in stages:
            if st.name in self.stages:  # a stage's name is its folder and what --force names: one each
                raise ConfigError(f"the pipeline has two stages named {st.name!r} (a stage kind registered beside "
                                  "a study may not take the name of one of its own)")
            missing = [d for d in st.deps if d not in self.stages]
            if missing:
                raise ValueError(f"stage {st.name} depends on unknown or later stages {missing}")
            st.key = stage_key(st.config, [self.stages[d].key for d in st.deps])
            self.stages[st.name] = st

    def downstream(self, workers: int) -> dict[str, float]:
        """Per stage, the expected wall clock of the longest chain of stages that depend on it
        (0 for a last stage): a job's priority is this plus its own cost, so that the longest
        remaining chain is served first (the upward rank of list scheduling)."""
        after: dict[str, float] = {name: 0.0 for name in self.stages}
        for name in reversed(list(self.stages)):  # stages are in dependency order
            st = self.stages[name]
            for dep in st.deps:
                after[dep] = max(after[dep], st.duration(workers) + after[name])
        return after

    def with_dependents(self, names: Iterable[str]) -> set[str]:
        """``names`` and every stage that depends on one of them, directly or not: what forcing
        them runs again (a dependent's key holds its inputs' settings, not their results, so it
        would otherwise keep a result made from the old ones)."""
        chosen = set(names)
        for name, st in self.stages.items():  # stages are in dependency order
            if any(dep in chosen for dep in st.deps):
                chosen.add(name)
        return chosen

    def directory(self, name: str) -> Path:
        st = self.stages[name]
        return self.out / "stages" / f"{name}-{st.key}"

    def is_done(self, name: str) -> bool:
        return (self.directory(name) / "stage.json").exists()

    def run(self, force: tuple[str, ...] = (), on_stage: Callable[[StageRecord], None] | None = None,
            concurrent: bool = True) -> list[StageRecord]:
        """Run every stage whose inputs are ready; returns the records in pipeline order.
        ``force``: stages to run again, with every stage that depends on them.

        With ``concurrent`` (the default) independent stages run at the same time, each in a
        thread of this process: their heavy work goes through a shared job runner, which
        bounds how many jobs run at once, so two tracks of a study interleave on the same
        workers. A stage whose input failed is recorded as failed without running; the
        others go on. ``on_stage`` is called in this thread as each stage ends.
        """
        unknown = [f for f in force if f not in self.stages]
        if unknown:
            raise ValueError(f"--force names unknown stage(s) {unknown}; stages: {list(self.stages)}")
        force = tuple(self.with_dependents(force))
        records: dict[str, StageRecord] = {}
        pending = dict(self.stages)
        running: dict[Future[StageRecord], str] = {}

        def finish(rec: StageRecord) -> None:
            records[rec.name] = rec
            if on_stage:
                on_stage(rec)

        # Ready stages start longest remaining chain first, so that their jobs are queued in
        # that order too (the job runner then keeps it by priority).
        order = self.downstream(1)
        pending = dict(sorted(pending.items(), key=lambda kv: -(order[kv[0]] + kv[1].duration(1))))
        with ThreadPoolExecutor(max_workers=max(1, len(self.stages) if concurrent else 1)) as threads:
            try:
                while pending or running:
                    for name, st in list(pending.items()):
                        if any(records.get(dep) is not None and records[dep].status == "failed" for dep in st.deps):
                            del pending[name]
                            finish(StageRecord(name, st.key, self.directory(name), "failed", 0.0, None,
                                               "an upstream stage failed"))
                        elif all(dep in records for dep in st.deps) and (concurrent or not running):
                            del pending[name]
                            running[threads.submit(self._run_stage, st, name in force)] = name
                    if not running:
                        continue
                    done, _ = wait(running, return_when=FIRST_COMPLETED)
                    for fut in done:
                        del running[fut]
                        finish(fut.result())
            except KeyboardInterrupt:
                # Ctrl-C in a program that calls the library (the command does this in its signal
                # handler too): stop the jobs the stage threads wait for, which leaving this block
                # waits for, instead of letting them run to their end (pool workers ignore SIGINT)
                abort_runners()
                raise
        return [records[name] for name in self.stages]

    def finished(self) -> list[StageRecord]:
        """The records of the stages finished so far ("skipped", with the wall clock they took),
        in pipeline order, running none: what a report of a study stopped part-way reads."""
        return [self._finished_record(name) for name in self.stages if self.is_done(name)]

    def _finished_record(self, name: str) -> StageRecord:
        d = self.directory(name)
        return StageRecord(name, self.stages[name].key, d, "skipped", float(read_timing(d).get("wall_s", 0.0)),
                           read_json(d / "stage.json").get("result"))

    def _run_stage(self, st: Stage, forced: bool) -> StageRecord:
        d = self.directory(st.name)
        if forced and d.exists():
            shutil.rmtree(d)
        if self.is_done(st.name):
            return self._finished_record(st.name)
        d.mkdir(parents=True, exist_ok=True)
        start = time.time()
        try:
            result = st.run(d, {dep: self.directory(dep) for dep in st.deps})
        except Exception as e:  # noqa: BLE001 - report the stage, let independent ones go on
            return StageRecord(st.name, st.key, d, "failed", time.time() - start, None, f"{type(e).__name__}: {e}",
                               start, time.time())
        end = time.time()
        # The wall clock goes to timing.json, so that stage.json is the same for the same inputs;
        # what the stage's code timed there itself (a comparison's wall clock) is kept.
        write_json(d / TIMING_FILE, {**read_timing(d), "wall_s": end - start, "start": start, "end": end})
        record = json_numbers({"name": st.name, "key": st.key, "config": st.config,
                               "deps": {dep: self.stages[dep].key for dep in st.deps}, "result": result})
        write_json(d / "stage.json", record)
        # the record a later invocation reads when it skips this stage, not the NaNs of this one
        return StageRecord(st.name, st.key, d, "done", end - start, record["result"], None, start, end)
