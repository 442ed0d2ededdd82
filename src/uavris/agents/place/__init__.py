"""Where the UAV should be: a learned value of a pose and the planner built on it (docs/places.md).

Modules: :mod:`.value` (``V(devices, position)``, a set encoder trained on the planner's
``R``), :mod:`.labels` (poses of training halls and their ``R``), :mod:`.planner` (the
argmax of ``V`` over a hall with the planner's travel-time rule, and its semi-amortised
form: the top places valued by ``R``), :mod:`.checkpoint` (safetensors + JSON).

Lives here: nothing at package level; import from the modules. Not here: the exact planner
it learns from and is judged against (:mod:`uavris.agents.oracle.planner`), the controller
that flies to a place (:mod:`uavris.agents.dt`).
"""
