"""One run of each kind of learning, with its run directory, checkpoints and resume.

Modules: :mod:`.train_expert` (an SB3 expert: :class:`~.train_expert.TrainConfig`),
:mod:`.compare` (the algorithm comparison, paper Fig. 2), :mod:`.collect` (the experts'
trajectories as a Minari dataset), :mod:`.demonstrations` (the planning oracle's, over
generated halls), :mod:`.pretrain` and :mod:`.finetune` (the Decision Transformer's two
stages, paper Algorithm 1) and :mod:`.dt_runs` (what writing the DT's run directories shares).

Lives here: nothing at package level. Not here: the models and their training steps
(:mod:`uavris.agents`), the study that runs these as jobs (:mod:`uavris.experiments.study`).
"""
