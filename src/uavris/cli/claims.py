"""The command that judges the paper's claims: ``uavris claims``.

Lives here: its flags (:class:`ClaimsArgs`) and :func:`claims_command`. Not here: the
judging (:mod:`uavris.experiments.study.claims`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from uavris.cli.parsing import Unset, UsageError, output_dir, parse


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
    """benchmarks/from_scratch.py --json's file: the deployment track's fine-tuning against an expert from scratch"""


def claims_command(args: list[str]) -> None:
    """Judge the paper's three claims in every track of one or more studies, by one rule.

    A claim holds where the 95% CI of its paired difference over the unit of generalisation
    (a seed and scenario in the paper and strong tracks, an unseen hall in the deployment
    track) excludes zero the claimed way, is refuted where it excludes zero the other way, and
    is not resolved otherwise. Writes OUT/claims.md (the claim x track table, then what each
    cell compares) and OUT/claims.json.
    """
    from uavris.experiments.study.claims import write_claims

    a = parse(ClaimsArgs, args, "uavris claims", claims_command.__doc__ or "")
    if bool(a.budgets) != (a.budget_comparison is not None):
        raise UsageError("--budget-comparison and --budgets go together")
    if any(b < 1 for b in a.budgets):
        raise UsageError(f"--budgets must be environment steps >= 1, got {list(a.budgets)}")
    output_dir(a.out)
    path = write_claims(list(a.studies), a.out, [(a.budget_comparison, b) for b in a.budgets], a.from_scratch)
    print(path.read_text().split("\n\n", 2)[1])
    print(f"wrote {path}")
