"""Pipelines, reports and tools built on the environment and the agents, in five rooms.

- :mod:`.engine`: the job engine; it imports nothing of the study. :mod:`~.engine.jobs`
  (process pool or Ray, one thread per worker), :mod:`~.engine.stages` (resumable stages
  keyed by their configuration), :mod:`~.engine.scheduling` (the runner shared by a
  pipeline's stages, priorities, the progress bar), :mod:`~.engine.costs` (what a job is
  expected to cost), :mod:`~.engine.forecast` (the expected schedule and the ETA).
- :mod:`.display`: how results are shown: :mod:`~.display.tables` (Markdown tables,
  numbers and intervals as text), :mod:`~.display.plots` (figures fit for a paper),
  :mod:`~.display.progress` (progress bars, TensorBoard writers).
- :mod:`.training`: one run of each kind of learning: :mod:`~.training.train_expert` (an
  expert), :mod:`~.training.compare` (the algorithm comparison, Fig. 2),
  :mod:`~.training.collect` (the experts' dataset), :mod:`~.training.demonstrations` (the
  oracle's, over generated halls), :mod:`~.training.pretrain` and :mod:`~.training.finetune`
  (the DT's two stages), :mod:`~.training.dt_runs` (writing their run directories).
- :mod:`.tools`: what a user calls on a policy or a hall: :mod:`~.tools.targets` (what a
  name on the command line names), :mod:`~.tools.rows` (a report's row, a controller
  directory, the registry), :mod:`~.tools.evaluate`, :mod:`~.tools.user_policy`,
  :mod:`~.tools.benchmark` (the study's protocol), :mod:`~.tools.sweep` (a grid of system
  parameters), :mod:`~.tools.plan` (the oracle's plan and rate map), :mod:`~.tools.run_curves`
  (learning curves), :mod:`~.tools.demo`.
- :mod:`.study`: ``uavris reproduce``: :mod:`~.study.config`, :mod:`~.study.tracks` (and
  their rows), :mod:`~.study.pipeline`, :mod:`~.study.workers`, :mod:`~.study.reproduce`,
  :mod:`~.study.finished` (a study's directory opened: its stages, results and rows) and :mod:`~.study.report`.

Each room imports only the rooms listed before it (``display`` and ``engine`` import no
other). Lives here: nothing at package level; import from the modules. Not here: the
policies and their scoring (:mod:`uavris.agents`), the command-line flags
(:mod:`uavris.cli`) and the preset tables (:mod:`uavris.presets`).
"""
