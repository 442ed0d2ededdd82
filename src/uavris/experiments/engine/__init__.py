"""The job engine: jobs on a process pool or Ray, resumable keyed stages, their schedule and costs.

Modules: :mod:`.process` (:func:`~.process.configure_threads`, :func:`~.process.machine`),
:mod:`.worker` (:class:`~.worker.Job` and its run in a worker process), :mod:`.ray_backend`
(jobs on Ray), :mod:`.jobs` (:class:`~.jobs.JobRunner`),
:mod:`.stages` (:class:`~.stages.Stage`, :class:`~.stages.Pipeline`), :mod:`.scheduling`
(:class:`~.scheduling.StudyContext`: the runner, priorities and progress shared by a
pipeline's stages), :mod:`.costs` (expected seconds of each kind of job) and
:mod:`.forecast` (the replay that gives the expected schedule and the ETA).

Lives here: nothing at package level. Not here: any stage of the study (it imports no
study code: :mod:`uavris.experiments.study` builds on it).
"""
