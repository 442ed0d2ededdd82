"""Every results page from one version: ``uavris pages`` runs the studies the pages read and writes them.

Lives here: :data:`STUDIES` (each study a page reads: its command, its output, the studies whose
finished stages it starts from), :data:`PAGES` (each page under ``docs/results``: the studies
it reads and its writer), :func:`make_pages` (run what the pages need, two at a time if asked,
then write each page stamped) and :func:`link_finished_stages` (a study started from
another's finished stages). Not here: what a page says (the report, :mod:`.report`; the claims,
:mod:`.claims`; the budget, :mod:`.claims_comparison`), the stamp (:mod:`.stamp`).

Every study is resumable (a study's finished stages are skipped, a comparison's finished runs,
the from-scratch file's finished halls, the oracle-gap search's finished halls), so a rerun of
``uavris pages`` continues where it stopped, and a page is written only from studies that
finished under this code (their stage keys are this code's). A page's stamp names the commit,
the machine and the studies it read.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from uavris.errors import UavrisError
from uavris.experiments.study import oracle_gap
from uavris.experiments.study.claims_comparison import write_budget_page
from uavris.experiments.study.stamp import HISTORICAL_FILE, historical_banner, read_stamp, stale
from uavris.experiments.tools.rows import PRETRAINED
from uavris.io import read_json, read_yaml
from uavris.presets import STUDY


@dataclass(frozen=True)
class StudyRun:
    """One command whose output a page reads: ``argv`` (uavris's arguments, ``{runs}`` the pages'
    runs folder, ``{preset}`` the preset), its output ``out`` (under the runs folder), the studies
    whose finished stages it starts from (``reuse``) and those that must finish first (``after``)."""

    name: str
    argv: tuple[str, ...]
    out: str
    reuse: tuple[str, ...] = ()
    after: tuple[str, ...] = ()
    module: str | None = None  # a measurement run as ``python -m MODULE`` instead of a uavris command

    def command(self, runs: Path, preset: str) -> list[str]:
        """The command's arguments with the runs folder and the preset filled in."""
        return [a.format(runs=runs, preset=preset) for a in self.argv]

    def line(self, runs: Path, preset: str) -> str:
        """The command as a user would type it."""
        return " ".join([*(["python", "-m", self.module] if self.module else ["uavris"]),
                         *self.command(runs, preset)])


SEEDS = 5  # training seeds of the paper and strong tracks on the claims page (the unit: docs/results/claims.md)


def _budgets(preset: str) -> tuple[int, int, int]:
    """The comparison's budget, four times it (every algorithm, the claims page) and sixteen times
    it (PPO only, the budget page), with the evaluation cadence: half the study's budget."""
    steps = int(STUDY[preset]["compare_steps"])
    return 4 * steps, 16 * steps, steps // 2


def _from_scratch_flags(preset: str) -> tuple[str, ...]:
    """``uavris from-scratch``'s defaults measure the quick study (200,000 steps in 4 halls); the
    smoke preset's check measures 2 halls at its comparison's budget."""
    if preset != "smoke":
        return ()
    steps = int(STUDY[preset]["compare_steps"])
    return ("--config.halls", "2", "--config.steps", str(steps), "--config.eval-every", str(steps // 2))


def _oracle_gap_flags(preset: str) -> tuple[str, ...]:
    """The oracle-gap search's halls: its defaults (20 halls of 3-8 devices); at the smoke preset one
    hall of 3 devices."""
    return ("--counts", "3", "--halls", "1", "--other-counts", "--few-counts") if preset == "smoke" else ()


def studies(preset: str, seeds: int = SEEDS) -> dict[str, StudyRun]:
    """The studies the pages read, at ``preset`` with ``seeds`` training seeds."""
    budget, long, every = _budgets(preset)
    out: list[StudyRun] = [
        StudyRun("quick", ("reproduce", "--preset", "{preset}", "--out", "{runs}/quick"), "quick"),
        StudyRun("ablation", ("reproduce", "--preset", "{preset}", "--ablation", "--out", "{runs}/ablation"),
                 "ablation", reuse=("quick",)),
        StudyRun("counts", ("reproduce", "--preset", "{preset}", "--track", "deployment", "--device-counts", "3", "6",
                            "8", "10", "--count-other-layouts", "4", "--out", "{runs}/counts"), "counts",
                 reuse=("quick",)),
        *(StudyRun(f"{track}-s{k}", ("reproduce", "--preset", "{preset}", "--track", track, "--seed", str(k), "--out",
                                     f"{{runs}}/{track}-s{k}"), f"{track}-s{k}", reuse=("quick",))
          for k in range(1, seeds) for track in ("paper", "strong")),
        StudyRun("budget", ("compare-algorithms", "--preset", "{preset}", "--seeds", "3", "--steps", str(budget),
                            "--eval-every", str(every), "--out", "{runs}/budget"), "budget"),
        StudyRun("budget-ppo", ("compare-algorithms", "--preset", "{preset}", "--algos", "ppo", "--seeds", "3",
                                "--steps", str(long), "--eval-every", str(every), "--out", "{runs}/budget-ppo"),
                 "budget-ppo"),
        StudyRun("oracle-gap", ("--out", "{runs}/oracle-gap", *_oracle_gap_flags(preset)), "oracle-gap",
                 module="uavris.experiments.study.oracle_gap"),
        StudyRun("from-scratch", ("from-scratch", "{runs}/ablation", "--out", "{runs}/from-scratch.json",
                                  *_from_scratch_flags(preset)), "from-scratch.json", after=("ablation",)),
    ]
    return {s.name: s for s in out}


@dataclass(frozen=True)
class Page:
    """A results page: its file under the destination, the studies it reads (``reads(seeds)``)
    and its writer (``write(runs, dest, preset, seeds)`` writes the file, stamped, and returns
    what it wrote)."""

    name: str
    file: str
    reads: Callable[[int], tuple[str, ...]]
    write: Callable[[Path, Path, str, int], list[Path]]
    about: str


def _write_report_copy(study: str, page: str) -> Callable[[Path, Path, str, int], list[Path]]:
    """A writer that copies a study's report as a page, stamped as the page (its figures: see
    :func:`uavris.experiments.study.report.page_copy`)."""
    def write(runs: Path, dest: Path, preset: str, seeds: int) -> list[Path]:
        from uavris.experiments.study.report import page_copy

        return page_copy(runs / study, dest / PAGES[page].file, page, studies(preset, seeds)[study].line(runs, preset))
    return write


def _lines(names: Sequence[str], runs: Path, preset: str, seeds: int) -> list[str]:
    table = studies(preset, seeds)
    return [table[n].line(runs, preset) for n in names]


def _write_claims(runs: Path, dest: Path, preset: str, seeds: int) -> list[Path]:
    from uavris.experiments.study.claims import write_claims

    budget, _, _ = _budgets(preset)
    outs = [runs / "ablation", *(runs / f"paper-s{k}" for k in range(1, seeds)),
            *(runs / f"strong-s{k}" for k in range(1, seeds))]
    made_by = _lines(["quick", *PAGES["claims"].reads(seeds)], runs, preset, seeds)
    return [write_claims(outs, dest, [(runs / "budget", budget)], runs / "from-scratch.json", made_by)]


def _write_budget(runs: Path, dest: Path, preset: str, seeds: int) -> list[Path]:
    budget, long, _ = _budgets(preset)
    steps = int(STUDY[preset]["compare_steps"])
    return write_budget_page([(runs / "budget", (steps, budget)), (runs / "budget-ppo", (long,))],
                             dest / "budget.md", preset, _lines(PAGES["budget"].reads(seeds), runs, preset, seeds))


def _write_oracle_gap(runs: Path, dest: Path, preset: str, seeds: int) -> list[Path]:
    run = studies(preset, seeds)["oracle-gap"]
    parsed = oracle_gap.parser().parse_args(run.command(runs, preset))
    done = {name: read_json(parsed.out / f"{name}.json")
            for name, *_ in oracle_gap.halls(parsed.counts, parsed.halls, parsed.other_counts, parsed.other,
                                             parsed.few_counts, parsed.few)}
    return [oracle_gap.write_page(done, dest / "oracle-gap.md", parsed.out, run.line(runs, preset))]


def _write_pretrained(runs: Path, dest: Path, preset: str, seeds: int) -> list[Path]:
    """Ship the make run's controller into the package and write its model card; at another preset
    (the smoke check of the chain) or into another ``dest``, into ``dest/pretrained`` instead: only
    the make run's pages replace the package's controller."""
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.pretrained import ship, write_card_page

    package = preset == "quick" and dest.resolve() == (PRETRAINED.parents[3] / "docs" / "results").resolve()
    shipped = ship(runs / "quick", PRETRAINED if package else dest / "pretrained", made_by=ReproduceConfig(preset),
                   scored_in=[runs / "counts"])
    table = studies(preset, seeds)
    return [write_card_page(shipped, dest / "pretrained.md", table["quick"].line(runs, preset),
                            [str(runs / "quick"), str(runs / "counts")], [table["counts"].line(runs, preset)]),
            shipped]


PAGES: dict[str, Page] = {p.name: p for p in (
    Page("quick-report", "quick-report.md", lambda seeds: ("quick",), _write_report_copy("quick", "quick-report"),
         "the make run's report: the three tracks, seed 0"),
    Page("device-counts", "deployment-device-counts.md", lambda seeds: ("counts",),
         _write_report_copy("counts", "device-counts"),
         "the deployment track at 3, 4, 6, 8 and 10 devices and in another generator's halls"),
    Page("claims", "claims.md", lambda seeds: ("ablation", *(f"{t}-s{k}" for k in range(1, seeds)
                                                             for t in ("paper", "strong")), "budget", "from-scratch"),
         _write_claims, "the paper's claims judged over the training seeds and the unseen halls, with its evidence"),
    Page("budget", "budget.md", lambda seeds: ("budget", "budget-ppo"), _write_budget,
         "Fig. 2 at the study's budget, four and sixteen times it"),
    Page("pretrained", "pretrained.md", lambda seeds: ("quick", "counts"), _write_pretrained,
         "the controller shipped with the package, shipped again, and its model card (scored at every device count)"),
    Page("oracle-gap", "oracle-gap.md", lambda seeds: ("oracle-gap",), _write_oracle_gap,
         "the oracle against a search at least ten times dearer, at 3 to 8 devices"),
)}


def link_finished_stages(source: Path, dest: Path) -> int:
    """Start the study ``dest`` from the finished stages of the study ``source``: each finished
    stage folder (``stages/NAME-KEY`` with its ``stage.json``) that ``dest`` lacks, hard-linked
    file by file (copied across file systems) into a folder beside it and renamed into place
    whole. A stage is found by its name and key, so ``dest`` uses those its own pipeline asks
    for and ignores the rest. Returns how many were linked."""
    linked = 0
    src_stages, dst_stages = source / "stages", dest / "stages"
    if not src_stages.is_dir():
        return 0
    dst_stages.mkdir(parents=True, exist_ok=True)
    for d in sorted(src_stages.iterdir()):
        if not (d / "stage.json").is_file() or d.is_symlink() or (dst_stages / d.name).exists():
            continue
        made = dst_stages / f".{d.name}.linking"
        shutil.rmtree(made, ignore_errors=True)
        shutil.copytree(d, made, copy_function=_link_or_copy, symlinks=True)
        os.replace(made, dst_stages / d.name)
        linked += 1
    return linked


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _needed(pages: Sequence[str], preset: str, seeds: int) -> list[StudyRun]:
    """The studies the ``pages`` read and the ones those start from or follow, in an order that
    runs each after what it needs."""
    table = studies(preset, seeds)
    order: list[str] = []

    def visit(name: str) -> None:
        if name in order:
            return
        for dep in (*table[name].reuse, *table[name].after):
            visit(dep)
        order.append(name)

    for page in pages:
        for name in PAGES[page].reads(seeds):
            visit(name)
    return [table[n] for n in order]


def _die_with_parent(pin: list[int] | None) -> Callable[[], None]:
    """What a study's process runs before its command: its core (``pin``), and a SIGTERM when
    ``uavris pages`` dies (Linux's parent-death signal: a SIGKILL of the parent no handler sees)."""
    def start() -> None:
        if pin:
            os.sched_setaffinity(0, pin)
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # not Linux: Ctrl-C and SIGTERM still stop them (run_studies)
            pass
    return start


def _stop(running: dict[str, tuple[int, subprocess.Popen, float]]) -> None:
    """Stop the studies still running: SIGTERM (each stops its own workers), then SIGKILL after 30 s."""
    for _, proc, _ in running.values():
        if proc.poll() is None:
            proc.terminate()
    deadline = time.monotonic() + 30
    for _, proc, _ in running.values():
        try:
            proc.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run_studies(needed: Sequence[StudyRun], runs: Path, preset: str, jobs: int, workers: int,
                say: Callable[[str], None] = print) -> None:
    """Run every study of ``needed``, ``jobs`` at a time (each pinned to a core of its own where
    ``jobs`` > 1 and the machine has them), each after the studies it starts from or follows,
    ``workers`` job processes each; its output to ``runs/.pages/NAME.log``. A study that fails
    stops the others from starting, with one line naming its log; Ctrl-C, SIGTERM or an error
    here stops the running ones. Every command resumes, so each study is run again on a rerun
    (a finished one in seconds)."""
    logs = runs / ".pages"
    logs.mkdir(parents=True, exist_ok=True)
    table = {r.name: r for r in needed}
    waiting, done, failed = list(needed), set(), []
    running: dict[str, tuple[int, subprocess.Popen, float]] = {}
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    try:
        while waiting or running:
            for run in list(waiting):
                if len(running) >= jobs or failed:
                    break
                if any(d not in done for d in (*run.reuse, *run.after)):
                    continue
                for source in run.reuse:
                    n = link_finished_stages(runs / table[source].out, runs / run.out)
                    if n:
                        say(f"[pages] {run.name}: {n} finished stages of {source} linked in")
                slot = min(set(range(jobs)) - {s for s, _, _ in running.values()})
                pin = [cores[slot]] if jobs > 1 and len(cores) >= jobs else None
                args = run.command(runs, preset)
                if args[0] in ("reproduce", "compare-algorithms"):
                    args += ["--workers", str(workers), "--no-progress"]
                what = f"python -m {run.module}" if run.module else "uavris"
                say(f"[pages] {run.name}: {what} {' '.join(args)}" + (f" (core {pin[0]})" if pin else ""))
                with open(logs / f"{run.name}.log", "a", encoding="utf-8") as log:
                    proc = subprocess.Popen([sys.executable, "-m", run.module or "uavris", *args], stdout=log,
                                            stderr=subprocess.STDOUT, preexec_fn=_die_with_parent(pin))
                running[run.name] = (slot, proc, time.perf_counter())
                waiting.remove(run)
            if not running:
                break  # what waits needs a study that failed
            time.sleep(0.5)
            for name, (_, proc, began) in list(running.items()):
                if proc.poll() is None:
                    continue
                del running[name]
                if proc.returncode != 0:
                    failed.append(name)
                    say(f"[pages] {name} failed (exit {proc.returncode}): see {logs / (name + '.log')}")
                else:
                    done.add(name)
                    say(f"[pages] {name} finished in {(time.perf_counter() - began) / 60:.1f} min")
    finally:
        _stop(running)
    if failed:
        raise UavrisError(f"{', '.join(failed)} failed: see {', '.join(str(logs / (n + '.log')) for n in failed)} "
                          "(a rerun resumes)")


def make_pages(pages: Sequence[str], runs: Path, dest: Path, preset: str = "quick", seeds: int = SEEDS,
               jobs: int = 1, workers: int = 2, say: Callable[[str], None] = print) -> list[Path]:
    """Run the studies ``pages`` read (:func:`run_studies`) and write each page into ``dest``,
    stamped; returns the files written."""
    unknown = [p for p in pages if p not in PAGES]
    if unknown:
        raise UavrisError(f"no page {', '.join(unknown)}: the pages are {', '.join(PAGES)}")
    if seeds < 3:
        raise UavrisError(f"--seeds must be at least 3 (a claim over fewer units is not measured), got {seeds}")
    run_studies(_needed(pages, preset, seeds), runs, preset, jobs, workers, say)
    written: list[Path] = []
    for name in pages:
        files = PAGES[name].write(runs, dest, preset, seeds)
        say(f"[pages] wrote {', '.join(str(f) for f in files)}")
        written += files
    return written


__all__ = ["PAGES", "SEEDS", "Page", "StudyRun", "link_finished_stages", "make_pages", "run_studies", "studies"]


def check_pages(results: Path) -> list[str]:
    """What is wrong with the results pages in ``results`` (empty: nothing): a page whose stamp is
    older than this code (:func:`uavris.experiments.study.stamp.stale`) that ``historical.yaml``
    does not list with its reason, a listed page that does not say so before its first section
    (:func:`~uavris.experiments.study.stamp.historical_banner`) or that is current after all, a
    listed page that is not there, a stamp that does not read."""
    listed_file = results / HISTORICAL_FILE
    listed = read_yaml(listed_file) if listed_file.is_file() else {}
    if not isinstance(listed, dict) or not all(isinstance(k, str) and isinstance(v, str) and v.strip()
                                               for k, v in listed.items()):
        return [f"{listed_file}: expected a mapping of page file to the reason it is kept"]
    problems = [f"{name} is listed in {HISTORICAL_FILE} but is not a page here" for name in listed
                if not (results / name).is_file()]
    for page in sorted(results.glob("*.md")):
        text = page.read_text(encoding="utf-8")
        try:
            why = stale(read_stamp(text, str(page)))
        except UavrisError as e:
            problems.append(str(e))
            continue
        if page.name in listed:
            top = text.split("\n## ", 1)[0]
            if not why:
                problems.append(f"{page.name} is current, yet listed as historical in {HISTORICAL_FILE}")
            elif historical_banner(listed[page.name].strip()) not in top:
                problems.append(f"{page.name} is listed as historical but does not say so at its top "
                                f"({historical_banner('REASON')!r}, the reason {HISTORICAL_FILE} gives)")
        elif why:
            problems.append(f"{page.name} is older than this code: {'; '.join(why)} (remake it with uavris pages, "
                            f"or list it in {HISTORICAL_FILE} with the reason)")
    return problems
