"""The progress bar of ``reproduce``: its ETA and its end.

The ETA is checked against schedules worked by hand and against a study simulated here with
a scheduler of the test's own (first come, first served, not the runner's order), whose jobs
take longer than the cost model says by a factor per kind of work."""

from __future__ import annotations

import io
import random
import time
from pathlib import Path

import pytest
from tqdm import tqdm

from uavris.experiments.engine.forecast import Speeds, eta_seconds, replay, stage_family
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage, StageRecord
from uavris.experiments.engine.worker import Job


def test_replay_of_a_study_under_way_worked_by_hand():
    # Two workers. Stage a: one job running with 5 s left and one queued of 10 s; stage b
    # (after a): one job of 30 s; stage c (independent): 4 jobs of 3 s.
    stages = {"a": ((), [10.0]), "b": (("a",), [30.0]), "c": ((), [3.0] * 4)}
    after = {"a": 30.0, "b": 0.0, "c": 0.0}
    wall, spans = replay(stages, after, 2, running=[("a", 5.0)])
    # By hand, the longest chain first: t=0 a's queued job (priority 30 + 10) on the free worker
    # (0-10); t=5 the other worker free: c1 (5-8); t=8 c2 (8-11); t=10 a ends, b
    # queued (priority 30) beside c3, c4 (priority 3): b takes w2 at 10 (10-40); t=11 c3 (11-14),
    # c4 (14-17). The end: 40.
    assert wall == 40.0
    assert spans["a"] == (0.0, 10.0) and spans["b"] == (10.0, 40.0) and spans["c"] == (5.0, 17.0)


def test_a_finished_input_is_taken_as_done():
    wall, spans = replay({"b": (("a",), [7.0])}, {}, 1, done={"a"})
    assert wall == 7.0 and spans["b"] == (0.0, 7.0)


def test_eta_scales_by_the_measured_speed_and_never_undercuts_a_running_job():
    stages = {"a": ((), [])}
    # one job running, expected 600 s, 100 s in: 500 s left at the expected speed
    assert eta_seconds(stages, {}, 2, (), [("a", 600.0, 100.0)]) == 500.0
    # jobs run twice as long as expected: 1200 - 100
    assert eta_seconds(stages, {}, 2, (), [("a", 600.0, 100.0)], lambda s: 2.0) == 1100.0
    # jobs run four times faster: the replay says 50 s, the running job's expected time left is 500
    assert eta_seconds(stages, {}, 2, (), [("a", 600.0, 100.0)], lambda s: 0.25) == 500.0


def test_speeds_are_learned_per_family_of_stages():
    speeds = Speeds()
    assert speeds("deploy-pretrain") == 1.0
    speeds.add("deploy-pretrain-s1", 100.0, 300.0)
    speeds.add("compare", 100.0, 60.0)
    assert speeds("deploy-pretrain-n128-s2") == pytest.approx(3.0)  # its family's
    # a family none of whose jobs has finished: every job's slowdown (360 / 200 = 1.8) with 2/3 of its
    # excess over 1 kept, for the 2 families it rests on
    assert speeds("deploy-evaluate-layout-unseen-3") == pytest.approx(1.0 + 0.8 * 2 / 3)
    speeds.add("x", 1.0, 100.0)
    assert speeds("x") == 4.0  # bounded
    assert stage_family("deploy-evaluate-layout-unseen-13") == stage_family("deploy-evaluate-layout-unseen-0")
    assert stage_family("finetune-unseen1") == "finetune-unseen" != stage_family("strong-finetune-unseen1")


def test_one_family_slow_on_this_cpu_does_not_price_the_whole_study():
    """The comparison's first jobs took 1.66 times their cost on a Zen 4 while the study as a whole
    took about 1.3 (docs/timings.md): before any other family has finished, the other stages are
    priced at 1 + 0.66 / 2, not at 1.66; the comparison's own stays its own."""
    speeds = Speeds()
    speeds.add("compare", 86.5, 143.6)
    assert speeds("compare") == pytest.approx(143.6 / 86.5)
    assert speeds("deploy-evaluate-layout-unseen-0") == pytest.approx(1.0 + (143.6 / 86.5 - 1.0) / 2)


def _simulated_study(rng: random.Random) -> tuple[dict, dict[str, float]]:
    """A study shaped like the quick one: a wide first stage (with short jobs, as PPO's are, and
    long ones), a dataset stage, single-job trainings, then wide evaluations. Costs in expected
    seconds; each family's true speed differs from the cost model by a factor of its own."""
    stages: dict[str, tuple[tuple[str, ...], list[float]]] = {
        "compare": ((), [rng.uniform(10, 20) for _ in range(3)] + [rng.uniform(100, 300) for _ in range(9)]),
        "dataset": ((), [150.0] * 8),
    }
    for s in range(3):
        for kind in ("pretrain", "bc", "flat"):
            stages[f"{kind}-s{s}"] = (("dataset",), [rng.uniform(60, 120)])
    for i in range(8):
        stages[f"finetune-{i}"] = (("pretrain-s0",), [rng.uniform(40, 80)])
    models = tuple(n for n in stages if n[:2] in ("pr", "bc", "fl"))
    for i in range(8):
        stages[f"evaluate-{i}"] = ((*models, f"finetune-{i}"), [rng.uniform(40, 120)])
    factor = {family: 1.8 * rng.uniform(0.8, 1.25) for family in
              ("compare", "dataset", "pretrain", "bc", "flat", "finetune", "evaluate")}
    return stages, factor


def _first_come_first_served(stages, factor, workers):
    """The truth: jobs queue in the order their stage's inputs finish and run for their cost
    times their family's factor. Returns each job's (stage, expected, start, end)."""
    ready_at: dict[str, float] = {}
    jobs, free, end_of = [], [0.0] * workers, {}
    pending = list(stages)
    while pending:
        name = min((n for n in pending if all(d in end_of for d in stages[n][0])),
                   key=lambda n: max([end_of[d] for d in stages[n][0]], default=0.0))
        ready_at[name] = max([end_of[d] for d in stages[name][0]], default=0.0)
        ends = []
        for cost in stages[name][1]:
            w = min(range(workers), key=lambda i: free[i])
            start = max(free[w], ready_at[name])
            free[w] = start + cost * factor[stage_family(name).split("-")[0]]
            jobs.append((name, cost, start, free[w]))
            ends.append(free[w])
        end_of[name] = max(ends)
        pending.remove(name)
    return jobs, max(end_of.values())


@pytest.mark.parametrize("seed", range(5))
def test_the_eta_of_a_simulated_study_stays_within_half_again_of_the_truth(seed: int):
    stages, factor = _simulated_study(random.Random(seed))
    jobs, end = _first_come_first_served(stages, factor, 2)
    after = {name: 0.0 for name in stages}
    for name in reversed(list(stages)):
        for dep in stages[name][0]:
            after[dep] = max(after[dep], max(stages[name][1]) + after[name])
    worst = 1.0
    for t in range(300, int(end), 60):  # once a minute after the first five
        finished = [j for j in jobs if j[3] <= t]
        running = [(n, c, t - s) for n, c, s, e in jobs if s <= t < e]
        ended = {n for n in stages if all(e <= t for m, _, _, e in jobs if m == n)}
        left = {n: (deps, [c for m, c, s, _ in jobs if m == n and s > t]) for n, (deps, _) in stages.items()
                if n not in ended}
        speeds = Speeds()
        for n, c, s, e in finished:
            speeds.add(n, c, e - s)
        eta = eta_seconds(left, after, 2, ended, running, speeds)
        truth = end - t
        worst = max(worst, eta / truth, truth / eta)
        assert eta >= max([c - el for _, c, el in running], default=0.0)
    assert worst <= 1.5, f"the ETA was off by a factor {worst:.2f}"


def test_the_bar_ends_at_100_percent_even_when_a_job_moved_it_while_running(tmp_path: Path):
    """A running job moves the bar by its elapsed time; its end must not add its cost on top
    (the count then passes the total, which tqdm prints as 0%: the quick run's bar did)."""
    out = io.StringIO()
    bar = tqdm(total=0, file=out, bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}{postfix}]")
    ctx = StudyContext(2, "local", None, bar)
    pipeline = Pipeline(tmp_path, [Stage("slow", {}, lambda d, deps: None, costs=(10.0,))])
    ctx.plan(pipeline)
    try:
        ctx.submit("slow", [Job("nap", time.sleep, (3.0,), tmp_path / "log", 10.0)])
        assert bar.n <= bar.total
        ctx.stage_done(StageRecord("slow", "k", tmp_path, "done", 3.0, None))
    finally:
        ctx.close()
    assert bar.n == bar.total == 10.0
    assert "100%" in str(bar)
    assert "ETA" in out.getvalue()  # the bar showed an ETA while the job ran
