"""The Decision Transformer of the paper's Sec. IV: its configuration, model, training and deployment.

Modules, in the order a reader meets them: :mod:`.config` (:class:`~.config.DTConfig`, the
model's size and kind), :mod:`.goals` (where a goal-conditioned DT is told to go),
:mod:`.encoders` (the state encoders: the DT paper's linear map, or a hall as a set of
devices), :mod:`.model` (the transformer), :mod:`.cache` (the banded layout's key/value
cache), :mod:`.trajectories` (eq. 14-18: trajectories, returns-to-go, elites, recording,
normalisation), :mod:`.training` (the windows, the loss L_OFF / L_FT, the optimiser, its
schedule and the steps, read top to bottom), :mod:`.checkpoint` (safetensors + JSON),
:mod:`.dataset` (Minari files) and :mod:`.policy` (deployment, and
:func:`~.policy.load_dt_policy`, the one loader).

Lives here: nothing at package level; import from the modules. Not here: the runs that use
them, with their directories, logs and checkpoints (:mod:`uavris.experiments.training.collect`,
:mod:`uavris.experiments.training.pretrain`, :mod:`uavris.experiments.training.finetune`,
:mod:`uavris.experiments.training.dt_runs`).
"""
