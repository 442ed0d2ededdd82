"""The commands that judge the paper's claims and make the results pages: ``uavris claims``, ``uavris
from-scratch`` (what it may read) and ``uavris pages`` (every results page from one version).

Lives here: their flags (:class:`ClaimsArgs`, :class:`FromScratchArgs`, :class:`PagesArgs`),
:func:`claims_command`, :func:`from_scratch_command` and :func:`pages_command`. Not here: the
judging (:mod:`uavris.experiments.study.claims`), the measurement
(:mod:`uavris.experiments.study.from_scratch`), the pages and their studies
(:mod:`uavris.experiments.study.pages`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from uavris.cli.outputs import output_dir, writing
from uavris.cli.parsing import Unset, UsageError, parse
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.study.claims import write_claims
from uavris.experiments.study.from_scratch import FromScratchConfig, from_scratch
from uavris.experiments.study.pages import PAGES, make_pages, studies
from uavris.presets import Preset


@dataclass(frozen=True)
class ClaimsArgs:
    studies: Annotated[tuple[Path, ...], tyro.conf.Positional, tyro.conf.arg(metavar="OUT")]
    """output directories of uavris reproduce: the paper and strong tracks pooled over them (run each with its
    own --seed), the deployment track from the first that ran it"""
    out: Path = Path("runs/claims")
    """where claims.md and claims.json are written"""
    budget_comparison: Unset[Path] = None
    """a uavris compare-algorithms directory run longer (--steps) and evaluated at --budgets"""
    budgets: tuple[int, ...] = ()
    """environment steps at which --budget-comparison's runs are judged (each a multiple of its --eval-every)"""
    from_scratch: Unset[Path] = None
    """uavris from-scratch's file: the deployment track's fine-tuning against an expert trained from scratch"""


def claims_command(args: list[str]) -> None:
    """Judge the paper's claims in every track of one or more studies, by one rule.

    A claim holds where the 95% CI of its paired difference over the unit of generalisation
    (a training seed in the paper and strong tracks: one study each, its unseen scenarios
    averaged; an unseen hall in the deployment track) excludes zero the claimed way, is refuted
    where it excludes zero the other way, and is not resolved otherwise; a cell of fewer than 3
    units is not measured. Writes OUT/claims.md (the claim x track table, what each cell
    compares, what the verdicts rest on) and OUT/claims.json.
    """
    a = parse(ClaimsArgs, args, "uavris claims", claims_command.__doc__ or "")
    if bool(a.budgets) != (a.budget_comparison is not None):
        raise UsageError("--budget-comparison and --budgets go together")
    if any(b < 1 for b in a.budgets):
        raise UsageError(f"--budgets must be environment steps >= 1, got {list(a.budgets)}")
    with writing(a.out):
        path = write_claims(list(a.studies), a.out, [(a.budget_comparison, b) for b in a.budgets], a.from_scratch)
    print(path.read_text().split("\n\n", 2)[1])
    print(f"wrote {path}")


@dataclass(frozen=True)
class FromScratchArgs:
    study: Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="OUT")]
    """output directory of uavris reproduce --track deployment --ablation (its fine-tuning that tries places)"""
    config: FromScratchConfig = FromScratchConfig()
    """what is measured"""
    out: Path = Path("runs/from-scratch.json")
    """where the per-hall numbers are written (uavris claims --from-scratch reads them)"""


def from_scratch_command(args: list[str]) -> None:
    """Fewer interactions, measured: in a study's first unseen halls, fine-tuning against hybrid
    PPO trained there from scratch (under the safety layer, evaluated every --config.eval-every
    steps on the study's episodes, for --config.steps): the interactions each needs to first
    reach 95% of that expert's final evaluation. Hours on one core per hall at the defaults.
    Writes --out (JSON: each hall's levels, curves and interactions, rewritten after every hall;
    uavris claims --from-scratch reads it).
    """
    a = parse(FromScratchArgs, args, "uavris from-scratch", from_scratch_command.__doc__ or "")
    rows: list[tuple[str, ...]] = []

    def report(h: dict) -> None:
        rows.append((h["hall"], f"{h['zero_shot']:.2f}", f"{h['finetuned']:.2f}", f"{h['expert_final']:.2f}",
                     f"{h['finetune_to_level']:,.0f}", f"{h['expert_to_level']:,.0f}" if h["reached"] else
                     f"not within {h['expert_steps']:,}", f"{h['expert_wall_s']:.0f}"))
        print("\n".join(markdown_table(("hall", "zero-shot level", "fine-tuned level", "expert's final level",
                                        "fine-tuning reaches 95% of it after", "the expert after",
                                        "expert's training (s)"), rows, "lrrrrrr")), flush=True)

    with writing(a.out.parent, "--out's folder", files_only=True):
        from_scratch(a.study, a.config, a.out, report)
    print(f"wrote {a.out}")


@dataclass(frozen=True)
class PagesArgs:
    pages: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="PAGE")] = ()
    """the pages to make (default: every page; --list names them)"""
    runs: Path = Path("runs/pages")
    """where the studies the pages read are run (each resumes: a rerun continues them)"""
    dest: Path = Path("docs/results")
    """where the pages are written"""
    preset: Preset = "quick"
    """the studies' preset (smoke: a minute's check of the whole chain)"""
    seeds: int = 5
    """training seeds of the paper and strong tracks on the claims page (at least 3)"""
    jobs: int = 1
    """studies run at a time (each pinned to a core of its own where the machine has one per job)"""
    workers: int = 2
    """job processes of each study"""
    list: bool = False
    """name every page, the studies it reads and their commands, and exit (nothing run or written)"""


def pages_command(args: list[str]) -> None:
    """Every results page from one version: run the studies the pages read, then write each page,
    stamped with what made it (the results format, the oracle's version, the demonstrations'
    teacher, the preset, the commit, the machine and float path, the date, the studies read).

    Every study resumes (finished stages, runs and halls are kept), so a rerun continues where
    it stopped; studies that start from another's finished stages have those linked in first.
    Writes each page into --dest (DEST/FILE.md, stamped, with its figures; the claims page its
    evidence beside it) and the studies under --runs; each study's progress goes to
    RUNS/.pages/STUDY.log. Ctrl-C or SIGTERM stops the running studies.
    """
    a = parse(PagesArgs, args, "uavris pages", pages_command.__doc__ or "")
    if a.jobs < 1 or a.workers < 1:
        raise UsageError(f"--jobs and --workers must be >= 1, got {a.jobs} and {a.workers}")
    if a.seeds < 3:
        raise UsageError(f"--seeds must be at least 3 (a claim over fewer units is not measured), got {a.seeds}")
    unknown = [p for p in a.pages if p not in PAGES]
    if unknown:
        raise UsageError(f"no page {', '.join(unknown)}; the pages are {', '.join(PAGES)}")
    names = list(a.pages or PAGES)
    if a.list:
        table = studies(a.preset, a.seeds)
        for name in names:
            page = PAGES[name]
            print(f"{name} ({a.dest / page.file}): {page.about}")
            for study in page.reads(a.seeds):
                print(f"  {table[study].line(a.runs, a.preset)}")
        return
    output_dir(a.runs, "--runs")
    with writing(a.dest, "--dest"):
        for path in make_pages(names, a.runs, a.dest, a.preset, a.seeds, a.jobs, a.workers):
            print(f"wrote {path}")
