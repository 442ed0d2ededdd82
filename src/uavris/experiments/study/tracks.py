"""The three tracks of the study: where each trains and is tested, what it trains, the rows that judge it.

Lives here: :class:`Track` and :data:`TRACK_SPECS`; where a track trains and is tested
(:func:`sites`, a :class:`uavris.layouts.Site` each) and whose experts are transferred
(:func:`transfer_sources`); the strong track's expert recipe (:func:`strong_expert_config`);
the models a track pre-trains (:class:`TrainedModel`, :func:`trained_models`) and the rows
of its evaluation (:func:`track_rows`, each a :class:`uavris.experiments.tools.rows.Row`):
adding a row to the study is an edit of :func:`track_rows`. Not here: the pipeline's stages
(:mod:`.pipeline`) and their names (:mod:`.stage_names`), the job entry points a worker runs for
them (:mod:`.workers`), the report (:mod:`.report`), the layouts (:mod:`uavris.layouts`).

- **paper**: the paper's study as published. The scenario experts are end-to-end DRL
  agents acting on all 22 action entries, of the algorithm that wins the Fig. 2
  comparison (Sec. IV-B: by the IQM of the final evaluations, or ``--expert-algo``); the DT
  imitates them.
- **strong**: the same study, with learning on the motion and attitude only and the
  per-slot phase optimiser setting the phases at every slot of training, collection,
  fine-tuning and evaluation (:mod:`uavris.env.wrappers`). The experts are imitations of
  the planning oracle's motion in their own scenario (behaviour cloning with DAgger,
  :mod:`uavris.agents.experts.imitation`) in SB3's PPO network of the 6 motion entries; no
  RL runs after the imitation (PPO after it lost ground). The DT is the paper's, trained offline on
  those experts' trajectories (motion actions) and deployed with optimised phases.
  Why this recipe: docs/study.md, "Strong track".
- **deployment**: the strong track's recipe over generated halls (docs/study.md, section
  2). Both tracks above vary only the UAV's start in the paper's hall, where every start
  has the same best pose; here each training and each unseen deployment is a layout of its
  own (:class:`uavris.layouts.LayoutGenerator`), the observation holds the devices as the
  UAV sees them (``SystemConfig.observe_devices``), and beside the DT stand every
  transferred expert (the nearest by :func:`uavris.layouts.layout_distance` named) and
  behaviour cloning on the same dataset with the same model and budget.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.experts.imitation import ImitationConfig
from uavris.agents.oracle.planner import SAFE_MARGIN_DEG
from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
from uavris.config import SCENARIOS, TRAINING_SCENARIOS, UNSEEN_SCENARIOS, Scenario, SystemConfig, get_scenario
from uavris.experiments.study.stage_names import (
    DATASET,
    DATASET_BEST,
    DATASET_MIXED,
    EXPERTS_TRAIN,
    EXPERTS_UNSEEN,
    PRETRAIN,
    finetune_stage,
    places_stage,
    value_stage,
)
from uavris.experiments.tools.rows import Row
from uavris.experiments.tools.targets import DTModel, ExpertRun, LearnedValue
from uavris.experiments.training.train_expert import TrainConfig
from uavris.layouts import LayoutGenerator, Site, layout_distance
from uavris.presets import STRONG_IMITATION

TRANSFER_NEIGHBOURS = 2
REFERENCE_ROWS = (ZERO_ACTION, HOVER_OPTIMIZER, ORACLE)  # every evaluation stage scores them beside its rows
TRACKS: tuple[str, ...] = ("paper", "strong", "deployment")


@dataclass(frozen=True)
class Track:
    """One track of the study: its stage-name prefix, who sets the phases, and where it deploys."""

    name: str
    prefix: str
    phase_control: str
    title: str
    layouts: bool = False  # generated halls (the deployment track) instead of the paper's scenarios
    unseen_experts: bool = True  # an expert trained in each unseen deployment, beside the DT
    behaviour_cloning: bool = False  # BC on the same dataset with the DT's model and budget, beside the DT
    demonstrations: bool = False  # the dataset: the planning oracle in generated halls, not trained experts
    seeded: bool = False  # every learned row over several pre-training seeds (ReproduceConfig.dt_seeds)
    ablation: bool = False  # an ablation on demand (--ablation): the data curve, the flat encoder, mixed-quality data
    front_margin_deg: float | None = None  # the DT rows also under the attitude safety layer with this margin
    places: bool = False  # a learned value of a pose, a DT told its place, fine-tuning by places (docs/places.md)

    def stage(self, name: str) -> str:
        return self.prefix + name


TRACK_SPECS: dict[str, Track] = {  # each track's DT and fine-tuning: uavris.presets.TRACK_PRETRAIN, TRACK_FINETUNE
    # every track has behaviour cloning on its own data beside its DT (the offline baseline a reader asks for)
    "paper": Track("paper", "", "agent", "paper track (end-to-end DRL experts, as published)",
                   behaviour_cloning=True),
    "strong": Track("strong", "strong-", "optimizer",
                    "strong track (learned motion, optimised phases; experts initialised from the oracle)",
                    behaviour_cloning=True),
    "deployment": Track("deployment", "deploy-", "optimizer",
                        "deployment track (the oracle's demonstrations in many generated halls; unseen halls)",
                        layouts=True, unseen_experts=False, behaviour_cloning=True, demonstrations=True,
                        seeded=True, ablation=True, front_margin_deg=SAFE_MARGIN_DEG, places=True),
}


def sites(track: Track, system: SystemConfig, train_layouts: int, unseen_layouts: int,
          layout_seed: int = 0, other_layouts: int = 0, device_counts: Sequence[int] = (),
          count_other_layouts: int = 0) -> tuple[list[Site], list[Site]]:
    """The training and the unseen sites of ``track`` on ``system``: the paper's eight
    training and two unseen scenarios, or generated layouts (the devices observed), the unseen
    ones followed by ``other_layouts`` halls of another generator (the ``other`` split of
    :class:`uavris.layouts.LayoutGenerator`: a result tuned to the study's generator shows)
    and by ``unseen_layouts`` unseen halls of each of ``device_counts`` devices (named
    ``layout-unseen-J-kK``), each count's followed by ``count_other_layouts`` of the other
    generator (``layout-other-J-kK``)."""
    if not track.layouts:
        return [Site(s, system) for s in TRAINING_SCENARIOS], [Site(s, system) for s in UNSEEN_SCENARIOS]
    base = system.replace(observe_devices=True)

    def made(split: str, count: int, devices: int = system.num_users) -> list[Site]:
        gen = LayoutGenerator(devices=devices, seed=layout_seed)
        return [Site.of(layout, base) for layout in gen.layouts(split, count, base)]

    counts = [made("unseen", unseen_layouts, k) + made("other", count_other_layouts, k)
              for k in device_counts if k != system.num_users]
    return made("train", train_layouts), made("unseen", unseen_layouts) + made("other", other_layouts) + sum(counts, [])


def zero_shot_only(site: Site, system: SystemConfig) -> bool:
    """A hall a study on ``system`` evaluates zero-shot only (no fine-tuning there): one of the
    other generator's, or one of another device count than the study's."""
    return site.split == "other" or site.devices != system.num_users


def strong_expert_config(scenario: str, seed: int, preset: str, eval_episodes: int, system: SystemConfig,
                         start: tuple[float, float, float] | None = None, curve: bool = False) -> TrainConfig:
    """The strong track's expert of ``scenario`` (module docstring), starting at ``start`` (a layout's)
    when given: DAgger imitation of the planning oracle's motion into SB3's PPO network
    (``algo="ppo"`` names the network), and no RL steps after it (``total_steps=0``); with
    ``curve``, evaluated after every round (an unseen scenario's expert, whose learning curve
    "fewer interactions" reads: its first crossing, not its whole budget)."""
    return TrainConfig(algo="ppo", scenario=scenario, seed=seed, preset=preset, eval_episodes=eval_episodes,
                       system=system, start=start, phase_control="optimizer",
                       imitation=ImitationConfig(**STRONG_IMITATION[preset], evaluate_rounds=curve), total_steps=0)


def nearest_training_scenarios(scenario: str | Scenario, k: int = TRANSFER_NEIGHBOURS) -> list[str]:
    """The ``k`` training scenarios whose start is closest to ``scenario``'s (ties by name)."""
    start = np.asarray(get_scenario(scenario).start)
    dist = {s: float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)) for s in TRAINING_SCENARIOS}
    return sorted(dist, key=lambda s: (round(dist[s], 9), s))[:k]


def transfer_sources(track: Track, unseen: Site, train: Sequence[Site]) -> list[tuple[str, float]]:
    """The training deployments whose experts are transferred to ``unseen``, nearest first, with
    their distance: the two nearest starts (paper and strong tracks, as the paper's Fig. 3),
    every training layout by :func:`uavris.layouts.layout_distance`, or, for demonstrations from
    many halls, the nearest training hall only (its oracle plan flown in ``unseen``)."""
    if not track.layouts:
        start = np.asarray(unseen.scenario.start)
        return [(s, float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)))
                for s in nearest_training_scenarios(unseen.scenario)]
    dist = sorted(((d.name, layout_distance(unseen.system.users, d.system.users)) for d in train),
                  key=lambda x: (round(x[1], 9), x[0]))
    dist = [(name, d) for name, d in dist if math.isfinite(d)]  # no hall of another device count is "nearest"
    return dist[:1] if track.demonstrations else dist


def track_rows(track: Track, site: Site, sources: list[tuple[str, float]], dirs: dict[str, Path],
               models: Sequence[TrainedModel], train: Sequence[Site] = (), ablation: bool = False) -> list[Row]:
    """Every row a track's evaluation stage scores in ``site``, in the report's order: its learned
    rows, then the references (the zero action, hovering with the optimiser's phases, the oracle).

    ``dirs`` holds the directories of the stages the rows read (experts, the pre-training
    stages of ``models``, ``finetune-<site>`` where the track fine-tuned there); ``sources``
    are the training sites transferred from (:func:`transfer_sources`). With the track's
    safety margin the learned controller is the policy under the attitude safety layer: every
    zero-shot and fine-tuned DT and behaviour cloning (the DT's baseline, so it gets the same
    layer) is scored under it, and the oracle under it too (the oracle keeps the same margin in
    its plan and flight: the two oracle rows differ only by the layer's second cut). The same
    policies without the layer, and every zero-shot DT with its attitude held level, are the
    ``ablation``'s rows (what the layer adds, and the alternative of never tilting)."""
    learned = _learned_rows(track, site, sources, dirs, models, train)
    rows = [r for r, _ in learned]
    margin = track.front_margin_deg
    if margin is not None:
        protected = [r for r, deployed in learned if deployed]
        safe = [r.replace(front_margin_deg=margin) for r in (*protected, Row.reference(ORACLE))]
        if ablation:
            rows = rows + safe + [r.replace(level=True) for r in protected if r.name in ("dt-zero-shot", "dt-ensemble")]
        else:
            rows = [r for r in rows if r not in protected] + safe
    return rows + [Row.reference(name) for name in REFERENCE_ROWS]


def _learned_rows(track: Track, site: Site, sources: list[tuple[str, float]], dirs: dict[str, Path],
                  models: Sequence[TrainedModel], train: Sequence[Site]) -> list[tuple[Row, bool]]:
    """The rows before the references, each with whether it is a learned controller the track
    deploys (under the safety layer where the track has one): the DT, behaviour cloning, their
    fine-tuning and ensemble, not the ablation's models nor a learned place flown by the oracle."""
    rows: list[tuple[Row, bool]] = []
    if track.unseen_experts:
        rows.append((Row("expert", "expert trained in the scenario",
                         ExpertRun.at(dirs[EXPERTS_UNSEEN] / "runs" / site.name), kind="expert"), False))
    if finetune_stage(site.name) in dirs:
        rows.append((Row("dt-finetuned", "fine-tuned DT", DTModel.at(dirs[finetune_stage(site.name)] / "model")),
                     True))
    seeded = len({m.seed for m in models}) > 1
    # one learned value per pre-training seed, so that the seeds are independent units (each its own fit of V)
    values = {s: LearnedValue.at(dirs[value_stage(s)] / "value")
              for s in sorted({m.seed for m in models}) if value_stage(s) in dirs}
    if train and site.devices != train[0].devices:  # a flat encoder's weights read its training halls' count only
        models = [m for m in models if dict(m.model).get("state_encoder") != "flat"]
    # the headline controller is told the deployed place (V proposes, R disposes: its places valued by R and
    # refined, staying always a candidate, the oracle's margin; docs/places.md), by its own seed's V
    deployed = {s: dataclasses.replace(v, deployed=True) for s, v in values.items()}
    for m in models:
        goal = {"goal_from": deployed[m.seed]} if m.row in ("dt-goal", "dt-goal-mlp") else {}
        rows.append((Row(m.row, m.label, DTModel.at(dirs[m.stage] / "model"), seed=m.seed if seeded else None,
                         training_halls=m.halls, **goal), not m.ablation))
    for m in models:  # fine-tuned by trying places in this hall: it keeps the place it chose
        stage = places_stage(site.name, m.seed)
        if m.row == "dt-goal" and stage in dirs:
            rows.append((Row("dt-goal-finetuned", "goal-conditioned DT, fine-tuned by trying places",
                             DTModel.at(dirs[stage] / "model"), seed=m.seed if seeded else None), True))
    for s, value in values.items():
        seed = s if seeded else None
        rows += [(Row("plan-learned", "learned planner's place (V's argmax), flown by the oracle's controller",
                      value, seed=seed), False),
                 (Row("plan-deployed", "the deployed place (V proposes, R disposes), flown by the oracle's "
                      "controller", deployed[s], seed=seed), False)]
    dts = [DTModel.at(dirs[m.stage] / "model") for m in models if m.row == "dt-zero-shot"]
    if len(dts) > 1:
        rows.append((Row("dt-ensemble", f"zero-shot DT, ensemble of the {len(dts)} seeds' models (mean action)",
                         members=tuple(dts)), True))
    halls = {d.name: d for d in train}
    for rank, (src, dist) in enumerate(sources):
        near = " (nearest)" if track.layouts and rank == 0 else ""
        if track.demonstrations:
            rows.append((Row(f"transfer-{src}", f"oracle plan of {src}{near}, {dist:.1f} m", plan_of=halls[src],
                             kind="transfer", rank=rank), False))
            continue
        label = f"transferred from {src}{near}" + (f", {dist:.1f} m" if track.layouts else "")
        rows.append((Row(f"transfer-{src}", label, ExpertRun.at(dirs[EXPERTS_TRAIN] / "runs" / src),
                         kind="transfer", rank=rank), False))
    return rows


@dataclass(frozen=True)
class TrainedModel:
    """A model a track pre-trains: its stage, the dataset stage it reads, the PretrainConfig
    fields (``fields``) and model fields (``model``, DTConfig's) it sets beside the track's, its
    pre-training seed (added to the study's) and the row it becomes (:func:`track_rows`)."""

    stage: str  # "pretrain", "bc-s1", "pretrain-n32-s2", "mixed-dt"
    dataset: str  # the dataset stage it reads: DATASET, DATASET_BEST or DATASET_MIXED (.stage_names)
    fields: tuple[tuple[str, Any], ...]
    model: tuple[tuple[str, Any], ...]
    row: str  # "dt-zero-shot", "bc", "dt-zero-shot-n32", ...
    label: str
    seed: int = 0
    ablation: bool = False  # one of the ablation's models (not deployed: no safety-layer row of its own)
    halls: int | None = None  # a model of the data curve: the training halls it saw

    def pretrain_fields(self, track_fields: dict[str, Any]) -> dict[str, Any]:
        """The PretrainConfig fields of this model on top of its track's (:data:`uavris.presets.TRACK_PRETRAIN`)."""
        return {**track_fields, **dict(self.fields), "model": {**track_fields.get("model", {}), **dict(self.model)}}


def trained_models(track: Track, train: Sequence[str], scaling: Sequence[int], seeds: int,
                   ablation: bool = False) -> list[TrainedModel]:
    """The models ``track`` pre-trains, each for ``seeds`` pre-training seeds (seed 0's stage
    unsuffixed, seed K's ``-sK``).

    Every track: the DT (``pretrain``). With behaviour cloning: ``bc``, the same model without
    return conditioning. A track that chooses places: the goal-conditioned DT (``goal``) and the
    field's baselines beside it, a goal-conditioned MLP (``goal-mlp``: a window of one slot, no
    attention over time) and filtered behaviour cloning (``bc-best``, on ``dataset-best``). With
    ``ablation``, where the track has one: over layouts, the DT on
    the first ``n`` training halls for each ``n`` of ``scaling`` (``pretrain-nN``, the data
    curve), the flat encoder on the same data (``flat``), and the DT and BC on the
    mixed-quality dataset (``mixed-dt``, ``mixed-bc``).
    """
    bc = (("condition_on_return", False),)
    kinds = [TrainedModel(PRETRAIN, DATASET, (), (), "dt-zero-shot", "zero-shot DT")]
    if track.behaviour_cloning:
        kinds.append(TrainedModel("bc", DATASET, (), bc, "bc", "behaviour cloning (the DT without return "
                                  "conditioning)"))
    if track.places:  # told a goal rather than a return: each demonstration's own plan target in training
        goal = (("goal", True), ("condition_on_return", False))
        kinds += [TrainedModel("goal", DATASET, (), goal, "dt-goal",
                               "goal-conditioned DT, told the deployed place (V proposes, R disposes)"),
                  # the field's baselines beside it: the same goal and inputs with no attention over time (a window of
                  # one slot), and behaviour cloning on the best tenth of the demonstrations by return
                  TrainedModel("goal-mlp", DATASET, (), (*goal, ("context", 1)), "dt-goal-mlp",
                               "goal-conditioned MLP (no attention over time), told the deployed place"),
                  TrainedModel("bc-best", DATASET_BEST, (), bc, "bc-best",
                               "filtered behaviour cloning (the best 10% of the demonstrations by return)")]
    if ablation and track.ablation:
        if track.layouts:
            kinds += [TrainedModel(f"{PRETRAIN}-n{n}", DATASET, (("scenarios", tuple(train[:n])),), (),
                                   f"dt-zero-shot-n{n}", f"zero-shot DT, {n} training layout{'s' * (n != 1)}",
                                   ablation=True, halls=n) for n in scaling]
        kinds += [TrainedModel("flat", DATASET, (), (("state_encoder", "flat"),), "dt-flat",
                               "zero-shot DT, flat encoder", ablation=True),
                  TrainedModel("mixed-dt", DATASET_MIXED, (), (), "dt-mixed", "zero-shot DT, mixed-quality data",
                               ablation=True),
                  TrainedModel("mixed-bc", DATASET_MIXED, (), bc, "bc-mixed", "behaviour cloning, mixed-quality data",
                               ablation=True)]
    return [dataclasses.replace(m, stage=m.stage if k == 0 else f"{m.stage}-s{k}", seed=k)
            for m in kinds for k in range(max(1, seeds))]
