"""Every policy of uavris, and how a policy is scored.

Families: :mod:`.baselines` (doing nothing, random, co-phasing), :mod:`.oracle` (the
references that plan with the simulator's state), :mod:`.experts` (the DRL experts),
:mod:`.dt` (the Decision Transformer). Around them: :mod:`.policy` (the interface),
:mod:`.references` (every reference by name), :mod:`.evaluation` (seeded evaluation).
Pipelines (training runs, datasets, studies) are in :mod:`uavris.experiments`.
"""
