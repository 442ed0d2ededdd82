"""Fewer interactions, measured: fine-tuning in a new hall against an expert trained there from scratch.

Lives here: :class:`FromScratchConfig` and :func:`from_scratch` (``uavris from-scratch STUDY``),
whose ``from-scratch.json`` ``uavris claims --from-scratch`` reads. Not here: the judging
(:mod:`.claims`), the study it reads (:class:`.finished.Study`).

The paper's claim: the pre-trained DT, fine-tuned in an unseen scenario, reaches the expert's
level "with fewer interactions". Here, in the deployment track of a finished study made with
``--ablation``, in its first ``halls`` unseen halls of its own, both sides are measured alike,
on the study's evaluation episodes under the attitude safety layer:

- fine-tuning: the paper's DT fine-tuned in the hall by its Algorithm 1 (the study's
  ``deploy-finetune-LAYOUT`` stage): the pre-trained model it started from and the model
  after each round (its checkpoints), each evaluated on the study's episodes under the layer,
  against the environment interactions fine-tuning had used (``finetune_curve``);
- from scratch: hybrid PPO on the motion entries with the optimiser's phases (the strong
  track's learner, no imitation, the quick hyperparameters), trained in the hall from its
  start under the attitude safety layer, evaluated every ``eval_every`` environment steps on
  the study's evaluation episodes, for ``steps`` steps (``expert_curve``).

The claims read both curves (both sides charged until they first reach 95% of the expert's
final evaluation). The file is rewritten after every hall, and a rerun of the same
measurement of the same study keeps the halls it holds.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from uavris.agents.evaluation import evaluate
from uavris.agents.oracle.planner import SAFE_MARGIN_DEG
from uavris.config import DictConfig
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.engine.process import machine
from uavris.experiments.study.claims_tracks import LEVEL
from uavris.experiments.study.finished import Study
from uavris.experiments.study.stage_names import PRETRAIN
from uavris.experiments.study.tracks import TRACK_SPECS, zero_shot_only
from uavris.experiments.tools.rows import Row
from uavris.experiments.tools.targets import DTModel
from uavris.experiments.training.train_expert import TrainConfig, train
from uavris.io import read_csv, read_json, write_json
from uavris.presets import EVAL_SEED
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


def finetune_curve_alike(study: Study, where: Any, episodes: int) -> tuple[list[float], list[float]]:
    """The paper's DT's fine-tuning in ``where`` as the expert's curve is measured: the
    pre-trained model and each round's model evaluated on the study's ``episodes`` evaluation
    episodes under the safety layer, against the interactions fine-tuning had used by then."""
    track = TRACK_SPECS["deployment"]
    fdir = study.finetuned(track, where.name)
    pretrained = study.done(track.stage(PRETRAIN))
    if fdir is None or pretrained is None:
        raise UavrisError(f"{study.out}: the paper's DT was not fine-tuned in {where.name} (uavris reproduce --track "
                          "deployment --ablation runs it)")
    rounds = read_csv(fdir / "model" / "finetune.csv")
    models = [pretrained / "model", *(fdir / "model" / "checkpoints" / f"round_{int(r['round'])}" for r in rounds[1:])]
    x, y = [], []
    for r, model in zip(rounds, models):
        row = Row("dt-finetuned", "fine-tuned DT", DTModel.at(model), front_margin_deg=SAFE_MARGIN_DEG)
        system = row.system(where.system)
        res = evaluate(row.load(system).policy, system, where.scenario, episodes, EVAL_SEED)
        x.append(float(r["env_interactions"]))
        y.append(float(np.mean(res.avg_sum_rate)))
    return x, y


def from_scratch(out: str | Path, cfg: FromScratchConfig, dest: Path,
                 report: Callable[[dict[str, Any]], None] = lambda hall: None) -> dict[str, Any]:
    """Measure (module docstring) in the study ``out``; write ``dest`` (JSON) after every hall,
    calling ``report`` with each hall's numbers; returns what it wrote. The halls ``dest``
    already holds of the same measurement of the same study are kept, not measured again."""
    study = Study.open(out)
    rc, track = study.config, TRACK_SPECS["deployment"]
    if track not in rc.tracks or not rc.ablation:
        raise UavrisError(f"{out}: the measurement needs the deployment track's fine-tuning (uavris reproduce --track "
                          "deployment --ablation)")
    _, unseen = study.sites(track)
    demos = study.demonstrations(track)
    measured: dict[str, Any] = {"study": str(Path(out).resolve()), "cpu": machine(), "config": cfg.to_dict(),
                                "format": FORMAT, "demonstrations": demos, "halls": []}
    kept = _kept(dest, measured)
    for where in [w for w in unseen if not zero_shot_only(w, rc.system)][:cfg.halls]:
        if where.name in kept:
            measured["halls"].append(kept[where.name])
            report(kept[where.name])
            continue
        found = study.evaluation(track, where.name)
        if found is None:
            raise UavrisError(f"{out}: the evaluation in {where.name} has not finished")
        res = found[1]
        fx, fy = finetune_curve_alike(study, where, rc.eval_episodes)
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
        # (claims_tracks.interactions_needed): both whole curves are kept
        to_level, censored = interactions_to_level(x, y, LEVEL * float(y[-1]))
        finetune_to_level, _ = interactions_to_level(fx, fy, LEVEL * float(y[-1]))
        hall = {"hall": where.name, "finetuned": float(res["dt-finetuned-safe"]["mean"]),
                "oracle": float(res["oracle-safe"]["mean"]), "zero_shot": fy[0],
                "finetune_interactions": fx[-1], "finetune_to_level": finetune_to_level, "finetune_curve": [fx, fy],
                "expert_best": float(y.max()),
                "expert_final": float(y[-1]), "expert_to_level": to_level, "reached": not censored,
                "expert_curve": [x.tolist(), y.tolist()], "expert_steps": cfg.steps, "expert_wall_s": wall}
        measured["halls"].append(hall)
        write_json(dest, measured)
        report(hall)
    write_json(dest, measured)
    return measured


# 2: fine-tuning is the paper's DT by its Algorithm 1, its curve on the study's episodes under the safety layer
FORMAT = 2


def _kept(dest: Path, measured: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The halls an earlier run wrote to ``dest`` of this same measurement (study, settings,
    format and demonstrations), by name; none where ``dest`` holds another's or none."""
    if not Path(dest).is_file():
        return {}
    old = read_json(dest)
    same = all(old.get(k) == measured[k] for k in ("study", "config", "format", "demonstrations"))
    return {h["hall"]: h for h in old.get("halls", [])} if same else {}
