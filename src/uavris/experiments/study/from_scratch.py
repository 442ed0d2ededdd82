"""Fewer interactions, measured: fine-tuning in a new hall against an expert trained there from scratch.

Lives here: :class:`FromScratchConfig` and :func:`from_scratch` (``uavris from-scratch STUDY``),
whose ``from-scratch.json`` ``uavris claims --from-scratch`` reads. Not here: the judging
(:mod:`.claims`), the study it reads (:class:`.finished.Study`).

The paper's claim: the pre-trained DT, fine-tuned in an unseen scenario, reaches the expert's
level "with fewer interactions". Here, in the deployment track of a finished study made with
``--ablation``, in its first ``halls`` unseen halls of its own:

- fine-tuning: the goal-conditioned DT fine-tuned by trying places (the study's
  ``deploy-finetune-places-LAYOUT`` stages, every pre-training seed): its level (the mean over
  seeds of the study's score of ``dt-goal-finetuned-safe``; the zero-shot ``dt-goal-safe``
  beside it), the interactions it used (the mean over seeds of its ``env_interactions``) and
  those it took to first reach 95% of the expert's final evaluation (the claims' rule);
- from scratch: hybrid PPO on the motion entries with the optimiser's phases (the strong
  track's learner, no imitation, the quick hyperparameters), trained in the hall from its
  start under the attitude safety layer, evaluated every ``eval_every`` environment steps on
  the study's evaluation episodes, for ``steps`` steps: its whole learning curve, which the
  claims read (both sides charged until they first reach 95% of its final evaluation).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from uavris.agents.oracle.planner import SAFE_MARGIN_DEG
from uavris.config import DictConfig
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.study.claims_tracks import LEVEL, finetune_curve
from uavris.experiments.study.finished import Study
from uavris.experiments.study.tracks import TRACK_SPECS, zero_shot_only
from uavris.io import read_csv, write_json
from uavris.stats import interactions_to_level


@dataclass(frozen=True)
class FromScratchConfig(DictConfig):
    """What ``uavris from-scratch`` measures."""

    halls: int = 4  # the study's first unseen halls of its own
    steps: int = 200_000  # the expert's budget of environment steps
    eval_every: int = 10_000  # environment steps between the expert's evaluations

    def __post_init__(self) -> None:
        for name in ("halls", "steps", "eval_every"):
            if getattr(self, name) < 1:
                raise ConfigError(f"FromScratchConfig.{name} must be >= 1, got {getattr(self, name)}")


def from_scratch(out: str | Path, cfg: FromScratchConfig, dest: Path,
                 report: Callable[[dict[str, Any]], None] = lambda hall: None) -> dict[str, Any]:
    """Measure (module docstring) in the study ``out``; write ``dest`` (JSON) after every hall,
    calling ``report`` with each hall's numbers; returns what it wrote."""
    from uavris.experiments.engine.jobs import machine
    from uavris.experiments.training.train_expert import TrainConfig, train

    study = Study.open(out)
    rc, track = study.config, TRACK_SPECS["deployment"]
    if track not in rc.tracks or not rc.ablation:
        raise UavrisError(f"{out}: the measurement needs the deployment track's fine-tuning (uavris reproduce --track "
                          "deployment --ablation)")
    _, unseen = study.sites(track)
    demos = study.demonstrations(track)
    measured: dict[str, Any] = {"study": str(Path(out).resolve()), "cpu": machine(), "config": cfg.to_dict(),
                                "demonstrations": demos, "halls": []}
    for where in [w for w in unseen if not zero_shot_only(w, rc.system)][:cfg.halls]:
        found = study.evaluation(track, where.name)
        if found is None:
            raise UavrisError(f"{out}: the evaluation in {where.name} has not finished")
        res = found[1]
        fine = [v for v in res.values() if v["variant"] == "dt-goal-finetuned-safe"]
        finetuned = float(np.mean([v["mean"] for v in fine]))
        tried = [study.places_tried(track, where.name, v["seed"] or 0) for v in fine]
        places = [t[0] for t in tried if t is not None]
        used = [t[1]["env_interactions"] for t in tried if t is not None]
        expert = TrainConfig(algo="ppo", scenario=where.name, start=where.scenario.start, seed=0, preset="quick",
                             total_steps=cfg.steps, eval_every=cfg.eval_every, eval_episodes=rc.eval_episodes,
                             phase_control="optimizer", system=where.system.replace(front_margin_deg=SAFE_MARGIN_DEG))
        with tempfile.TemporaryDirectory() as tmp:
            began = time.perf_counter()
            train(expert, Path(tmp) / "run", progress=False)
            wall = time.perf_counter() - began
            evals = read_csv(Path(tmp) / "run" / "evals.csv")
        x, y = np.array([float(r["env_steps"]) for r in evals]), np.array([float(r["mean"]) for r in evals])
        # the claims charge both sides until they first reach 95% of this expert's final evaluation
        # (claims_tracks.interactions_needed): its whole curve is kept
        to_level, censored = interactions_to_level(x, y, LEVEL * float(y[-1]))
        finetune_to_level = float(np.mean([interactions_to_level(*finetune_curve(d / "model"), LEVEL * float(y[-1]))[0]
                                           for d in places if d is not None]))
        hall = {"hall": where.name, "finetuned": finetuned, "oracle": float(res["oracle-safe"]["mean"]),
                "zero_shot": float(np.mean([v["mean"] for v in res.values() if v["variant"] == "dt-goal-safe"])),
                "finetune_interactions": float(np.mean(used)), "finetune_to_level": finetune_to_level,
                "expert_best": float(y.max()),
                "expert_final": float(y[-1]), "expert_to_level": to_level, "reached": not censored,
                "expert_curve": [x.tolist(), y.tolist()], "expert_steps": cfg.steps, "expert_wall_s": wall}
        measured["halls"].append(hall)
        write_json(dest, measured)
        report(hall)
    return measured
