"""Fine-tuning (paper Algorithm 1, stage 2): the pre-trained DT online in one scenario, from elites.

Lives here: :class:`FinetuneConfig` and :func:`finetune`. Not here: the model and its
training, the windows, loss and steps (:mod:`uavris.agents.dt.training`), the run
directory's machinery (:mod:`.dt_runs`).

In one scenario, for H rounds:
collect N trajectories with Gaussian noise sigma on the DT's actions, keep K elites,
relabel their returns-to-go from the rewards actually received, and minimise L_FT (eq. 19)
on them. The paper fixes N = 80 and K = 50 and leaves the rest open; ours, with reasons:

- Elites (a departure, docs/model.md): by default (``selection="paired"``) the N candidates
  are N / 5 episode seeds with 5 noisy rollouts each, and the K kept are those with the
  largest return relative to the mean of their seed's rollouts. Rollouts of one seed share
  every channel and pairing draw, so the difference is what the actions did; the paper's
  plain top-K by return (eq. 18, ``selection="return"``) mostly keeps episodes that were
  lucky in which pairs were active.

- H = 10 rounds (``paper``), 3 (``quick``): 800 episodes = 80,000 slots of interaction in
  ``paper``, about 3% of one DDPG expert's 2.5 M training steps, which is the saving the
  paper claims for fine-tuning over training an expert.
- sigma = 0.1, the DDPG experts' own exploration noise (actions live in [-1, 1]).
- Learning rate 5e-5 after a 100-step warm-up, one AdamW for all rounds: half the
  pre-training rate, large enough to move within a few hundred steps per round, small
  enough not to erase the pre-trained policy in one round.
- Epochs per round: 5 (``paper``), 2 (``quick``), an epoch being ceil(elite slots / batch)
  sampled windows (banded DT: ceil(elites x context / batch) sampled episodes, about as
  many predicted actions); only the current round's elites are trained on, as in Algorithm 1.
- The target return stays the pre-trained model's default (or ``--target-return``), so
  zero-shot and fine-tuned policies are conditioned alike; the state normalisation and
  return scale of the pre-trained model are kept, so its inputs mean the same thing.
- Environment interactions = slots of the candidate trajectories (N per round, each up to
  T slots); evaluation episodes are reported separately and not counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
from numpy.typing import NDArray

from uavris.agents.dt.checkpoint import save_dt
from uavris.agents.dt.goals import FixedGoals
from uavris.agents.dt.policy import DTBatchPolicy, load_dt_policy
from uavris.agents.dt.training import TrainingWindows, load_trainer_state, make_optimizer, train_steps
from uavris.agents.dt.trajectories import ELITE_RULES, EliteRule, Trajectory, record_episodes, select_elites
from uavris.agents.evaluation import evaluate
from uavris.agents.place.checkpoint import load_value
from uavris.agents.place.planner import learned_plan, places_to_try
from uavris.agents.policy import LevelAttitude, check_policy_fits
from uavris.config import (
    Scenario,
    ScenarioName,
    SystemConfig,
    check_non_negative,
    check_positive,
    float_tuple,
    scenario_at,
)
from uavris.env.simulator import layout_as_lists
from uavris.errors import ConfigError
from uavris.experiments.display.progress import progress_bar, tb_writer
from uavris.experiments.training.dt_runs import (
    FINETUNE_KIND,
    INT_COLUMNS,
    latest_checkpoint,
    prepare_run_dir,
    restore_weights,
    write_checkpoint,
)
from uavris.io import read_rows, write_csv
from uavris.presets import (
    EVAL_SEED,
    FINETUNE,
    FINETUNE_SEED,
    PRESET,
    Preset,
    PresetConfig,
    check_preset,
    fill_from_preset,
)
from uavris.runs import RunClock, write_done

ROUND_HEADER = ("round", "env_interactions", "gradient_steps", "candidate_mean_return", "candidate_avg_sum_rate",
                "elite_mean_return", "elite_min_return", "loss", "eval_mean", "eval_ci_low", "eval_ci_high")


@dataclass(frozen=True)
class FinetuneConfig(PresetConfig):
    """Everything that determines a fine-tuning run (dumped as config.yaml). Fields left at
    ``PRESET`` take the preset's values (:data:`uavris.presets.FINETUNE`)."""

    model: str  # a pre-trained DT: a `uavris pretrain-dt` run or model directory
    scenario: ScenarioName | str  # where it adapts (or a layout's name, with start)
    start: tuple[float, float, float] | None = None  # the UAV's start; None: the named scenario's (a layout sets it)
    system: SystemConfig | None = None  # the hall to adapt to; None: the pre-trained model's system
    preset: Preset = "quick"  # the schedule's defaults: smoke (seconds), quick (minutes), paper
    seed: int = 0  # seed of the exploration noise and of the sampled windows
    rounds: int = PRESET  # rounds H of collection and training
    candidates: int = PRESET  # noisy trajectories N per round
    elites: int = PRESET  # trajectories K kept per round
    noise_sigma: float = 0.1  # standard deviation sigma of the exploration noise on the actions
    selection: EliteRule = "paired"  # "return": eq. (18); "paired": within-seed ranking (docs/model.md)
    rollouts_per_seed: int = PRESET  # paired: candidates = seeds x rollouts_per_seed
    level_rollouts: int = 0  # paired: of each seed's rollouts, this many hold the attitude level (an alternative)
    epochs_per_round: int = PRESET  # passes over the elites per round
    batch_size: int = PRESET  # windows per gradient step
    learning_rate: float = 5e-5  # AdamW's rate after the warm-up
    weight_decay: float = 1e-4  # AdamW's decoupled weight decay
    warmup_steps: int = PRESET  # linear warm-up of the learning rate
    grad_clip: float = 0.25  # gradient-norm clipping
    target_return: float | None = None  # None: the pre-trained model's default
    eval_episodes: int = PRESET  # evaluation episodes after each round (the zero-shot model first)
    eval_seed: int = EVAL_SEED  # seed of the first evaluation episode
    collect_seed: int = FINETUNE_SEED  # seed of the first candidate episode
    value: str | None = None  # a goal-conditioned DT: the learned value whose planner gives its goal (places)
    places: int = 0  # a goal-conditioned DT: its candidates try the start and this many of the best places by V

    def __post_init__(self) -> None:
        check_preset(self.preset)
        fill_from_preset(self, FINETUNE[self.preset])
        object.__setattr__(self, "model", str(self.model))
        if isinstance(self.system, dict):
            object.__setattr__(self, "system", SystemConfig.from_dict(self.system))
        if self.start is not None:
            object.__setattr__(self, "start", float_tuple(self.start, "FinetuneConfig", "start", "[x, y, z] (m)"))
        scenario = scenario_at(self.scenario, self.start)
        if self.system is not None:
            scenario.validate_for(self.system)
        check_positive("FinetuneConfig", self, ("rounds", "candidates", "elites", "epochs_per_round", "batch_size",
                                                 "learning_rate", "warmup_steps", "grad_clip", "eval_episodes"))
        if self.elites > self.candidates:
            raise ConfigError(f"FinetuneConfig.elites ({self.elites}) must be <= candidates ({self.candidates})")
        if self.selection not in ELITE_RULES:
            raise ConfigError(f"FinetuneConfig.selection must be one of {', '.join(ELITE_RULES)}, "
                              f"got {self.selection!r}")
        if self.selection == "paired" and not (isinstance(self.rollouts_per_seed, int) and self.rollouts_per_seed >= 2
                                               and self.candidates % self.rollouts_per_seed == 0):
            raise ConfigError(f"FinetuneConfig.rollouts_per_seed must be an integer >= 2 dividing candidates "
                              f"({self.candidates}) for paired selection, got {self.rollouts_per_seed!r}")
        check_non_negative("FinetuneConfig", self, ("noise_sigma", "seed", "weight_decay", "eval_seed",
                                                    "collect_seed"))
        if not (isinstance(self.level_rollouts, int) and 0 <= self.level_rollouts
                and (self.level_rollouts == 0 or (self.selection == "paired"
                                                  and self.level_rollouts < self.rollouts_per_seed))):
            raise ConfigError(f"FinetuneConfig.level_rollouts must be 0, or (paired selection) an integer below "
                              f"rollouts_per_seed ({self.rollouts_per_seed}), got {self.level_rollouts!r}")
        if self.target_return is not None and not math.isfinite(self.target_return):
            raise ConfigError(f"FinetuneConfig.target_return must be finite, got {self.target_return}")
        if self.places and (self.value is None or self.selection != "paired"
                            or self.rollouts_per_seed % (self.places + 1) or self.level_rollouts):
            raise ConfigError(f"FinetuneConfig.places ({self.places}) needs a learned value, paired selection and "
                              f"rollouts_per_seed a multiple of places + 1 (each seed tries every place), without "
                              f"level_rollouts; got value {self.value!r}, rollouts_per_seed {self.rollouts_per_seed}")


def _candidates(cfg: FinetuneConfig, h: int, dt_policy: Callable[..., DTBatchPolicy], system: SystemConfig,
                scenario: Scenario, phase_control: str, places: NDArray | None = None) -> list[Trajectory]:
    """Round ``h``'s noisy rollouts: ``candidates / rollouts_per_seed`` episode seeds with
    ``rollouts_per_seed`` rollouts each (paired selection; one each for plain top-K), the
    noise seeded by (seed, round), so that a resumed run explores as an uninterrupted one.
    ``level_rollouts`` of each seed's rollouts hold the attitude level
    (:class:`~uavris.agents.policy.LevelAttitude`): not only noise around the model's own path
    but the alternative to its tilts, recorded as flown, which the paired elites keep where it
    pays (a tilt that puts a device behind the RIS: docs/study.md, section 2)."""
    noise_seed = int(np.random.SeedSequence([cfg.seed, h]).generate_state(1)[0])
    per_seed = cfg.rollouts_per_seed if cfg.selection == "paired" else 1
    distinct = cfg.candidates // per_seed
    first = cfg.collect_seed + (h - 1) * cfg.candidates + np.arange(distinct)
    seeds = np.repeat(first, per_seed - cfg.level_rollouts)
    if places is not None:  # one place per episode: each seed's rollouts go round the places (the start first)
        goals = places[np.arange(len(seeds)) % len(places)]
        return record_episodes(dt_policy(cfg.noise_sigma, noise_seed, FixedGoals(goals)), system, scenario, seeds,
                               expert="dt-finetune", expert_algo="dt", phase_control=phase_control, goal=goals)
    out = record_episodes(dt_policy(cfg.noise_sigma, noise_seed), system, scenario, seeds, expert="dt-finetune",
                          expert_algo="dt", phase_control=phase_control)
    if cfg.level_rollouts:
        level_seed = int(np.random.SeedSequence([cfg.seed, h, 1]).generate_state(1)[0])
        out += record_episodes(LevelAttitude(dt_policy(cfg.noise_sigma, level_seed)), system, scenario,
                               np.repeat(first, cfg.level_rollouts), expert="dt-finetune-level", expert_algo="dt",
                               phase_control=phase_control)
    return out


def _round_row(h: int, interactions: int, steps: int, cands: list[Trajectory], elites: list[Trajectory],
               losses: Sequence[float], ev: dict[str, Any]) -> dict[str, Any]:
    """Round ``h``'s row of finetune.csv (round 0, the zero-shot model, has no candidates)."""
    def mean(x: Sequence[float]) -> float:
        return float(np.mean(x)) if len(x) else float("nan")

    return {"round": h, "env_interactions": interactions, "gradient_steps": steps,
            "candidate_mean_return": mean([tr.episode_return for tr in cands]),
            "candidate_avg_sum_rate": mean([tr.episode_return / tr.length for tr in cands]),
            "elite_mean_return": mean([tr.episode_return for tr in elites]),
            "elite_min_return": float(elites[-1].episode_return) if elites else float("nan"), "loss": mean(losses),
            "eval_mean": ev["mean"], "eval_ci_low": ev["ci_low"], "eval_ci_high": ev["ci_high"]}


def _evaluation(row: dict[str, Any]) -> dict[str, float]:
    """A round's evaluation from its log row: mean and 95% CI."""
    return {"mean": row["eval_mean"], "ci_low": row["eval_ci_low"], "ci_high": row["eval_ci_high"]}


def paired_place_scores(places: NDArray, goals: NDArray, seeds: NDArray, returns: NDArray
                        ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Each episode's place (the one nearest its goal) and paired score: its return minus the
    mean return of its seed's episodes (they share every channel and pairing draw, so the
    difference is the place's)."""
    places, goals = np.asarray(places, dtype=np.float64), np.asarray(goals, dtype=np.float64)
    seeds, score = np.asarray(seeds), np.array(returns, dtype=np.float64)
    for s in np.unique(seeds):
        score[seeds == s] -= score[seeds == s].mean()
    return np.argmin(np.linalg.norm(places[None] - goals[:, None], axis=-1), axis=1), score


class Places:
    """Where a goal-conditioned DT is told to go while it fine-tunes: the learned planner's
    place at first (``chosen``), then, with places to try (``places``: the start and the best
    places by ``V``), the one whose episodes did best by :func:`paired_place_scores`, summed
    over all rounds (the highest mean paired score)."""

    def __init__(self, chosen: NDArray, places: NDArray | None) -> None:
        self.chosen = np.asarray(chosen, dtype=np.float64)
        self.places = None if places is None else np.asarray(places, dtype=np.float64)
        n = 0 if self.places is None else len(self.places)
        self.total, self.count = np.zeros(n), np.zeros(n)

    @classmethod
    def from_value(cls, cfg: FinetuneConfig, system: SystemConfig, start: tuple[float, float, float]) -> Places:
        """The learned value ``cfg.value``'s place, and with ``cfg.places`` the places to try."""
        if cfg.value is None:
            raise ConfigError("a goal-conditioned DT fine-tunes with a learned value to tell its goal "
                              "(FinetuneConfig.value)")
        value, _ = load_value(cfg.value)
        return cls(learned_plan(value, system, start).target,
                   places_to_try(value, system, start, cfg.places) if cfg.places else None)

    def update(self, cands: Sequence[Trajectory]) -> None:
        """Add a round's candidates' paired scores to their places', and choose the best place."""
        if self.places is None:
            return
        place, score = paired_place_scores(self.places, np.array([tr.goal for tr in cands]),
                                           np.array([tr.seed for tr in cands]),
                                           np.array([tr.episode_return for tr in cands]))
        np.add.at(self.total, place, score)  # episode by episode, in order
        np.add.at(self.count, place, 1.0)
        self.chosen = self.places[int(np.argmax(self.total / np.maximum(self.count, 1)))].copy()

    def state(self) -> dict[str, Any]:
        return {"place_total": self.total.tolist(), "place_count": self.count.tolist(), "goal": self.chosen.tolist()}

    def restore(self, meta: dict[str, Any]) -> None:
        self.total, self.count = np.asarray(meta["place_total"]), np.asarray(meta["place_count"])
        self.chosen = np.asarray(meta["goal"], dtype=np.float64)


def improvement_round(cfg: FinetuneConfig, h: int, dt_policy: Callable[..., DTBatchPolicy], model: Any,
                      opt: Any, rng: np.random.Generator, steps: int, system: SystemConfig, scenario: Scenario,
                      phase_control: str, places: Places | None
                      ) -> tuple[list[Trajectory], list[Trajectory], list[float], int]:
    """Algorithm 1's step ``h`` (paper Sec. IV, stage 2): noisy candidate rollouts, their elites
    (:func:`select_elites`), and the DT trained on the elites' windows, their returns-to-go from
    the rewards actually received; with ``places``, the candidates' paired scores choose the
    place the DT is told next. Returns the candidates, the elites, the losses and the number of
    gradient steps taken (``steps`` before them)."""
    cands = _candidates(cfg, h, dt_policy, system, scenario, phase_control, None if places is None else places.places)
    if places is not None:
        places.update(cands)
    elites = select_elites(cands, cfg.elites, cfg.selection)
    windows = TrainingWindows.for_model(elites, model.cfg, system)
    count = cfg.epochs_per_round * math.ceil(windows.samples_per_epoch / cfg.batch_size)
    losses = train_steps(model, opt, windows, rng, steps, count, cfg.batch_size, cfg.learning_rate,
                         cfg.warmup_steps, cfg.grad_clip)
    return cands, elites, losses, count


def default_finetune_dir(cfg: FinetuneConfig, root: str | Path = "runs/dt") -> Path:
    return Path(root) / f"finetune-{cfg.scenario}-s{cfg.seed}-{cfg.preset}"


def finetune(cfg: FinetuneConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
             progress: bool = True, device: str = "cpu") -> Path:
    """Fine-tune a pre-trained DT in ``cfg.scenario`` (Algorithm 1, stage 2): the zero-shot
    model evaluated (round 0), then ``cfg.rounds`` of :func:`improvement_round`, each evaluated,
    logged and checkpointed (``resume`` goes on from the last); returns the model directory."""
    cfg.check()  # before anything is written
    run_dir = Path(run_dir)
    pre = load_dt_policy(cfg.model, cfg.target_return, device=device)  # a run directory stands for its final model
    base, pre_meta, model_dir = pre.policy, pre.meta, pre.directory
    model, target, phase_control = base.model, base.target_return, base.phase_control
    system = cfg.system or pre.system
    check_policy_fits(base, system, str(model_dir))
    scenario = scenario_at(cfg.scenario, cfg.start)
    scenario.validate_for(system)
    resuming = prepare_run_dir(run_dir, FINETUNE_KIND, cfg.to_dict(), resume, force)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    opt = make_optimizer(model, cfg.learning_rate, cfg.weight_decay)
    model_meta = {**{k: v for k, v in pre_meta.items() if k not in ("kind", "format_version", "config")},
                  "stage": "finetune", "scenario": cfg.scenario, "start": list(scenario.start),
                  "system": system.to_dict(), "observation_layout": layout_as_lists(system),
                  "pretrained_model": str(cfg.model), "target_return": float(target)}

    places = Places.from_value(cfg, system, scenario.start) if model.cfg.goal else None

    def dt_policy(sigma: float = 0.0, noise_seed: int | None = None, goals: Any = None) -> DTBatchPolicy:
        if places is not None and goals is None:
            goals = FixedGoals(places.chosen)
        return DTBatchPolicy(model, target, sigma, noise_seed, phase_control, goals, system)

    done_round, steps, interactions, rows = 0, 0, 0, []
    if resuming and (latest := latest_checkpoint(run_dir)) is not None:
        done_round, ck = latest
        restore_weights(model, ck)
        meta = load_trainer_state(ck, opt, rng)
        steps, interactions = int(meta["gradient_steps"]), int(meta["env_interactions"])
        if places is not None:
            places.restore(meta)
        rows = read_rows(run_dir / "finetune.csv", ROUND_HEADER, done_round + 1, INT_COLUMNS)
    writer = tb_writer(run_dir, done_round)
    model.eval()
    if not rows:  # round 0: the zero-shot policy
        ev = evaluate(dt_policy(), system, scenario, cfg.eval_episodes, cfg.eval_seed).summary()
        rows.append(_round_row(0, 0, 0, [], [], [], ev))
        writer.add_scalar("eval/avg_sum_rate", ev["mean"], 0)
        write_csv(run_dir / "finetune.csv", ROUND_HEADER, rows)
    bar = progress_bar(cfg.rounds, f"finetune-dt {cfg.scenario}", "round", progress, done_round)
    clock = RunClock(run_dir, resuming)
    try:
        for h in range(done_round + 1, cfg.rounds + 1):
            cands, elites, losses, count = improvement_round(cfg, h, dt_policy, model, opt, rng, steps, system,
                                                             scenario, phase_control, places)
            interactions += sum(tr.length for tr in cands)
            steps += count
            ev = evaluate(dt_policy(), system, scenario, cfg.eval_episodes, cfg.eval_seed).summary()
            row = _round_row(h, interactions, steps, cands, elites, losses, ev)
            rows.append(row)
            for name, value in (("eval/avg_sum_rate", ev["mean"]),
                                ("rollout/candidate_mean_return", row["candidate_mean_return"]),
                                ("rollout/elite_mean_return", row["elite_mean_return"]), ("train/loss", row["loss"]),
                                ("rollout/env_interactions", interactions)):
                writer.add_scalar(name, value, h)
            write_csv(run_dir / "finetune.csv", ROUND_HEADER, rows)
            goal = {} if places is None else {"goal": places.chosen.tolist()}
            write_checkpoint(run_dir, h, model, {**model_meta, **goal, "env_interactions": interactions,
                                                  "finetune_rounds": h, "finetune_gradient_steps": steps}, opt, rng,
                              {"gradient_steps": steps, "env_interactions": interactions,
                               **({} if places is None else places.state())}, prefix="round", clock=clock)
            bar.update(1)
            bar.set_postfix(eval=f"{ev['mean']:.2f}", refresh=False)
    finally:
        writer.close()
        bar.close()
    clock.save(round=cfg.rounds)
    goal = {} if places is None else {"goal": places.chosen.tolist(), **places.state()}
    save_dt(model, run_dir, {**model_meta, **goal, "env_interactions": interactions, "finetune_rounds": cfg.rounds,
                             "finetune_gradient_steps": steps})
    write_done(run_dir, {
        "rounds": cfg.rounds, "env_interactions": interactions, "gradient_steps": steps,
        "zero_shot_eval": _evaluation(rows[0]),
        "final_eval": {**_evaluation(rows[-1]),
                       "episodes": cfg.eval_episodes, "seed": cfg.eval_seed},
        "target_return": float(target)})
    return run_dir
