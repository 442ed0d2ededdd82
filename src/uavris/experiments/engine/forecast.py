"""When the study will end: an event-driven replay of the job runner over the expected costs.

Lives here: :func:`replay` (the runner's order: a free worker takes the queued job of the
longest remaining chain), :func:`expected_schedule` (the study, or what is left of it, before it runs, for
``reproduce --estimate``) and :func:`eta_seconds` (what is left of a running study, for
the progress bar). Not here: the costs (:mod:`.costs`) and the bar (:mod:`.scheduling`).

Why not the progress bar's own rate: the study's parallelism changes as it goes (two
workers busy with the comparison, then one long chain of DT stages, then sixteen
evaluations), so work done per minute so far says little about the minutes left. The
replay knows the chain: at the end of a run it waits for the last long job instead of
dividing the work left by the rate of a time when both workers were busy. It is scaled by
how long this invocation's finished jobs took against their expected cost, which absorbs
a machine slower or faster than the one the costs were measured on.
"""

from __future__ import annotations

import heapq
import itertools
import math
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

SPEED_BOUNDS = (0.25, 4.0)  # the measured slowdown is trusted within these (a first job can mislead)


def replay(stages: Mapping[str, tuple[Sequence[str], Sequence[float]]], after: Mapping[str, float], workers: int,
           done: Collection[str] = (), running: Sequence[tuple[str, float]] = ()
           ) -> tuple[float, dict[str, tuple[float, float]]]:
    """Replay the runner from now: ``stages`` maps each unfinished stage to its dependencies
    and the expected seconds of its jobs not yet started; ``running`` holds (stage, seconds
    left) of the jobs under way, which occupy workers from the start; ``done`` the finished
    stages. A stage's jobs queue once its inputs are done, a free worker takes the queued job
    of the longest remaining chain (``after`` of its stage plus its own cost). Returns the
    seconds until the last stage ends and, per stage, its (start, end) from now."""
    running_in = {name: 0 for name in stages}
    for name, _ in running:
        running_in[name] += 1
    left = {name: len(costs) + running_in[name] for name, (_, costs) in stages.items()}
    spans: dict[str, list[float]] = {}
    queued: list[tuple[float, int, str, float]] = []
    busy: list[tuple[float, int, str]] = []
    seq = itertools.count()
    t, free, finished = 0.0, max(1, workers) - len(running), set(done)

    def release(name: str, costs: Sequence[float]) -> None:
        spans.setdefault(name, [math.inf, t])
        for cost in costs:
            heapq.heappush(queued, (-(after.get(name, 0.0) + cost), next(seq), name, cost))

    for name, seconds in running:  # a stage under way: its running jobs hold workers, the rest queue now
        spans[name] = [0.0, 0.0]
        heapq.heappush(busy, (max(0.0, seconds), next(seq), name))
    for name in list(spans):
        release(name, stages[name][1])
    while len(finished) < len(done) + len(stages):
        for name, (deps, costs) in stages.items():
            if name not in spans and all(d in finished for d in deps):
                if not left[name]:
                    left[name], costs = 1, (0.0,)  # a stage with no job still ends (when its inputs are done)
                release(name, costs)
        while free > 0 and queued:
            _, _, name, cost = heapq.heappop(queued)
            spans[name][0] = min(spans[name][0], t)
            heapq.heappush(busy, (t + cost, next(seq), name))
            free -= 1
        if not busy:
            raise ValueError(f"stages wait for inputs that never finish: {sorted(set(stages) - finished)}")
        t, _, name = heapq.heappop(busy)
        free += 1
        left[name] -= 1
        if not left[name]:
            finished.add(name)
            spans[name][1] = t
    return t, {name: (a, b) for name, (a, b) in spans.items()}


def expected_schedule(pipeline: Any, workers: int, done: Collection[str] = ()
                      ) -> tuple[float, dict[str, tuple[float, float]]]:
    """The study's expected wall clock on ``workers`` workers, from the cost model (:mod:`.costs`):
    the :func:`replay` of every stage of ``pipeline`` (a
    :class:`~uavris.experiments.engine.stages.Pipeline`) but the ``done`` ones. Returns the
    expected seconds and, per stage left, its expected (start, end). An estimate: the unit costs
    were measured on one machine."""
    stages = {name: (st.deps, st.costs) for name, st in pipeline.stages.items() if name not in done}
    return replay(stages, pipeline.downstream(workers), workers, done) if stages else (0.0, {})


def eta_seconds(stages: Mapping[str, tuple[Sequence[str], Sequence[float]]], after: Mapping[str, float],
                workers: int, done: Collection[str], running: Sequence[tuple[str, float, float]],
                speed: Callable[[str], float] = lambda name: 1.0) -> float:
    """Seconds until a running study ends: the :func:`replay` of what is left with each stage's
    expected costs times ``speed(stage)`` (this run's measured slowdown, :class:`Speeds`);
    ``running`` holds (stage, expected cost, seconds elapsed) of the jobs under way. Never
    less than the longest running job's expected time left: a job that is expected to need
    another ten minutes is not overtaken by a rate."""
    scaled = {name: (deps, [c * speed(name) for c in costs]) for name, (deps, costs) in stages.items()}
    now = [(name, max(0.0, cost * speed(name) - elapsed)) for name, cost, elapsed in running]
    wall = replay(scaled, after, workers, done, now)[0] if stages else 0.0
    return max([wall] + [cost - elapsed for _, cost, elapsed in running])


def stage_family(name: str) -> str:
    """The kind of work a stage does, shared by its seeds, data sizes and deployments:
    ``deploy-pretrain-n128-s1`` and ``deploy-pretrain`` are one family, as are the
    ``deploy-evaluate-layout-unseen-*`` stages and ``finetune-unseen1`` and ``-unseen2``."""
    return re.sub(r"(-[sn]\d+|-?\d+)+$", "", re.sub(r"-n\d+(?=-)", "", name))


class Speeds:
    """How much longer this run's jobs take than expected, from the finished ones: per stage
    family (the sum of wall clocks over the sum of expected costs) where a job of the family
    has finished; for a family none of whose jobs has finished, the slowdown over every finished
    job with only ``k / (k + 1)`` of its excess over 1 kept, for the ``k`` families it rests on
    (the comparison's first jobs alone, 1.66 times their cost on a Zen 4, put the whole
    study at 1.66 for five minutes where it ran at 1.3: docs/timings.md); 1 before any has
    finished. Bounded by :data:`SPEED_BOUNDS` (one short job can mislead)."""

    def __init__(self) -> None:
        self._sums: dict[str, list[float]] = {}
        self._all = [0.0, 0.0]

    def add(self, stage: str, expected: float, took: float) -> None:
        if expected <= 0 or took != took:
            return
        for acc in (self._sums.setdefault(stage_family(stage), [0.0, 0.0]), self._all):
            acc[0] += expected
            acc[1] += took

    def __call__(self, stage: str) -> float:
        expected, took = self._sums.get(stage_family(stage), (0.0, 0.0))
        if expected <= 0:
            expected, took = self._all
            if expected <= 0:
                return 1.0
            families = sum(1 for e, _ in self._sums.values() if e > 0)
            pooled = 1.0 + (took / expected - 1.0) * families / (families + 1)
            return min(max(pooled, SPEED_BOUNDS[0]), SPEED_BOUNDS[1])
        return min(max(took / expected, SPEED_BOUNDS[0]), SPEED_BOUNDS[1]) if expected > 0 else 1.0
