"""``uavris reproduce``: the paper's whole study in three tracks, resumable, on a process pool or Ray.

Lives here: :func:`reproduce` (run or resume the study, then write the report) and
:func:`estimate` (its expected schedule, nothing run). Not here: what the study is
(:class:`~.config.ReproduceConfig`), its stages (:mod:`.pipeline`), the work of each
(:mod:`.workers`), keying, skipping and scheduling stages and jobs
(:mod:`uavris.experiments.engine`) and the report (:mod:`.report`).
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any, Sequence

from uavris.agents.oracle.store import kept_in as plans_kept_in
from uavris.errors import UavrisError
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.engine.forecast import expected_schedule
from uavris.experiments.engine.jobs import BACKENDS
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.study.config import AUTO, ReproduceConfig
from uavris.experiments.study.finished import STUDY_FILE, Study
from uavris.experiments.study.pipeline import build_pipeline
from uavris.float_paths import warn_if_unpinned
from uavris.io import write_json, write_yaml
from uavris.runs.lock import locked

PLANS_DIR = "plans"  # in a study's folder: the plans its workers' oracles share (uavris.agents.oracle.store)


# ------------------------------------------------------------------------------------------ entry point
def estimate(rc: ReproduceConfig, workers: int, out: str | Path | None = None, force: Sequence[str] = ()) -> str:
    """The study's stages with their expected core-minutes and expected start and end on
    ``workers`` workers, and the expected wall clock (:func:`~.forecast.expected_schedule`), as
    markdown. Where ``out`` holds this study in part, its finished stages (but those ``force``
    runs again: the named ones and what depends on them) are "done" and the clock is that of
    what is left (what ``reproduce`` with the same ``force`` would run now). Nothing is run or
    written."""
    if workers < 1:
        raise UavrisError(f"--workers must be >= 1, got {workers}")
    pipeline = build_pipeline(rc, Path(out) if out is not None else Path("<estimate>"),
                              StudyContext(workers, "local", None))
    forced = pipeline.with_dependents(f for f in force if f in pipeline.stages)
    done = {name for name in pipeline.stages if out is not None and name not in forced and pipeline.is_done(name)}
    wall, spans = expected_schedule(pipeline, workers, done)
    algo = rc.expert_algo if rc.expert_algo != AUTO else "the dearest algorithm (SAC) until the comparison chooses"

    def row(name: str, st: Any) -> tuple[Any, ...]:
        if name in done:
            return name, len(st.costs), "done", "", ""
        return (name, len(st.costs), f"{sum(st.costs) / 60:.1f}", f"{spans[name][0] / 60:.1f}",
                f"{spans[name][1] / 60:.1f}")

    table = markdown_table(("stage", "jobs", "core-min", "expected start (min)", "expected end (min)"),
                           [row(name, st) for name, st in pipeline.stages.items()], "lrrrr")
    what = f"what is left of {out} ({len(done)} of {len(pipeline.stages)} stages done)" if done else \
        f"`uavris reproduce --preset {rc.preset} --track {rc.track}`"
    experts = f"; paper-track experts: {algo}" if any(t.name == "paper" for t in rc.tracks) else ""
    lines = [f"expected wall clock of {what} on {workers} worker(s): {wall / 3600:.1f} h ({wall / 60:.0f} min)"
             f"{experts}", "", *table]
    total = sum(sum(st.costs) for name, st in pipeline.stages.items() if name not in done)
    lines += ["", f"{'work left' if done else 'total work'} {total / 3600:.1f} core-hours; unit costs measured on a "
              "2-core AMD EPYC, one job per core (uavris.experiments.engine.costs); an estimate, not a promise", ""]
    return "\n".join(lines)


def reproduce(rc: ReproduceConfig, out: str | Path, *, workers: int = 2, backend: str = "local",
              ray_address: str | None = None, force: Sequence[str] = (), progress: bool = True,
              device: str = "cpu", report_only: bool = False) -> Path:
    """Run (or resume) the whole study into ``out`` (torch on ``device``); returns the report path.
    ``report_only``: run nothing, write the report of the stages ``out`` holds, of the study its
    ``study.yaml`` says (``rc`` is not read; a study stopped part-way, while no other invocation
    writes it).

    Raises :class:`UavrisError` at the end when any job or stage failed (after writing the
    report of everything that finished).
    """
    rc.check()  # before anything is written
    if report_only:
        return _report_only(Path(out))
    warn_if_unpinned("reproduce")  # a result meant to be compared with another machine's
    if backend not in BACKENDS:
        raise UavrisError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if workers < 1:
        raise UavrisError(f"--workers must be >= 1, got {workers}")
    # a cluster's nodes write the study's files where the driver has them: the same absolute paths
    out = Path(os.path.abspath(out)) if ray_address else Path(out)
    # The bar counts expected seconds of work (uavris.experiments.engine.scheduling), shown as a share.
    bar = progress_bar(0, "reproduce", "s", progress,
                       bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}{postfix}]")
    # --force: every row flown again (study.kept_rows)
    ctx = StudyContext(workers, backend, ray_address, bar, device, reuse=not [f for f in force if f != "report"])
    pipeline = build_pipeline(rc, out, ctx)
    unknown = [f for f in force if f not in pipeline.stages and f != "report"]
    if unknown:
        bar.close()
        raise UavrisError(f"--force names unknown stage(s) {unknown}; stages: {list(pipeline.stages) + ['report']}")
    try:
        # the workers' oracles plan each hall once between them (uavris.agents.oracle.store); set before a
        # local Ray instance starts, whose workers inherit it
        with plans_kept_in(Path(os.path.abspath(out)) / PLANS_DIR):
            ctx.runner.connect()  # a cluster that cannot be reached: one line, before anything is written
            with locked(out, "uavris reproduce"):  # one invocation writes a study at a time
                return _run(rc, out, pipeline, ctx, force, bar, progress, workers)
    except BaseException:
        ctx.runner.close()  # Ray too, where it was joined and the study never began
        raise
    finally:
        bar.close()


def _report_only(out: Path) -> Path:
    """The report of the stages ``out`` holds, of the study its ``study.yaml`` says (the last
    invocation's parameters), nothing run (:func:`reproduce`'s ``report_only``)."""
    if not (out / STUDY_FILE).is_file():
        raise UavrisError(f"--report-only: {out} holds no study (no {STUDY_FILE}); run uavris reproduce first")
    study = Study.open(out)
    with locked(out, "uavris reproduce --report-only"):  # one writer: not while a study runs into it
        records = study.pipeline.finished()
        if not records:
            raise UavrisError(f"--report-only: no stage of the study in {out} has finished")
        return _write_report(study, records, 0.0, ran=False)


def _run(rc: ReproduceConfig, out: Path, pipeline: Any, ctx: StudyContext, force: Sequence[str], bar: Any,
         progress: bool, workers: int) -> Path:
    write_yaml(out / STUDY_FILE, rc.to_dict())  # what Study.open reads (uavris evaluate OUT --row KEY, claims)
    t0, origin = time.perf_counter(), time.time()
    try:
        ctx.plan(pipeline)
        records = pipeline.run(tuple(f for f in force if f != "report"), ctx.stage_done)
    finally:
        ctx.close()
    if progress and records and all(r.status == "skipped" for r in records):
        bar.write("every stage was done earlier: only the report and its figures are drawn again")

    write_json(out / "schedule.json", {"workers": workers, "origin": origin, "jobs": ctx.schedule(origin),
                                       "eta": ctx.etas(origin)})
    report = _write_report(Study(out, rc, pipeline), records, time.perf_counter() - t0, origin)
    bar.close()
    failed = [r for r in records if r.status == "failed"]
    if failed or ctx.failures:
        logs = "; ".join(f"{f.name}: {f.log}" for f in ctx.failures)
        raise UavrisError(f"{len(failed)} stage(s) failed ({', '.join(r.name for r in failed)}); "
                          f"report of the rest: {report}" + (f"; failed job logs: {logs}" if logs else ""))
    return report


def _write_report(study: Study, records: Sequence[Any], wall_s: float, origin: float = math.nan,
                  ran: bool = True) -> Path:
    """:func:`uavris.experiments.study.report.write_report`, imported when the report is written: its
    figures load matplotlib, which ``--estimate`` and a study's stages never need."""
    from uavris.experiments.study.report import write_report

    return write_report(study, records, wall_s, origin, ran)


__all__ = ["ReproduceConfig", "estimate", "reproduce"]
