"""What a user calls on a policy or a hall: evaluate, benchmark, sweep, plan, plot, demo.

Modules: :mod:`.targets` (what a name on the command line names: a reference, a run, a DT
model, a user's policy), :mod:`.rows` (a report's row, a controller directory and the registry
that resolves a name), :mod:`.evaluate` (``uavris evaluate``), :mod:`.user_policy` (a
user's own controller), :mod:`.benchmark` (any target on the study's protocol),
:mod:`.sweep` (the sum rate over a grid of system parameters), :mod:`.plan` (the oracle's
plan and the rate map of a hall), :mod:`.run_curves` (learning
curves of runs) and :mod:`.demo` (``uavris demo``).

Lives here: nothing at package level. Not here: the evaluation loop
(:func:`uavris.agents.evaluation.evaluate`), the command-line flags (:mod:`uavris.cli`).
"""
