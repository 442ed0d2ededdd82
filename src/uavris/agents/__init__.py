"""Every policy of uavris, and how a policy is scored.

Families: :mod:`.baselines` (doing nothing, random, co-phasing), :mod:`.oracle` (the
references that plan with the simulator's state), :mod:`.experts` (the DRL experts),
:mod:`.dt` (the Decision Transformer). Around them: :mod:`.policy` (the interface),
:mod:`.references` (every reference by name), :mod:`.evaluation` (seeded evaluation),
:mod:`.torch_device` (the torch device the experts and the DT run on).

Lives here: nothing at package level; import from the modules above. Not here: the rollout
loop every policy runs in (:mod:`uavris.env.rollout`) and the pipelines (training runs,
datasets, studies: :mod:`uavris.experiments`).
"""
