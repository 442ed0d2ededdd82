"""Gymnasium environment ``uavris/UavRisD2D-v1`` (one UAV-RIS system).

Lives here: :class:`UavRisD2DEnv`, a one-row :class:`uavris.env.simulator.BatchedSimulator`
behind Gymnasium's ``reset`` and ``step`` (spaces, reward, termination: its docstring). Not
here: the dynamics (:mod:`.simulator`), the batched environment (:mod:`.vector`) and the
registration with :func:`uavris.env.make_env` (:mod:`uavris.env`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator, observation_bounds, step_info
from uavris.env.wrappers import PhaseControl, PhaseControlled

_SCALARS = {"energy_used": float, "energy_remaining": float, "slot": int, "sum_rate": float, "slot_energy": float}


def _row(info: dict[str, NDArray], i: int = 0) -> dict[str, Any]:
    """Row ``i`` of a batched ``info`` (:func:`uavris.env.simulator.step_info`), scalars as Python numbers."""
    return {k: _SCALARS[k](v[i]) if k in _SCALARS else v[i] for k, v in info.items()}


class UavRisD2DEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """UAV-mounted RIS serving randomly activated D2D pairs (paper Sec. II-IV).

    ## Description

    A rotary-wing UAV carries a reconfigurable intelligent surface (RIS) of ``N = nx * ny``
    elements (the paper's 4 x 4) over an indoor hall (the paper's 40 x 40 x 8 m) in which ``K``
    D2D devices stand (the paper's four). In every slot of ``slot_s`` = 0.5 s a random set of
    device pairs is active (``m`` pairs, ``m`` uniform in ``1..floor(K/2)``, random partners and
    directions), and every link goes through the RIS: Rician device-RIS channels whose
    line-of-sight part follows the UAV's position and attitude (the NLoS part is redrawn every
    slot), an angle-dependent reflection coefficient, interference between the active links.
    The agent steers the UAV (3-D acceleration), its attitude (yaw, pitch and roll increments)
    and the ``N`` RIS phases; the reward is the sum rate, and the UAV's propulsion energy is
    budgeted. The UAV flies inside the flight region ``[0, room_x] x [0, room_y] x [z_min, z_max]``
    and keeps ``safety_distance`` (3 m) from every device, both enforced by the kinematics.
    This environment is one row of :class:`uavris.env.simulator.BatchedSimulator`; the vector
    environment :class:`uavris.env.vector.UavRisD2DVectorEnv` is the same system, bit for bit.
    The model, equation by equation: ``docs/model.md``.

    ## Action Space

    ``Box(-1, 1, (N + 6,), float32)`` (``SystemConfig.action_dim``: 22 for the paper's
    ``N = 16``; ``2N + 6`` = 38 with ``learn_amplitudes=True``), in this order:

    | entries | meaning | mapping |
    |---|---|---|
    | ``[0:3]`` | the UAV's acceleration (x, y, z) | times ``a_max`` (2 m/s^2), norm limited by ``a_max``, ``v_max`` |
    | ``[3:3+N]`` | RIS phase of element ``n = m * nx + i`` | ``(x + 1) * pi``, in ``[0, 2 pi]`` |
    | ``[3+N:3+2N]``, only with ``learn_amplitudes`` | RIS amplitudes | ``(x + 1) / 2``, in ``[0, 1]`` |
    | last 3 | attitude increments (yaw, pitch, roll) | times ``attitude_step_deg`` (10 degrees) |

    Values outside ``[-1, 1]`` are clipped; NaN, inf or another shape raise
    :class:`uavris.errors.ActionError` (a ``ValueError``) before any state changes. A policy of
    the 6 motion entries can leave the phases to the per-slot phase optimiser
    (:mod:`uavris.env.wrappers`, phase control ``"optimizer"``).

    ## Observation Space

    ``Box(low, high, (2KN + K^2 + 14,), float32)`` (``SystemConfig.observation_dim``: 158 for
    the paper's ``K = 4``, ``N = 16``), ``3K`` entries more with ``observe_devices=True`` (170).
    The blocks, in order (:func:`uavris.env.simulator.observation_layout` gives their slices):

    | block | size | content and scaling |
    |---|---|---|
    | ``position`` | 3 | the UAV's position, ``(q - centre) / half`` of the flight region, in ``[-1, 1]`` |
    | ``velocity`` | 3 | ``v / v_max``, in ``[-1, 1]`` |
    | ``attitude_sin`` | 3 | sine of yaw, pitch and roll |
    | ``attitude_cos`` | 3 | cosine of yaw, pitch and roll |
    | ``channel_real`` | ``K * N`` | ``Re H(t)``, device ``k``'s element ``n`` at ``k * N + n``, scaled (below) |
    | ``channel_imag`` | ``K * N`` | ``Im H(t)``, the same layout and scale |
    | ``pairing`` | ``K * K`` | the pairing ``P(t)``, row = transmitter: 1 for an active link, else 0 |
    | ``energy_remaining`` | 1 | ``clip(1 - E / energy_budget_j, 0, 1)`` |
    | ``time_fraction`` | 1 | ``t / horizon`` |
    | ``devices``, only with ``observe_devices`` | ``3K`` | ``(q_k - q) / L`` per device, in the layout's order |

    The channels are multiplied by ``channel_ref_distance ** (alpha / 2)``; ``L`` is the flight
    region's largest half-extent (20 m in the paper's hall), one length for the three axes.
    The channels' bounds are ``+-channel_observation_bound`` (10.76 at the defaults: the
    closest approach the safety distance allows and the largest NLoS draw), the pairing and
    the two fractions lie in ``[0, 1]``, the devices' offsets within the room seen from the
    flight region, every other entry in ``[-1, 1]``.

    ## Rewards

    The sum rate ``r(t)`` of the pairs active in slot ``t``, in bps/Hz: over the active links,
    ``log2(1 + SINR)`` with the phases of this action applied to the channels and pairing of
    slot ``t`` (the ones observed), the other active transmitters' signals as interference.
    There is no penalty term; the energy acts through termination only.

    ## Starting State

    The scenario's start (a named scenario's, a position ``[x, y, z]`` or a layout's start), at
    rest and level (velocity and attitude 0), slot 0, no energy used; the channels ``H(0)`` and
    the pairing ``P(0)`` are drawn there. Nothing of the start is random. The random numbers
    are counter-based streams: ``reset(seed=s)`` starts the stream of seed ``s``; a later
    ``reset()`` without a seed moves to that stream's next episode; a first ``reset()``
    without a seed draws the key from Gymnasium's entropy-seeded ``np_random``.

    ## Episode End

    - Termination: the propulsion energy used reaches ``energy_budget_j`` (8 kJ: hovering
      ends after 95 of the 100 slots). That slot is completed and rewarded, so the total may
      exceed the budget by at most one slot's energy.
    - Truncation: after ``horizon`` slots (100, 50 s), unless the same slot terminates.

    ## Arguments

    ``gymnasium.make("uavris/UavRisD2D-v1", config=None, scenario="fig2", phase_control="agent")``:

    - ``config``: the system, a :class:`uavris.config.SystemConfig` or its ``to_dict()`` (an
      environment spec stored as JSON, e.g. by Minari, gives a dict); ``None``: the paper's
      system with the defaults of ``docs/model.md``.
    - ``scenario``: a named scenario (``"fig2"``, ``"train1"``..``"train8"``, ``"unseen1"``,
      ``"unseen2"``), a :class:`uavris.config.Scenario` or its ``to_dict()``, or a start
      ``[x, y, z]``; it must lie in the flight region and keep ``safety_distance`` from every
      device (else :class:`uavris.errors.ConfigError`). A hall of your own:
      ``system, scenario = layout.resolve(SystemConfig())`` (:mod:`uavris.layouts`).
    - ``phase_control``: who sets the RIS phases. ``"agent"`` (the paper): the action holds the
      UAV's motion and the surface's phases; ``"optimizer"``: the action is the motion alone and each
      slot's phases are the phase optimiser's (:mod:`uavris.physics.phase_opt`, docs/model.md).

    ``gymnasium.make_vec("uavris/UavRisD2D-v1", num_envs=n, vectorization_mode="vector_entry_point")``
    gives the batched :class:`uavris.env.vector.UavRisD2DVectorEnv`. ``info`` holds
    ``sum_rate``, ``pair_rates`` (``K x K``), ``pairing``, ``incidence_deg``, ``position``,
    ``velocity``, ``attitude``, ``acceleration``, ``energy_used``, ``energy_remaining``,
    ``slot_energy`` and ``slot`` (after a reset: the pose, energy, slot, pairing and incidence).

    ## Version History

    Gymnasium's rule: the version moves when a change can alter results.

    - v1 (uavris 0.3.0; the dynamics since 0.2.0): the UAV keeps ``SystemConfig.safety_distance``
      (3 m) from every device, enforced by the kinematics like the walls (a start inside a
      safety ball is a ``ConfigError``), so the channels' observation bound fell from 92.38 to
      10.76. Off by default, so that the defaults' spaces are v0's: ``observe_devices`` (the
      devices appended to the observation, in the layout's order, in metres over one length),
      ``layout=`` (a hall of one's own: devices below ``z_min``, ``min_device_spacing`` apart),
      ``phase_control="optimizer"`` (6 motion entries, the optimiser's phases) and
      ``front_margin_deg`` (the attitude safety layer). ``config`` may be a dict (a stored
      spec, e.g. Minari's ``recover_environment``, rebuilds the environment); invalid actions
      raise ``ActionError``, a ``ValueError``.
    - v0 (uavris 0.1.0): the paper's system: 22 actions, 158 observations, reward the sum rate,
      termination on the energy budget, truncation at the horizon, no safety separation (under
      v1: ``SystemConfig(safety_distance=0)``).
    """

    metadata = {"render_modes": []}

    def __init__(self, config: SystemConfig | None = None, scenario: str | Scenario = "fig2",
                 phase_control: PhaseControl = "agent") -> None:
        self.config = config if config is not None else SystemConfig()
        self.sim = BatchedSimulator(self.config, scenario, 1)
        self.scenario = self.sim.scenario
        self.controls = PhaseControlled(self.config, phase_control)
        low, high = observation_bounds(self.config)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.controls.action_dim,), dtype=np.float32)
        self._seeded = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.sim.seed(np.array([seed]))
            self.sim.reset()
        elif not self._seeded:
            # Unseeded: draw the key from Gymnasium's entropy-seeded generator.
            self.sim.seed(self.np_random.integers(0, 2**63, size=1))
            self.sim.reset()
        else:
            self.sim.reset(next_episode=True)
        self._seeded = True
        return self.sim.observe()[0], _row(step_info(self.sim, None))

    def step(self, action: NDArray):
        if not self._seeded:
            raise RuntimeError("call reset() before step()")
        executed = self.controls.executed(self.sim, np.asarray(action).reshape(1, -1))
        reward, terminated, truncated, info = self.sim.step(executed)
        return (self.sim.observe()[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                _row(step_info(self.sim, info)))
