"""The study (``uavris reproduce``): the paper's pipeline in three tracks, and its report.

Modules, in the order a reader follows the study: :mod:`.config`
(:class:`~.config.ReproduceConfig`: what determines a study), :mod:`.tracks` (what sets the
paper, strong and deployment tracks apart, and where each trains and is tested),
:mod:`.pipeline` (the stages, their keys, inputs and costs), :mod:`.workers` (what a worker
process runs for a stage's job), :mod:`.reproduce` (run or resume the study; its estimate)
and :mod:`.report` (``report.md`` and its figures).

Lives here: nothing at package level. Not here: the job engine the stages run on
(:mod:`uavris.experiments.engine`), one training run (:mod:`uavris.experiments.training`).
"""
