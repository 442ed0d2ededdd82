"""The DRL experts: DDPG, PPO, SAC and TD3 from Stable-Baselines3 on the batched env.

Modules: :mod:`.hyperparams` (validated hyperparameters and their reasons), :mod:`.sb3`
(building, loading and deploying the SB3 models), :mod:`.vec_env` (the SB3 VecEnv over the
batched simulator), :mod:`.resume_state` (what exact resume needs beyond SB3's files),
:mod:`.imitation` (the strong track's start: imitation of the oracle). Training runs are
:mod:`uavris.experiments.train_expert`.
"""

from uavris.agents.experts.hyperparams import (
    ALGORITHMS,
    OFF_POLICY,
    Hyperparams,
    check_algorithm,
    default_hyperparams,
    hyperparams_for,
)

__all__ = ["ALGORITHMS", "OFF_POLICY", "Hyperparams", "check_algorithm", "default_hyperparams", "hyperparams_for"]
