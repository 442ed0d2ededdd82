"""Functional physics API: pure, numpy-batched functions of the paper's system model.

Modules: :mod:`.geometry` (attitude, RIS axes, incidence), :mod:`.channel` (UPA channels,
cascaded gains), :mod:`.reflection` (angle-dependent reflection), :mod:`.rates` (SINR, sum
rate), :mod:`.pairing` (link activation), :mod:`.motion` (kinematics, propulsion energy),
:mod:`.streams` (counter-based random numbers), :mod:`.co_phasing`, :mod:`.phase_opt` and
:mod:`.phase_kernel` (the per-slot phase optimiser: one pair's closed form, the method, its compiled core).

Lives here: the re-exports of the first six modules' functions (``__all__``). Not here:
:mod:`.streams`, :mod:`.co_phasing` and :mod:`.phase_opt`, imported from their modules, and the per-slot
composition of these functions into a simulator (:mod:`uavris.env.simulator`).

Every function works on arrays with arbitrary leading (batch) dimensions. Example: the
sum rate of one geometry, attitude, NLoS draw, phase vector and pairing::

    import numpy as np
    from uavris import physics as ph

    users = np.array([[15, 5, 1.0], [20, 8, 1.5], [30, 20, 0.1], [15, 35, 0.6]])
    axes = ph.ris_axes([0.0, 0.0, 0.0])                       # level RIS
    u, v, cos_t, dist = ph.incidence([20, 20, 4.5], users, axes)
    rng = np.random.default_rng(0)
    w = (rng.standard_normal((4, 16)) + 1j * rng.standard_normal((4, 16))) / np.sqrt(2)
    h = ph.rician_channels(u, v, cos_t, dist, w, rician_factor=8, pathloss_exponent=2.4, nx=4, ny=4)
    r = ph.effective_reflection(np.exp(1j * rng.uniform(0, 2 * np.pi, 16)), cos_t)
    P = np.zeros((4, 4)); P[0, 1] = P[2, 3] = 1                # 0 -> 1 and 2 -> 3 active
    print(ph.sum_rate(ph.cascaded_gains(h, r), P, tx_power_w=1.0, noise_w=1e-11))
"""

from uavris.physics.channel import (
    array_response,
    cascaded_gains,
    effective_reflection,
    effective_reflection_from_phases,
    rician_channels,
)
from uavris.physics.geometry import (
    accumulate_attitude,
    clear_attitude,
    incidence,
    ris_axes,
    rotation_matrix,
    worst_elevation,
    wrap_angle,
)
from uavris.physics.motion import (
    feasible_acceleration,
    kinematic_step,
    limit_norm,
    propulsion_power,
    separation,
    slot_energy,
)
from uavris.physics.pairing import pairing_from_uniforms, sample_pairing
from uavris.physics.rates import pair_rates, pair_sinr, sum_rate
from uavris.physics.reflection import (
    lambda_coefficients,
    preset_for_target,
    reflection_coefficient,
    reflection_coefficient_eq5,
    unit_reflection_coefficient,
)

__all__ = [
    "accumulate_attitude",
    "array_response",
    "cascaded_gains",
    "clear_attitude",
    "effective_reflection",
    "effective_reflection_from_phases",
    "feasible_acceleration",
    "incidence",
    "kinematic_step",
    "lambda_coefficients",
    "limit_norm",
    "pair_rates",
    "pair_sinr",
    "pairing_from_uniforms",
    "preset_for_target",
    "propulsion_power",
    "reflection_coefficient",
    "reflection_coefficient_eq5",
    "ris_axes",
    "rician_channels",
    "rotation_matrix",
    "sample_pairing",
    "separation",
    "slot_energy",
    "sum_rate",
    "unit_reflection_coefficient",
    "worst_elevation",
    "wrap_angle",
]
