"""What a job of the study is expected to cost: seconds of one core, from its amount of work.

Lives here: the measured cost per unit of each kind of work (:data:`SB3_STEP_S`, ...) and the
expected cost of each kind of job (:func:`train_cost`, :func:`dataset_cost`,
:func:`demonstration_cost`, :func:`pretrain_cost`, :func:`finetune_cost`, :func:`evaluate_cost`). Not here: what uses
them, the order in which the job runner starts jobs (:mod:`.jobs`, :mod:`.stages`: the
longest chain first) and the progress bar of ``reproduce`` (each job weighs its cost).

The unit costs are those of the project machine (2-core AMD EPYC, Zen 5, one job per core,
quick preset): each group of them (the SB3 env step, the simulated slot, the plans, the
planner's poses, the DT's step, the value's step) scaled to fit the stage times of a whole quick
study on a fresh clone (its ``schedule.json``, read by ``benchmarks/findings/cost_model.py
--fit``; docs/timings.md). The shapes inside a group come from earlier measurements: an SB3 env
step per algorithm with the quick networks (64 x 64), and with the paper preset's 256 x 256 from
``benchmarks/paper_wallclock.py``; a simulated slot with a learned policy, with and without the
per-slot phase optimiser; the exact planner's plan and the oracle's (with its global stage) by the
number of devices; a DT gradient step at the DT paper's size (batch 64 windows of 20 slots, width
128, 3 layers), scaled by the tokens it reads. They order and weigh jobs and start the ETA, which
then scales them by this run's own job times (:mod:`.forecast`); nothing depends on them being
exact, only on their ratios being about right.
"""

from __future__ import annotations

from typing import Any

# SB3 training, seconds per env step (networks of the preset; smoke uses quick's rates).
SB3_STEP_S: dict[str, dict[str, float]] = {
    "quick": {"ddpg": 1.8e-3, "td3": 1.8e-3, "sac": 3.4e-3, "ppo": 0.076e-3},
    "paper": {"ddpg": 3.6e-3, "td3": 3.9e-3, "sac": 6.2e-3, "ppo": 0.12e-3},
}
# A simulated slot of one episode with a learned policy, by who sets the phases, and with the
# planning oracle as the teacher of imitation (its motion only, no phases).
SLOT_S = {"agent": 0.16e-3, "optimizer": 0.41e-3}
# a collected slot costs this share of an evaluated one (one batch, no slot records; the optimiser's measured
# in the make run of docs/timings.md)
COLLECT_SHARE = {"agent": 0.3, "optimizer": 0.79}
IMITATION_SLOT_S = 0.56e-3  # a DAgger slot: the rollout, the oracle's label and its share of the fitting
PLAN_S = 1.4  # the planner's plan of one hall without the global stage, refining with R (EXACT_TEACHER)
# The oracle's plan (the yardstick, with its global stage: docs/model.md section 19) by the number of devices
ORACLE_PLAN_S = {3: 0.17, 4: 6.8, 5: 11.3, 6: 17.0, 7: 22.6, 8: 28.3}
TEACHER_PLAN_S = PLAN_S / 4.1  # the demonstrations' teacher (its pattern search on the cheap estimate), measured 4.1x
# A DT gradient step at the DT paper's size: batch 64 windows of 20 slots, width 128, 3 layers;
# other sizes scale with the slots read times width^2 times depth (the matrix products).
DT_STEP_S = 0.149
DT_REFERENCE = 64 * 20 * 128 * 128 * 3
# What a gradient step costs whatever the model's size (the sampling of windows, the optimiser,
# the autograd bookkeeping): small models are dominated by it. And the device-set encoder's
# per-device and pair networks, per state it reads (docs/study.md, section 2).
DT_STEP_OVERHEAD_S = 0.0112
DEVICE_ENCODER_STATE_S = 1.86e-5


def _dt_step(batch: int, context: int, width: int, depth: int) -> float:
    return DT_STEP_S * batch * context * width * width * depth / DT_REFERENCE


def train_cost(cfg: Any) -> float:
    """An expert's training run (a :class:`~uavris.experiments.training.train_expert.TrainConfig`):
    imitation rollouts and fitting, the RL env steps, and its periodic and final evaluations."""
    rates = SB3_STEP_S.get(cfg.preset, SB3_STEP_S["quick"])
    cost = cfg.total_steps * rates[cfg.algo]
    horizon = cfg.system.horizon
    evaluations = cfg.total_steps // cfg.eval_every + 1
    cost += evaluations * cfg.eval_episodes * horizon * SLOT_S[cfg.phase_control]
    if cfg.imitation is not None:
        cost += PLAN_S + cfg.imitation.rounds * cfg.imitation.episodes * horizon * IMITATION_SLOT_S
        if cfg.imitation.evaluate_rounds:  # each round's student evaluated too
            cost += cfg.imitation.rounds * cfg.eval_episodes * horizon * SLOT_S[cfg.phase_control]
    return cost


def dataset_cost(episodes: int, horizon: int, phase_control: str) -> float:
    """Collecting ``episodes`` expert episodes."""
    return episodes * horizon * SLOT_S[phase_control] * COLLECT_SHARE[phase_control]


def demonstration_cost(halls: int, episodes_per_hall: int, horizon: int, exact_plans: bool = False) -> float:
    """The planning oracle's demonstrations in ``halls`` halls: a plan each (the teacher's, or
    its search with ``R``), and the episodes (all behaviours of a hall) with the optimiser's
    phases."""
    return halls * ((PLAN_S if exact_plans else TEACHER_PLAN_S) + episodes_per_hall * horizon * SLOT_S["optimizer"])


def pretrain_cost(cfg: Any) -> float:
    """A DT pre-training run (a :class:`~uavris.experiments.training.pretrain.PretrainConfig`)."""
    m = cfg.model
    encoder = DEVICE_ENCODER_STATE_S * cfg.batch_size * m.context if m.state_encoder == "devices" else 0.0
    return cfg.steps * (DT_STEP_OVERHEAD_S + _dt_step(cfg.batch_size, m.context, m.width, m.depth) + encoder)


def finetune_cost(cfg: Any, horizon: int, phase_control: str, model: Any) -> float:
    """A DT fine-tuning run (a :class:`~uavris.experiments.training.finetune.FinetuneConfig`) of a
    ``model`` (a :class:`~uavris.agents.dt.config.DTConfig`: its context, width and depth): per
    round, the noisy candidates, the gradient steps on the elites and an evaluation."""
    context, width, depth = model.context, model.width, model.depth
    slots = (cfg.candidates + cfg.eval_episodes) * horizon
    steps = cfg.epochs_per_round * -(-cfg.elites * horizon // cfg.batch_size)
    per_round = slots * (SLOT_S[phase_control] + _dt_step(1, context, width, depth) / 4) + steps * _dt_step(
        cfg.batch_size, context, width, depth)
    return cfg.eval_episodes * horizon * SLOT_S[phase_control] + cfg.rounds * per_round


# The planner's R of one pose (its pairings x 2 NLoS draws, optimised), by the number of devices:
# K = 3 has one pair at most (the closed form); more pairs, more optimiser per slot.
POSE_S = {3: 0.72e-4, 4: 0.0105, 5: 0.0101, 6: 0.0192, 7: 0.0326, 8: 0.0455}
VALUE_STEP_S = 0.0155  # a gradient step of the learned value at width 64, batch 256 (scales with width^2)


def pose_cost(devices: int) -> float:
    """The planner's ``R`` of one pose in a hall of ``devices`` (:data:`POSE_S`; beyond 8 devices
    as the square of the count)."""
    return POSE_S.get(devices, POSE_S[8] * (devices / 8) ** 2)


# Poses labelled per position where each is labelled again tilted towards the devices (ValueLabelsConfig.tilted):
# measured over 32 training halls of each of 3-8 devices, 1.83 (3 devices) to 1.55 (8).
TILTED_LABELS = 1.65


def value_labels_cost(count: int, halls: int, poses: int, tilted: bool = False) -> float:
    """Labelling ``poses`` positions in each of ``halls`` halls of ``count`` devices (and each hall's
    screen), each again tilted where ``tilted``."""
    per = poses * (TILTED_LABELS if tilted else 1.0)
    return halls * (per * pose_cost(count) + 0.05)


def value_fit_cost(steps: int, width: int) -> float:
    """Fitting the learned value: ``steps`` gradient steps of a network of ``width``."""
    return steps * VALUE_STEP_S * (width / 64) ** 2


def optimiser_scale(devices: int) -> float:
    """What a slot of the per-slot phase optimiser costs in a hall of ``devices`` against one of
    4: as the planner's ``R`` of a pose does (:func:`pose_cost`, its pairings optimised), at least
    1 (the slot's other work). It grows faster than
    the pairs: an evaluated row's episode cost 0.16, 0.26 and 0.46 s at 6, 8 and 10 devices
    (2026-11-29, Zen 4), where pairs alone gave a 10-device hall a third of its measured time."""
    return max(1.0, pose_cost(devices) / POSE_S[4])


def evaluate_cost(policies: int, episodes: int, horizon: int, phase_control: str, devices: int = 4,
                  oracle_plans: int = 1, generated: bool = False, teacher_plans: int = 0,
                  dt_forwards: int = 0, model: Any = None) -> float:
    """Evaluating ``policies`` learned policies and the references (zero action, hover with the
    optimiser's phases, the planning oracle) on ``episodes`` episodes in a hall of ``devices``
    devices: the optimiser's slots grow with them (:func:`optimiser_scale`); ``dt_forwards`` DT models of ``model``'s
    size (a DT or behaviour-cloning row one, an ensemble its members) read their window every
    slot, as fine-tuning's rollouts do; the oracle plans ``oracle_plans`` times (with and
    without a safety layer), in a ``generated`` hall with its global stage
    (:data:`ORACLE_PLAN_S`), and ``teacher_plans`` other halls are planned (a transferred plan's)."""
    dearer = optimiser_scale(devices)
    learned = policies * episodes * horizon * SLOT_S[phase_control] * (dearer if phase_control == "optimizer" else 1.0)
    if dt_forwards and model is not None:
        learned += dt_forwards * episodes * horizon * _dt_step(1, model.context, model.width, model.depth) / 4
    plan = ORACLE_PLAN_S.get(devices, ORACLE_PLAN_S[8] * devices / 8) if generated else PLAN_S
    references = oracle_plans * plan + teacher_plans * PLAN_S + 2 * episodes * horizon * SLOT_S["optimizer"] * dearer
    return learned + references
