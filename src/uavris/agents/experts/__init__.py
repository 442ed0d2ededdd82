"""The DRL experts: DDPG, PPO, SAC and TD3 from Stable-Baselines3 on the batched env.

Modules: :mod:`.hyperparams` (validated hyperparameters and their reasons), :mod:`.sb3`
(building, loading and deploying the SB3 models), :mod:`.vec_env` (the SB3 VecEnv over the
batched simulator), :mod:`.resume_state` (what exact resume needs beyond SB3's files),
:mod:`.imitation` (the strong track's start: imitation of the oracle).

Lives here: the re-exports of :mod:`.hyperparams` (:data:`ALGORITHMS`, :data:`OFF_POLICY`,
:class:`Hyperparams`, :func:`check_algorithm`, :func:`default_hyperparams`,
:func:`hyperparams_for`). Not here: training runs (:mod:`uavris.experiments.training.train_expert`)
and the per-preset hyperparameter values (:mod:`uavris.presets`).
"""

from uavris.agents.experts.hyperparams import (
    ALGORITHMS,
    OFF_POLICY,
    Algorithm,
    Hyperparams,
    check_algorithm,
    default_hyperparams,
    hyperparams_for,
)

__all__ = ["ALGORITHMS", "OFF_POLICY", "Algorithm", "Hyperparams", "check_algorithm", "default_hyperparams",
           "hyperparams_for"]
