"""The three tracks of the study, where each deploys, and the work of their stages (run as jobs by ``reproduce``).

Lives here: what distinguishes the tracks (:class:`Track`, the strong track's expert
recipe), where a track trains and is tested (:class:`Deployment`, :func:`deployments`), the
job entry points that a worker process runs for a stage (experts, dataset, pre-training,
fine-tuning, evaluation) and the evaluation of every policy of a track in one unseen
deployment. Not here: the pipeline and its stages (:mod:`.reproduce`), the report
(:mod:`.report`), the layouts (:mod:`uavris.layouts`).

- **paper**: the paper's study as published. The scenario experts are end-to-end DRL
  agents acting on all 22 action entries, of the algorithm that wins the Fig. 2
  comparison (Sec. IV-B: by the IQM of the final evaluations, or ``--expert-algo``); the DT
  imitates them.
- **strong**: the same study, with learning on the motion and attitude only and the
  per-slot phase optimiser setting the phases at every slot of training, collection,
  fine-tuning and evaluation (:mod:`uavris.env.wrappers`). The experts are PPO policies
  of the 6 motion entries, initialised by imitation of the planning oracle's motion in
  their own scenario (behaviour cloning with DAgger, :mod:`uavris.agents.experts.imitation`), then
  trained by PPO for the preset's RL budget. The DT is the paper's, trained offline on
  those experts' trajectories (motion actions) and deployed with optimised phases.
  Why this recipe: docs/study.md, "Strong track".
- **deployment**: the strong track's recipe over generated halls (docs/study.md, section
  21). Both tracks above vary only the UAV's start in the paper's hall, where every start
  has the same best pose; here each training and each unseen deployment is a layout of its
  own (:class:`uavris.layouts.LayoutGenerator`), the observation holds the devices as the
  UAV sees them (``SystemConfig.observe_devices``), and beside the DT stand every
  transferred expert (the nearest by :func:`uavris.layouts.layout_distance` named) and
  behaviour cloning on the same dataset with the same model and budget.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.experts.imitation import ImitationConfig
from uavris.config import (
    SCENARIOS,
    TRAINING_SCENARIOS,
    UNSEEN_SCENARIOS,
    DictConfig,
    Scenario,
    SystemConfig,
    scenario_at,
)
from uavris.experiments.training.train_expert import TrainConfig
from uavris.layouts import LayoutGenerator, layout_distance
from uavris.presets import STRONG_IMITATION, STRONG_RL_STEPS

TRANSFER_NEIGHBOURS = 2
# The attitude safety layer's margin in the deployment track's "safe" rows: every device at least
# this far in front of the RIS plane (SystemConfig.front_margin_deg; docs/study.md section 21).
SAFE_MARGIN_DEG = 1.0
SAFE = "-safe"  # the suffix of a row evaluated under the safety layer
LEVEL = "+level"  # the suffix of a policy kind whose attitude increments are replaced by zero
SEED_MARK = "@s"  # "dt-zero-shot@s1": the row's model of pre-training seed 1 (the report averages over seeds)
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
    pretrain: tuple[tuple[str, Any], ...] = ()  # PretrainConfig fields this track sets otherwise than the preset
    finetune: tuple[tuple[str, Any], ...] = ()  # FinetuneConfig fields this track sets otherwise than the preset
    demonstrations: bool = False  # the dataset: the planning oracle in generated halls, not trained experts
    seeded: bool = False  # every learned row over several pre-training seeds (ReproduceConfig.dt_seeds)
    ablation: bool = False  # an ablation on demand (--ablation): the data curve, the flat encoder, mixed-quality data
    front_margin_deg: float | None = None  # the DT rows also under the attitude safety layer with this margin

    def stage(self, name: str) -> str:
        return self.prefix + name


TRACK_SPECS: dict[str, Track] = {
    "paper": Track("paper", "", "agent", "paper track (end-to-end DRL experts, as published)"),
    # The strong and deployment tracks' DT reads 10 slots instead of the DT paper's 20: 1.7x
    # cheaper per step, and the zero-shot scores of the quick report stay within their CIs
    # (docs/study.md, section 22). The paper track keeps the DT paper's model.
    "strong": Track("strong", "strong-", "optimizer",
                    "strong track (learned motion, optimised phases; experts initialised from the oracle)",
                    pretrain=(("context", 10),)),
    "deployment": Track("deployment", "deploy-", "optimizer",
                        "deployment track (the oracle's demonstrations in many generated halls; unseen halls)",
                        layouts=True, unseen_experts=False, behaviour_cloning=True, demonstrations=True,
                        seeded=True, ablation=True, front_margin_deg=SAFE_MARGIN_DEG,
                        # 3e-4 instead of the DT paper's 1e-4: at the quick budget (1,500 steps) the DT
                        # fitted its 32 training layouts to 91% of the oracle with 1e-4 and to 98% with
                        # 3e-4. Width 64 and 2 blocks instead of 128 and 3: zero-shot within a point of
                        # the larger model on 512 halls, 3.3x cheaper to train (docs/study.md, section 21).
                        # The device-set encoder reads a hall as a set of devices (the ablation sets the
                        # flat one beside it).
                        pretrain=(("learning_rate", 3e-4), ("context", 10), ("width", 64), ("depth", 2),
                                  ("state_encoder", "devices")),
                        # Fine-tuning in each of the 16 unseen halls: 40 candidates (8 seeds x 5) and 25
                        # elites instead of 80 and 50, and 8 episodes for the per-round curve (the
                        # evaluation stage scores the result on the study's episodes): at 80/50 it added
                        # +0.3 points [-0.7, +1.4] over the zero-shot DT under the safety layer in the
                        # quick run of 2026-11-25, for a quarter of the study's time (docs/halls.md).
                        finetune=(("candidates", 40), ("elites", 25), ("eval_episodes", 8))),
}


@dataclass(frozen=True)
class Deployment(DictConfig):
    """Where a policy is trained or tested: a system (its devices) and a start, under a name."""

    name: str
    system: SystemConfig
    start: tuple[float, float, float] | None = None  # None: the named scenario's

    @property
    def scenario(self) -> Scenario:
        return scenario_at(self.name, self.start)


def deployments(track: Track, system: SystemConfig, train_layouts: int, unseen_layouts: int,
                layout_seed: int = 0, other_layouts: int = 0) -> tuple[list[Deployment], list[Deployment]]:
    """The training and the unseen deployments of ``track`` on ``system``: the paper's eight
    training and two unseen scenarios, or generated layouts (the devices observed), the unseen
    ones followed by ``other_layouts`` halls of another generator (the ``other`` split of
    :class:`uavris.layouts.LayoutGenerator`: a result tuned to the study's generator shows)."""
    if not track.layouts:
        return ([Deployment(s, system) for s in TRAINING_SCENARIOS], [Deployment(s, system) for s in UNSEEN_SCENARIOS])
    base = system.replace(observe_devices=True)
    gen = LayoutGenerator(devices=system.num_users, seed=layout_seed)

    def made(split: str, count: int) -> list[Deployment]:
        out = []
        for layout in gen.layouts(split, count, base):
            hall, where = layout.resolve(base)
            out.append(Deployment(layout.name, hall, where.start))
        return out

    return made("train", train_layouts), made("unseen", unseen_layouts) + made("other", other_layouts)


def is_other_hall(name: str) -> bool:
    """A hall of the other generator (evaluated zero-shot only: no fine-tuning there)."""
    return name.startswith("layout-other-")


def strong_expert_config(scenario: str, seed: int, preset: str, eval_episodes: int, system: SystemConfig,
                         start: tuple[float, float, float] | None = None) -> TrainConfig:
    """The strong track's expert of ``scenario`` (module docstring), starting at ``start`` (a layout's)
    when given."""
    return TrainConfig(algo="ppo", scenario=scenario, seed=seed, preset=preset, eval_episodes=eval_episodes,
                       system=system, start=start,
                         phase_control="optimizer", imitation=ImitationConfig(**STRONG_IMITATION[preset]),
                         total_steps=STRONG_RL_STEPS[preset])


def nearest_training_scenarios(scenario: str, k: int = TRANSFER_NEIGHBOURS) -> list[str]:
    """The ``k`` training scenarios whose start is closest to ``scenario``'s (ties by name)."""
    start = np.asarray(SCENARIOS[scenario].start)
    dist = {s: float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)) for s in TRAINING_SCENARIOS}
    return sorted(dist, key=lambda s: (round(dist[s], 9), s))[:k]


def transfer_sources(track: Track, unseen: Deployment, train: Sequence[Deployment]) -> list[tuple[str, float]]:
    """The training deployments whose experts are transferred to ``unseen``, nearest first, with
    their distance: the two nearest starts (paper and strong tracks, as the paper's Fig. 3),
    every training layout by :func:`uavris.layouts.layout_distance`, or, for demonstrations from
    many halls, the nearest training hall only (its oracle plan flown in ``unseen``)."""
    if not track.layouts:
        start = np.asarray(unseen.scenario.start)
        return [(s, float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)))
                for s in nearest_training_scenarios(unseen.name)]
    dist = sorted(((d.name, layout_distance(unseen.system.users, d.system.users)) for d in train),
                  key=lambda x: (round(x[1], 9), x[0]))
    return dist[:1] if track.demonstrations else dist


def evaluated_policies(track: Track, where: Deployment, sources: list[tuple[str, float]], dirs: dict[str, Path],
                       train: Sequence[Deployment] = (), ablation: bool = False) -> dict[str, tuple[str, str, str]]:
    """What a track's evaluation stage scores in ``where`` beside the references:
    ``{key: (label, kind, path)}`` (:func:`~.workers.evaluate_policies`); ``dirs`` holds the
    directories of the stages it reads (experts, pre-training stages by name,
    ``finetune-<where>``).

    With the track's safety margin the learned controller is the policy under the attitude
    safety layer: every zero-shot and fine-tuned DT and behaviour cloning (the DT's baseline,
    so it gets the same layer) is scored under it (key + :data:`SAFE`), and the oracle under it
    too (what the margin costs). The same policies without the layer, and every zero-shot DT
    with its attitude held level (``dt-level``), are the ``ablation``'s rows (what the layer
    adds, and the alternative of never tilting)."""
    policies = _learned_policies(track, where, sources, dirs, train)
    if track.front_margin_deg is None:
        return policies
    protected = {key: spec for key, spec in policies.items()
                 if key.split(SEED_MARK)[0] in ("dt-zero-shot", "dt-ensemble", "dt-finetuned", "bc")}
    safe = {_safe_key(key): (f"{label}, safety layer", kind, path) for key, (label, kind, path) in protected.items()}
    safe["oracle" + SAFE] = ("oracle (planning), safety layer", "oracle", "")
    if not ablation:
        return {key: spec for key, spec in policies.items() if key not in protected} | safe
    level = {key.replace("dt-zero-shot", "dt-level").replace("dt-ensemble", "dt-ensemble-level"):
             (f"{label}, attitude held level", kind + LEVEL, path) for key, (label, kind, path) in protected.items()
             if key.split(SEED_MARK)[0] in ("dt-zero-shot", "dt-ensemble")}
    return policies | safe | level


def _safe_key(key: str) -> str:
    """``dt-zero-shot@s1`` -> ``dt-zero-shot-safe@s1``: the seed mark stays last."""
    name, mark, seed = key.partition(SEED_MARK)
    return name + SAFE + mark + seed


def _learned_policies(track: Track, where: Deployment, sources: list[tuple[str, float]], dirs: dict[str, Path],
                      train: Sequence[Deployment]) -> dict[str, tuple[str, str, str]]:
    policies: dict[str, tuple[str, str, str]] = {}
    if track.unseen_experts:
        policies["expert"] = ("expert trained in the scenario", "expert",
                              str(dirs["experts-unseen"] / "runs" / where.name))
    if f"finetune-{where.name}" in dirs:
        policies["dt-finetuned"] = ("fine-tuned DT", "dt", str(dirs[f"finetune-{where.name}"] / "model"))
    for name, stage_dir in dirs.items():
        made = stage_policy(name)
        if made is not None:
            policies[made[0]] = (made[1], "dt", str(stage_dir / "model"))
    seeds = [str(dirs[k] / "model") for k in dirs
             if k == "pretrain" or (k.startswith("pretrain-s") and k[len("pretrain-s"):].isdigit())]
    if len(seeds) > 1:
        policies["dt-ensemble"] = (f"zero-shot DT, ensemble of the {len(seeds)} seeds' models (mean action)",
                                   "dt-ensemble", json.dumps(seeds))
    halls = {d.name: d for d in train}
    for rank, (src, dist) in enumerate(sources):
        near = " (nearest)" if track.layouts and rank == 0 else ""
        if track.demonstrations:
            policies[f"transfer-{src}"] = (f"oracle plan of {src}{near}, {dist:.1f} m", "plan",
                                           json.dumps(halls[src].to_dict()))
            continue
        label = f"transferred from {src}{near}" + (f", {dist:.1f} m" if track.layouts else "")
        policies[f"transfer-{src}"] = (label, "expert", str(dirs["experts-train"] / "runs" / src))
    return policies


def pretraining_stages(track: Track, schedule: dict[str, Any], train: Sequence[str], scaling: Sequence[int],
                       seeds: int, ablation: bool = False) -> dict[str, tuple[str, dict[str, Any]]]:
    """The pre-training stages of ``track``: ``{stage: (dataset stage, PretrainConfig overrides)}``.

    Every track: the DT (``pretrain``). With behaviour cloning: ``bc``, the same model without
    return conditioning. With ``ablation``, where the track has one: over layouts, the DT on
    the first ``n`` training halls for each ``n`` of ``scaling`` (``pretrain-nN``, the data
    curve), the flat encoder on the same data (``flat``), and the DT and BC on the
    mixed-quality dataset (``mixed-dt``, ``mixed-bc``). Every row for ``seeds`` pre-training
    seeds (``-sK``, K >= 1, beside seed 0's unsuffixed stage). ``schedule`` is the track's
    PretrainConfig overrides; ``seed`` in the overrides is added to the study's seed.
    """
    base = dict(schedule)
    rows: dict[str, tuple[str, dict[str, Any]]] = {"pretrain": ("dataset", base)}
    if track.behaviour_cloning:
        rows["bc"] = ("dataset", {**base, "condition_on_return": False})
    if ablation and track.ablation:
        if track.layouts:
            rows.update({f"pretrain-n{n}": ("dataset", {**base, "scenarios": tuple(train[:n])}) for n in scaling})
        rows["flat"] = ("dataset", {**base, "state_encoder": "flat"})
        rows["mixed-dt"] = ("dataset-mixed", base)
        rows["mixed-bc"] = ("dataset-mixed", {**base, "condition_on_return": False})
    if seeds <= 1:
        return rows
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    for name, (data, overrides) in rows.items():
        out.update({name if k == 0 else f"{name}-s{k}": (data, {**overrides, "seed": k}) for k in range(seeds)})
    return out


POLICY_OF_STAGE = {"pretrain": ("dt-zero-shot", "zero-shot DT"),
                   "bc": ("bc", "behaviour cloning (the DT without return conditioning)"),
                   "flat": ("dt-flat", "zero-shot DT, flat encoder"),
                   "mixed-dt": ("dt-mixed", "zero-shot DT, mixed-quality data"),
                   "mixed-bc": ("bc-mixed", "behaviour cloning, mixed-quality data")}


def stage_policy(stage: str) -> tuple[str, str] | None:
    """The evaluation key and label of the model a pre-training stage makes (None for any other
    stage): ``pretrain`` is ``dt-zero-shot``, ``pretrain-n8`` ``dt-zero-shot-n8``, a seed's copy
    ``-sK`` gets ``@sK`` (the report averages a row over its seeds)."""
    name, seed = stage, ""
    if "-s" in stage and stage.rsplit("-s", 1)[1].isdigit():
        name, k = stage.rsplit("-s", 1)
        seed = f"{SEED_MARK}{k}"
    if name.startswith("pretrain-n") and name[len("pretrain-n"):].isdigit():
        n = name[len("pretrain-n"):]
        key, label = f"dt-zero-shot-n{n}", f"zero-shot DT, {n} training layout{'s' * (n != '1')}"
    elif name in POLICY_OF_STAGE:
        key, label = POLICY_OF_STAGE[name]
    else:
        return None
    return key + seed, label + (f", seed {seed[2:]}" if seed else "")
