"""The Decision Transformer of the paper's Sec. IV: model, cache, checkpoints, data, trainer, policy.

Modules: :mod:`.model` (the transformer and its configuration), :mod:`.cache` (the banded
layout's key/value cache), :mod:`.checkpoint` (safetensors + JSON), :mod:`.trajectories`
(eq. 14-18: trajectories, returns-to-go, elites, windows), :mod:`.dataset` (Minari files),
:mod:`.trainer` (the optimiser, the learning-rate schedule and the training step),
:mod:`.policy` (deployment).

Lives here: nothing at package level; import from the modules. Not here: the pipelines that
use them (:mod:`uavris.experiments.training.collect`, :mod:`uavris.experiments.training.pretrain`,
:mod:`uavris.experiments.training.finetune`) and DT run directories (:mod:`uavris.experiments.training.dt_runs`).
"""
