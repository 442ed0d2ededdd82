"""The two tracks of the study and the work of their stages (run as jobs by ``reproduce``).

Lives here: what distinguishes the tracks (:class:`Track`, the strong track's expert
recipe), the job entry points that a worker process runs for a stage (experts, dataset,
pre-training, fine-tuning, evaluation) and the per-scenario evaluation of every policy of
a track. Not here: the pipeline and its stages (:mod:`.reproduce`), the report
(:mod:`.report`).

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
  Why this recipe: docs/model.md, "Strong track".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uavris.agents.experts.imitation import ImitationConfig
from uavris.config import SCENARIOS, TRAINING_SCENARIOS, SystemConfig, get_scenario
from uavris.experiments.train_expert import TrainConfig, preset_config
from uavris.presets import EVAL_SEED, STRONG_IMITATION, STRONG_RL_STEPS
from uavris.runs import read_done

TRANSFER_NEIGHBOURS = 2
TRACKS: tuple[str, ...] = ("paper", "strong")


@dataclass(frozen=True)
class Track:
    """One track of the study: its stage-name prefix and who sets the phases."""

    name: str
    prefix: str
    phase_control: str
    title: str

    def stage(self, name: str) -> str:
        return self.prefix + name


TRACK_SPECS: dict[str, Track] = {
    "paper": Track("paper", "", "agent", "paper track (end-to-end DRL experts, as published)"),
    "strong": Track("strong", "strong-", "optimizer",
                    "strong track (learned motion, optimised phases; experts initialised from the oracle)"),
}


def strong_expert_config(scenario: str, seed: int, preset: str, eval_episodes: int, system: SystemConfig
                         ) -> TrainConfig:
    """The strong track's expert of ``scenario`` (module docstring)."""
    return preset_config("ppo", scenario, seed, preset, eval_episodes=eval_episodes, system=system,
                         phase_control="optimizer", imitation=ImitationConfig(**STRONG_IMITATION[preset]),
                         total_steps=STRONG_RL_STEPS[preset])


def nearest_training_scenarios(scenario: str, k: int = TRANSFER_NEIGHBOURS) -> list[str]:
    """The ``k`` training scenarios whose start is closest to ``scenario``'s (ties by name)."""
    start = np.asarray(get_scenario(scenario).start)
    dist = {s: float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)) for s in TRAINING_SCENARIOS}
    return sorted(dist, key=lambda s: (round(dist[s], 9), s))[:k]


# ------------------------------------------------------------------------------ jobs (worker entry points)
def dataset_job(expert_dirs: list[str], trajectories: int, out: str) -> dict[str, Any]:
    """Collect the experts' trajectories into a dataset; returns its summary."""
    from uavris.experiments.collect import collect, dataset_summary

    return dataset_summary(collect(expert_dirs, trajectories, out, force=True, progress=False))


def pretrain_job(cfg_dict: dict[str, Any], out: str, device: str = "cpu") -> dict[str, Any]:
    """Pre-train (or resume) a DT; returns its done.json."""
    from uavris.experiments.pretrain import PretrainConfig, pretrain

    model_dir = Path(out)
    pretrain(PretrainConfig(**cfg_dict), model_dir, resume=model_dir.exists(), progress=False, device=device)
    return read_done(model_dir)


def finetune_job(cfg_dict: dict[str, Any], out: str, device: str = "cpu") -> dict[str, Any]:
    """Fine-tune (or resume) a DT; returns its done.json."""
    from uavris.experiments.finetune import FinetuneConfig, finetune

    model_dir = Path(out)
    finetune(FinetuneConfig(**cfg_dict), model_dir, resume=model_dir.exists(), progress=False, device=device)
    return read_done(model_dir)


def evaluate_job(out: str, scenario: str, track: str, system_dict: dict[str, Any], episodes: int,
                 dirs: dict[str, str]) -> dict[str, Any]:
    """Every policy of a track in ``scenario`` on the same seeded episodes (see :func:`evaluate_policies`)."""
    return evaluate_policies(Path(out), scenario, TRACK_SPECS[track], SystemConfig.from_dict(system_dict), episodes,
                             {k: Path(v) for k, v in dirs.items()})


# ------------------------------------------------------------------------------ evaluation of a track
def evaluate_policies(out: Path, scenario: str, track: Track, system: SystemConfig, episodes: int,
                      dirs: dict[str, Path]) -> dict[str, Any]:
    """The scenario's own expert, the zero-shot and fine-tuned DT, the experts of the nearest
    training scenarios (transferred) and the references (zero action, hover with the
    optimiser's phases, oracle), all on episodes ``EVAL_SEED ..``; per-episode CSVs in ``out``.

    ``dirs``: ``experts-train``, ``experts-unseen``, ``pretrain``, ``finetune`` stage directories.
    """
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, REFERENCES, ZERO_ACTION, reference_policy
    from uavris.experiments.dt_runs import load_dt_policy
    from uavris.experiments.evaluate import write_results
    from uavris.experiments.jobs import configure_torch_threads
    from uavris.experiments.train_expert import load_run_policy
    from uavris.stats import summarize

    configure_torch_threads()

    def expert(run_dir: Path) -> tuple[str, Any]:
        cfg, policy = load_run_policy(run_dir)
        return cfg.algo.upper(), policy

    policies: dict[str, tuple[str, Any]] = {}
    algo, policy = expert(dirs["experts-unseen"] / "runs" / scenario)
    policies["expert"] = (f"{algo} expert trained in the scenario", policy)
    policies["dt-zero-shot"] = ("zero-shot DT", load_dt_policy(dirs["pretrain"] / "model")[0])
    policies["dt-finetuned"] = ("fine-tuned DT", load_dt_policy(dirs["finetune"] / "model")[0])
    for src in nearest_training_scenarios(scenario):
        algo, policy = expert(dirs["experts-train"] / "runs" / src)
        policies[f"transfer-{src}"] = (f"{algo} transferred from {src}", policy)
    for name in (ZERO_ACTION, HOVER_OPTIMIZER, ORACLE):
        policies[name] = (REFERENCES[name].label, reference_policy(name, system))
    result: dict[str, Any] = {}
    for key, (label, policy) in policies.items():
        res = evaluate(policy, system, scenario, episodes, EVAL_SEED)
        summary = {"policy": key, "label": label, "scenario": scenario, "track": track.name, **res.summary(),
                   **{f"boot_{k}": v for k, v in summarize(res.avg_sum_rate).items()}}
        write_results(res, summary, out / key)
        result[key] = summary
    return result
