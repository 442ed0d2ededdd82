"""Pipelines, reports and plots built on the environment and the agents.

Training: :mod:`.train_expert` (one expert run), :mod:`.compare` (the algorithm comparison),
:mod:`.collect` (the experts' Minari dataset), :mod:`.pretrain` and :mod:`.finetune` (the
DT's two stages), :mod:`.dt_runs` (their run directories). Scoring and figures:
:mod:`.evaluate`, :mod:`.plots`, :mod:`.run_curves`. The study: :mod:`.reproduce`
(``uavris reproduce``), :mod:`.study` (its two tracks and the work of its stages),
:mod:`.stages` (resumable keyed stages), :mod:`.jobs` (process pool or Ray), :mod:`.report`
(``report.md`` and its figures).

Lives here: nothing at package level; import from the modules. Not here: the policies and
their scoring (:mod:`uavris.agents`), the command-line flags (:mod:`uavris.cli`) and the
preset budgets (:mod:`uavris.presets`).
"""
