"""Every preset table and every seed base, in one place.

Lives here: :data:`PRESETS`, :func:`check_preset` and the budgets of the ``smoke``
(seconds, for tests), ``quick`` (the laptop study) and ``paper`` (sized like the paper)
presets, one table per config class: expert training (:data:`TRAIN`), the DT's pre-training
and fine-tuning (:data:`PRETRAIN`, :data:`FINETUNE`), the study (:data:`STUDY`), and the
strong track's experts; and the seed bases (:data:`EVAL_SEED`, ...) that keep evaluation,
collection, fine-tuning and imitation episodes apart; how a preset acts on a config
(:data:`PRESET`, :func:`fill_from_preset`, :class:`PresetConfig`). Not here: what the numbers
mean and why (the module that uses a table explains its values) and the experts'
hyperparameters, kept with their reasons in :mod:`uavris.agents.experts.hyperparams`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping, get_args

from uavris.config import DictConfig
from uavris.errors import ConfigError
from uavris.io import INTERNAL

Preset = Literal["smoke", "quick", "paper"]  # what --preset accepts
PRESETS: tuple[str, ...] = get_args(Preset)

# Seed bases: episode j of a kind uses BASE + j, so the kinds never share an episode.
EVAL_SEED = 1_000_000  # evaluation episodes: every policy of a report is scored on these
COLLECT_SEED = 2_000_000  # expert trajectories for the DT's dataset
FINETUNE_SEED = 3_000_000  # the DT's fine-tuning candidates
IMITATION_SEED = 4_000_000  # the strong experts' imitation rollouts
VALUE_SEED = 5_000_000  # the learned value's labelled poses and their draws

# A table per config class, each complete: a config built with ``preset=NAME`` takes every
# field of ``TABLE[NAME]`` that it is not given (PRESET, below, marks those fields), in
# Python as on the command line.

# Expert training (uavris.experiments.training.train_expert.TrainConfig): env steps, the
# periodic evaluation (interval, episodes) and the checkpoint interval. smoke exercises the
# code; quick is 500 episodes per run; paper matches the paper's ~25,000 training episodes.
# The hyperparameters: uavris.agents.experts.hyperparams.
TRAIN: dict[str, dict[str, Any]] = {
    "smoke": dict(total_steps=640, eval_every=320, eval_episodes=8, checkpoint_every=320),
    "quick": dict(total_steps=50_000, eval_every=10_000, eval_episodes=32, checkpoint_every=10_000),
    "paper": dict(total_steps=2_500_000, eval_every=50_000, eval_episodes=100, checkpoint_every=50_000),
}

# DT pre-training (uavris.experiments.training.pretrain.PretrainConfig): smoke exercises the
# code in a second; quick is a few minutes on one core with the DT paper's model size; paper
# is the DT paper's training schedule.
# ``model``: the DTConfig fields of the model (the rest are DTConfig's defaults, the DT paper's).
_DT_PAPER_MODEL = dict(context=20, width=128, depth=3, heads=1)
PRETRAIN: dict[str, dict[str, Any]] = {
    "smoke": dict(steps=20, batch_size=8, warmup_steps=5, checkpoint_every=10, log_every=5, learning_rate=1e-3,
                  model=dict(context=4, width=16, depth=1, heads=1)),
    "quick": dict(steps=1500, batch_size=64, warmup_steps=150, checkpoint_every=500, log_every=50,
                  learning_rate=1e-4, model=_DT_PAPER_MODEL),
    "paper": dict(steps=100_000, batch_size=64, warmup_steps=10_000, checkpoint_every=5_000, log_every=200,
                  learning_rate=1e-4, model=_DT_PAPER_MODEL),
}

# DT fine-tuning (Algorithm 1, stage 2; uavris.experiments.training.finetune.FinetuneConfig).
_FT_PAPER = dict(candidates=80, elites=50, rollouts_per_seed=5, batch_size=64, warmup_steps=100)
FINETUNE: dict[str, dict[str, Any]] = {
    "smoke": dict(rounds=1, candidates=4, elites=2, rollouts_per_seed=2, epochs_per_round=1, batch_size=8,
                  warmup_steps=2, eval_episodes=2),
    "quick": dict(rounds=3, epochs_per_round=2, eval_episodes=16, **_FT_PAPER),
    "paper": dict(rounds=10, epochs_per_round=5, eval_episodes=100, **_FT_PAPER),
}

# The learned value of a pose (uavris.agents.place, docs/places.md): the labels (training halls per
# device count, labelled poses per hall; uavris.experiments.training.values.ValueLabelsConfig)
# and the fit (ValueFitConfig: the network's width and its gradient steps).
VALUE: dict[str, dict[str, Any]] = {
    "smoke": dict(counts=(3, 4), halls=2, poses=9, width=16, steps=40),
    "quick": dict(counts=(3, 4, 5, 6, 7, 8), halls=32, poses=48, width=64, steps=6000),
    "paper": dict(counts=(3, 4, 5, 6, 7, 8), halls=256, poses=96, width=128, steps=20_000),
}
# Fine-tuning that tries places (a goal-conditioned DT, docs/places.md): the start and this many of
# the learned planner's best places, one per candidate episode (rollouts_per_seed a multiple
# of places + 1: each episode seed tries every place; the track's fine-tuning table otherwise).
PLACES_FINETUNE: dict[str, dict[str, Any]] = {
    "smoke": dict(places=1),
    "quick": dict(places=4),
    "paper": dict(places=4),
}

# The strong track's experts: imitation of the oracle's motion (DAgger rounds, episodes per
# round, epochs), nothing else: no RL steps after it at any preset, since PPO after imitation
# lost ground and did not pass it (docs/study.md, "Strong track"). The policy network is
# SB3's PPO actor-critic, trained by behaviour cloning only.
STRONG_IMITATION: dict[str, dict[str, Any]] = {
    "smoke": dict(rounds=2, episodes=4, epochs=5),
    "quick": dict(rounds=6, episodes=32, epochs=30),
    "paper": dict(rounds=8, episodes=64, epochs=30),
}

# The study (``uavris reproduce``, uavris.experiments.study.config.ReproduceConfig):
# evaluation episodes per policy, comparison seeds per algorithm and environment steps per run,
# expert trajectories per training scenario (the paper: 500). quick: 3 seeds and 25,000 steps
# (250 episodes), because at 50,000 steps the comparison took 31 of the study's 86 core-minutes
# (the study's time on 2 cores: docs/timings.md). Its
# curves still rise at 25,000 steps (PPO crosses the zero action between 100,000 and 400,000:
# docs/results/budget.md), so the quick comparison's verdicts hold at that budget only; paper
# keeps 5 seeds and the paper's ~25,000 episodes.
# The deployment track (docs/study.md section 2): generated training halls with the planning
# oracle's demonstrations (episodes per hall: layout_trajectories), unseen halls, the smaller
# training sets of the data curve (zero-shot score against the number of training halls; the
# full set is its last point), pre-training seeds of every learned row, and the halls of the
# mixed-quality dataset (the oracle, another hall's plan, hovering, a noisy oracle: where
# return conditioning can matter). quick: 512 halls x 2 episodes, about as many episodes as
# the paper track's dataset (8 scenarios x 100), spread over many halls (docs/study.md
# section 2 measures the split).
STUDY: dict[str, dict[str, Any]] = {
    "smoke": dict(compare_seeds=2, compare_steps=640, eval_episodes=8, trajectories=4, layout_trajectories=2,
                  train_layouts=3, unseen_layouts=2, scaling=(1,), dt_seeds=2, mixed_layouts=2),
    "quick": dict(compare_seeds=3, compare_steps=25_000, eval_episodes=32, trajectories=100, layout_trajectories=2,
                  train_layouts=512, unseen_layouts=16, scaling=(32, 128), dt_seeds=3, mixed_layouts=64),
    "paper": dict(compare_seeds=5, compare_steps=2_500_000, eval_episodes=100, trajectories=500,
                  layout_trajectories=2, train_layouts=4096, unseen_layouts=32, scaling=(32, 128, 512, 1024, 2048),
                  dt_seeds=3, mixed_layouts=1024),
}
DEMONSTRATION_CHUNK = 64  # halls per demonstration job (a job writes its part of the dataset)

# The study's tracks (uavris.experiments.study.tracks): what each track's DT pre-trains and
# fine-tunes with beside the preset's PRETRAIN and FINETUNE rows, per preset. This is the one
# place a track's model and schedule are set (``model``: the DTConfig fields that differ from
# the preset's model; the smoke preset keeps its tiny model in every track).
# - strong and deployment: the DT reads 10 slots instead of the DT paper's 20: 1.7x cheaper
#   per step, and the zero-shot scores of the quick report stay within their CIs (docs/study.md,
#   section 3). The paper track keeps the DT paper's model.
# - deployment: learning rate 3e-4 instead of the DT paper's 1e-4: at the quick budget (1,500
#   steps) the DT fitted its 32 training layouts to 91% of the oracle with 1e-4 and to 98% with
#   3e-4. Width 64 and 2 blocks instead of 128 and 3: zero-shot within a point of the larger
#   model on 512 halls, 3.3x cheaper to train (docs/study.md, section 2). The device-set
#   encoder reads a hall as a set of devices (the ablation sets the flat one beside it).
# - deployment fine-tuning, in each of the 16 unseen halls: 40 candidates (8 seeds x 5) and 25
#   elites instead of 80 and 50, and 8 episodes for the per-round curve (the evaluation stage
#   scores the result on the study's episodes): at 80/50 it added +0.3 points [-0.7, +1.4] over
#   the zero-shot DT under the safety layer in a quick run, for a quarter of the study's time
#   (docs/halls.md). The other tracks' fine-tuning evaluates on the study's episodes.
_SHORT_CONTEXT = dict(model=dict(context=10))
_DEPLOYMENT_DT = dict(learning_rate=3e-4, model=dict(context=10, width=64, depth=2, state_encoder="devices"))
TRACK_PRETRAIN: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {"smoke": {}, "quick": {}, "paper": {}},
    "strong": {"smoke": {}, "quick": _SHORT_CONTEXT, "paper": _SHORT_CONTEXT},
    "deployment": {"smoke": dict(learning_rate=3e-4, model=dict(state_encoder="devices")), "quick": _DEPLOYMENT_DT,
                   "paper": _DEPLOYMENT_DT},
}
_DEPLOYMENT_FT = dict(candidates=40, elites=25, eval_episodes=8)
TRACK_FINETUNE: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {"smoke": {}, "quick": {}, "paper": {}},
    "strong": {"smoke": {}, "quick": {}, "paper": {}},
    "deployment": {"smoke": _DEPLOYMENT_FT, "quick": _DEPLOYMENT_FT, "paper": _DEPLOYMENT_FT},
}


def check_preset(preset: str) -> None:
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")


# ------------------------------------------------------------------ how a preset acts on a config
class _PresetValue:
    """The default of a field whose value comes from the config's preset (:data:`PRESET`)."""

    def __repr__(self) -> str:
        return "<the preset's>"


PRESET: Any = _PresetValue()


def fill_from_preset(cfg: PresetConfig, table: Mapping[str, Any]) -> None:
    """Give every field of the frozen config ``cfg`` still at :data:`PRESET` the preset table's
    value (a :mod:`uavris.presets` table's row): the one way a preset acts, so that
    ``PretrainConfig(dataset, preset="paper")`` is the paper preset's run, in Python as on the
    command line. A field still at the value an earlier preset gave it (``dataclasses.replace(cfg,
    preset="paper")``, or ``algo=`` where the algorithm's hyperparameters are the preset's) takes
    this table's too. Call it first in ``__post_init__``, before validation."""
    earlier = dict(cfg._from_preset)  # what the preset gave the config a dataclasses.replace copied
    given = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        # the very object the preset gave (dataclasses.replace copies it), not a value given equal to it
        if value is PRESET or (f.name in earlier and value is earlier[f.name]):
            if f.name not in table:
                raise ConfigError(f"{type(cfg).__name__}.{f.name} has no value in the preset's table")
            object.__setattr__(cfg, f.name, table[f.name])
            given[f.name] = table[f.name]
    object.__setattr__(cfg, "_from_preset", tuple(given.items()))


@dataclass(frozen=True)
class PresetConfig(DictConfig):
    """A config with a preset (:func:`fill_from_preset`): it keeps the values its preset gave, for
    a replace that changes the preset to give the new one's. Kept in memory only: a config read
    back from its dict (a run's config.yaml) holds none, and a replace keeps its values. A value
    given that is the very object the preset gave (a small integer, say 64 where the preset's is
    64) is read as the preset's."""

    # (name, value) pairs; a plain tuple, so that its type reads in every subclass's module
    _from_preset: tuple = field(default=(), kw_only=True, repr=False, compare=False, metadata={INTERNAL: True})
