"""The batched simulator shared by the single and the vector environment.

Lives here: :class:`BatchedSimulator` and :class:`SlotInfo`, the action map
(:func:`decode_action`, :func:`phases_to_action`), the observation (:func:`observation_layout`,
:func:`observation_bounds`, the devices' slice :func:`device_observation`) and the ``info``
dict (:func:`step_info`). Not here: the physics it composes (:mod:`uavris.physics`), the
Gymnasium interfaces (:mod:`.single`, :mod:`.vector`, registered in :mod:`uavris.env`) and
the optimised-phase control (:mod:`.wrappers`).

State lives in arrays with a leading environment axis; every quantity is computed with
one numpy call per step for the whole batch. The single environment is this simulator
with one row, which is why both agree bit for bit.

Slot timing (docs/model.md section 11): the observation of slot t holds the pose of slot t,
the channels H(t) (NLoS included) and the pairing P(t). The action's phases apply to slot t;
its acceleration and attitude increments then move the UAV to its slot t+1 pose, and
H(t+1), P(t+1) are drawn.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.config import Scenario, SystemConfig, get_scenario
from uavris.env._malloc import tune_allocator
from uavris.errors import ActionError, ConfigError
from uavris.physics import streams


@dataclass
class SlotInfo:
    """What one step produced, one row per environment."""

    reward: NDArray[np.float64]  # sum rate r(t), bps/Hz
    pair_rates: NDArray[np.float64]  # (n, K, K) rate of each active link tx -> rx
    pairing: NDArray[np.float64]  # (n, K, K) P(t)
    cos_theta: NDArray[np.float64]  # (n, K) incidence cosines in slot t
    accel: NDArray[np.float64]  # (n, 3) acceleration actually applied
    slot_energy: NDArray[np.float64]  # (n,) J spent moving to the next pose


def decode_action(action: NDArray, config: SystemConfig) -> tuple[NDArray, NDArray, NDArray | None, NDArray]:
    """Map Box(-1, 1) actions ``(n, action_dim)`` to (acceleration, phase, amplitude, attitude increment).

    Phases map [-1, 1] -> [0, 2 pi]; amplitudes (only with ``learn_amplitudes``) [-1, 1] -> [0, 1]
    and are ``None`` otherwise (unit amplitude).

    Out-of-range values are clipped; NaN or inf raise :class:`ActionError`.
    """
    a = np.asarray(action, dtype=np.float64)
    if a.ndim != 2 or a.shape[-1] != config.action_dim:
        raise ActionError(f"action must have shape (..., {config.action_dim}), got {np.shape(action)}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ActionError(f"action contains NaN or inf (first at index {tuple(int(i) for i in bad)}); "
                          "actions must be finite numbers in [-1, 1]")
    a = np.clip(a, -1.0, 1.0)
    n = config.num_elements
    accel = ph.limit_norm(a[:, 0:3] * config.a_max, config.a_max)
    # float32 phases: the action itself is float32, and float32 sin/cos are ~10x faster.
    phase = ((a[:, 3:3 + n] + 1.0) * np.pi).astype(np.float32)  # [0, 2 pi]
    amp = 0.5 * (a[:, 3 + n:3 + 2 * n] + 1.0) if config.learn_amplitudes else None
    d_att = a[:, -3:] * config.attitude_step_rad
    return accel, phase, amp, d_att


def phases_to_action(phase: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of the action's phase map [-1, 1] -> [0, 2 pi): the action entries of phases."""
    return np.mod(phase, 2 * np.pi) / np.pi - 1.0


def slot_draws(config: SystemConfig, keys: NDArray[np.uint64]) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """A slot's randomness from its counter keys (:func:`uavris.physics.streams.slot_key`, one per
    row): the NLoS draws ``w`` ``(n, K, N)`` and the pairing ``P(t)`` ``(n, K, K)`` (docs/model.md
    section 16). They depend on the seed, episode and slot alone, never on the actions."""
    K, N = config.num_users, config.num_elements
    bits = streams.raw_bits(keys, K * N + 1 + K)
    nlos = streams.complex_normals(bits[:, : K * N]).reshape(-1, K, N)
    unif = streams.uniforms(bits[:, K * N:])
    return nlos, ph.pairing_from_uniforms(unif[:, 0], unif[:, 1:], config.pairs_upper)


class BatchedSimulator:
    """The UAV-RIS D2D system for ``num_envs`` independent environments."""

    def __init__(self, config: SystemConfig, scenario: str | Scenario, num_envs: int) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.config = config.check()  # a system made field by field is judged whole here, at the latest
        self.scenario = get_scenario(scenario)
        self.scenario.validate_for(config)
        self.num_envs = num_envs
        if num_envs >= 64:
            tune_allocator()
        c = config
        self.users = np.asarray(c.users, dtype=np.float64)
        self.low = np.asarray(c.region_low)
        self.high = np.asarray(c.region_high)
        self._center = 0.5 * (self.low + self.high)
        self._half = 0.5 * (self.high - self.low)
        self._device_scale = device_scale(c)
        self._power = {k: float(v) for k, v in vars(c.propulsion).items()}
        self._chan_scale = c.channel_ref_distance ** (0.5 * c.pathloss_exponent)
        K, N = c.num_users, c.num_elements
        self._layout = observation_layout(c)
        z = np.zeros
        self.key = z(num_envs, dtype=np.uint64)
        self.episode = z(num_envs, dtype=np.uint64)
        self.t = z(num_envs, dtype=np.int64)
        self.pos = z((num_envs, 3))
        self.vel = z((num_envs, 3))
        self.att = z((num_envs, 3))
        self.energy = z(num_envs)
        self.channels = z((num_envs, K, N), dtype=np.complex128)
        self.pairing = z((num_envs, K, K))
        self.u = z((num_envs, K))
        self.v = z((num_envs, K))
        self.cos_theta = z((num_envs, K))
        self.dist = z((num_envs, K))

    # ----------------------------------------------------------------- randomness & channels
    def _draw_slot(self, rows: NDArray[np.intp] | slice) -> None:
        """Compute incidence for the current pose and draw H(t), P(t) for ``rows``."""
        c = self.config
        axes = ph.ris_axes(self.att[rows])
        u, v, cos_t, dist = ph.incidence(self.pos[rows], self.users, axes)
        nlos, pairing = slot_draws(c, streams.slot_key(self.key[rows], self.episode[rows], self.t[rows]))
        h = ph.rician_channels(u, v, cos_t, dist, nlos, rician_factor=c.rician_factor,
                               pathloss_exponent=c.pathloss_exponent, nx=c.nx, ny=c.ny, spacing=c.element_spacing)
        if isinstance(rows, slice) and rows == slice(None):
            # Whole batch: rebind rather than copy, so arrays handed out in a step's info
            # keep describing that step.
            self.channels, self.pairing = h, pairing
            self.u, self.v, self.cos_theta, self.dist = u, v, cos_t, dist
        else:
            self.channels[rows], self.pairing[rows] = h, pairing
            self.u[rows], self.v[rows], self.cos_theta[rows], self.dist[rows] = u, v, cos_t, dist

    # ----------------------------------------------------------------- reset
    def seed(self, seeds: NDArray[np.integer], rows: NDArray[np.intp] | slice = slice(None)) -> None:
        """Set the key of ``rows`` from integer seeds and restart their episode count."""
        self.key[rows] = streams.seed_key(seeds)
        self.episode[rows] = 0

    def reset(self, rows: NDArray[np.intp] | slice = slice(None), next_episode: bool = False) -> None:
        """Put ``rows`` back at the scenario's start, at rest and level, slot 0.

        A partial reset writes into the state arrays in place; arrays returned by an
        earlier :meth:`step` were rebound by it and are not affected.
        """
        if next_episode:
            self.episode[rows] += np.uint64(1)
        self.t[rows] = 0
        self.pos[rows] = self.scenario.start
        self.vel[rows] = 0.0
        self.att[rows] = 0.0
        self.energy[rows] = 0.0
        self._draw_slot(rows)

    def place(self, position: NDArray[np.floating], attitude: NDArray[np.floating]) -> None:
        """Put every UAV at a pose, at rest, and draw the current slot's channels and pairing
        there (for analysis and tests: the kinematics, walls and safety separation are bypassed)."""
        self.pos = np.broadcast_to(np.asarray(position, dtype=np.float64), (self.num_envs, 3)).copy()
        self.att = np.broadcast_to(np.asarray(attitude, dtype=np.float64), (self.num_envs, 3)).copy()
        self.vel = np.zeros((self.num_envs, 3))
        self._draw_slot(slice(None))

    # ----------------------------------------------------------------- step
    def step(self, action: NDArray) -> tuple[NDArray, NDArray, NDArray, SlotInfo]:
        """Advance every environment by one slot. Returns (reward, terminated, truncated, info)."""
        c = self.config
        accel_cmd, phase, amp, d_att = decode_action(action, c)
        if accel_cmd.shape[0] != self.num_envs:
            raise ActionError(f"expected {self.num_envs} actions, got {accel_cmd.shape[0]}")
        if amp is None:
            refl = ph.effective_reflection_from_phases(phase, self.cos_theta, c.angle_dependent_reflection)
        else:
            refl = ph.effective_reflection(amp * np.exp(1j * phase), self.cos_theta, c.angle_dependent_reflection)
        gains = ph.cascaded_gains(self.channels, refl)
        rates = ph.pair_rates(gains, self.pairing, c.tx_power_w, c.noise_w)
        reward = rates.sum(axis=(-2, -1))
        accel = ph.feasible_acceleration(self.vel, accel_cmd, c.slot_s, c.v_max, c.a_max)
        e_slot = ph.slot_energy(self.vel, accel, c.slot_s, **self._power)
        self.pos, self.vel = ph.kinematic_step(self.pos, self.vel, accel, c.slot_s, self.low, self.high,
                                               self.users, c.safety_distance)
        if c.front_margin_deg is not None:  # the attitude safety layer, at the pose the slot's move reached
            d_att = ph.clear_attitude(self.att, d_att, self.pos, self.users, np.radians(c.front_margin_deg),
                                      c.attitude_step_rad)
        self.att = ph.accumulate_attitude(self.att, d_att)
        self.energy = self.energy + e_slot
        self.t = self.t + 1
        info = SlotInfo(reward, rates, self.pairing, self.cos_theta, accel, e_slot)
        terminated = self.energy >= c.energy_budget_j
        truncated = (self.t >= c.horizon) & ~terminated
        self._draw_slot(slice(None))
        # Debug-mode invariant (stripped by python -O): the incidence step just measured every
        # UAV-device distance, so checking the safety separation costs one comparison.
        assert np.all(self.dist >= c.safety_distance * (1.0 - 1e-9)), (
            f"UAV within {self.dist.min():.6f} m of a device (safety_distance {c.safety_distance} m)")
        return reward, terminated, truncated, info

    # ----------------------------------------------------------------- observation
    def observe(self) -> NDArray[np.float32]:
        """Order-1 observation ``(n, observation_dim)`` (layout in :data:`OBSERVATION_LAYOUT`)."""
        c = self.config
        n = self.num_envs
        lay = self._layout
        obs = np.empty((n, c.observation_dim), dtype=np.float32)
        obs[:, lay["position"]] = (self.pos - self._center) / self._half
        obs[:, lay["velocity"]] = self.vel / c.v_max
        obs[:, lay["attitude_sin"]] = np.sin(self.att)
        obs[:, lay["attitude_cos"]] = np.cos(self.att)
        h = self.channels.reshape(n, -1)
        obs[:, lay["channel_real"]] = h.real * self._chan_scale
        obs[:, lay["channel_imag"]] = h.imag * self._chan_scale
        obs[:, lay["pairing"]] = self.pairing.reshape(n, -1)
        obs[:, lay["energy_remaining"]] = np.clip(1.0 - self.energy / c.energy_budget_j, 0.0, 1.0)[:, None]
        obs[:, lay["time_fraction"]] = (self.t / c.horizon)[:, None]
        if c.observe_devices:
            obs[:, lay["devices"]] = device_observation(self.users, self.pos, self._device_scale)
        return obs


def device_scale(config: SystemConfig) -> float:
    """The one length (m) that scales the devices' offsets in the observation: the flight
    region's largest half-extent (20 m in the paper's hall). One length for the three axes,
    so that a device's norm in the observation orders devices as metres do."""
    return float(0.5 * np.max(np.asarray(config.region_high) - np.asarray(config.region_low)))


def device_observation(users: NDArray[np.float64], pos: NDArray[np.float64], scale: float) -> NDArray[np.float64]:
    """The devices as the UAV sees them: ``(q_k - q_U) / scale`` in the layout's order,
    flattened to ``(n, 3K)`` (docs/study.md, section 2). Relative, so that a hall moved as a
    whole looks the same from the same relative pose; in the layout's order, so that device
    ``k`` of this slice is device ``k`` of the channels and the pairing (an order-free policy
    reads the three together per device: :class:`uavris.agents.dt.encoders.DeviceSetEncoder`)."""
    rel = (users[None] - pos[:, None]) / scale  # (n, K, 3)
    return rel.reshape(len(pos), -1)


def uav_position(observations: NDArray, config: SystemConfig) -> NDArray[np.float64]:
    """The UAV's position (m), ``(..., 3)``, read back from observations ``(..., D)`` of ``config``."""
    lo, hi = np.asarray(config.region_low), np.asarray(config.region_high)
    lay = observation_layout(config)
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.asarray(observations, dtype=np.float64)[..., lay["position"]]


def devices_seen(observations: NDArray, config: SystemConfig) -> NDArray[np.float64]:
    """The devices' positions (m), ``(..., K, 3)``, read back from observations ``(..., D)`` of a
    system whose observation holds them (``observe_devices``): the UAV's position plus each
    device's offset (:func:`device_observation`)."""
    lay = observation_layout(config)
    if "devices" not in lay:
        raise ConfigError("the observation holds no devices: SystemConfig(observe_devices=True) gives them")
    obs = np.asarray(observations, dtype=np.float64)
    rel = obs[..., lay["devices"]].reshape(*obs.shape[:-1], -1, 3) * device_scale(config)
    return uav_position(obs, config)[..., None, :] + rel


def step_info(sim: BatchedSimulator, slot: SlotInfo | None) -> dict[str, NDArray]:
    """The environments' ``info`` after a reset (``slot`` None) or a step, one row per environment."""
    out: dict[str, NDArray] = {
        "position": sim.pos.copy(),
        "velocity": sim.vel.copy(),
        "attitude": sim.att.copy(),
        "energy_used": sim.energy.copy(),
        "energy_remaining": np.maximum(sim.config.energy_budget_j - sim.energy, 0.0),
        "slot": sim.t.copy(),
    }
    if slot is None:
        out["pairing"] = sim.pairing.copy()
        out["incidence_deg"] = np.degrees(np.arccos(np.clip(sim.cos_theta, -1, 1)))
    else:
        out.update(sum_rate=slot.reward.copy(), pair_rates=slot.pair_rates, pairing=slot.pairing,
                   incidence_deg=np.degrees(np.arccos(np.clip(slot.cos_theta, -1, 1))),
                   acceleration=slot.accel, slot_energy=slot.slot_energy)
    return out


def observation_layout(config: SystemConfig) -> dict[str, slice]:
    """Named slices of the observation vector."""
    return observation_slices(config.num_users, config.num_elements, config.observe_devices)


def observation_slices(num_users: int, num_elements: int, observe_devices: bool) -> dict[str, slice]:
    """Named slices of the observation of a system of ``num_users`` devices and ``num_elements``
    RIS elements (what :func:`observation_layout` reads off a configuration)."""
    K, N = num_users, num_elements
    sizes = [("position", 3), ("velocity", 3), ("attitude_sin", 3), ("attitude_cos", 3),
             ("channel_real", K * N), ("channel_imag", K * N), ("pairing", K * K),
             ("energy_remaining", 1), ("time_fraction", 1)]
    if observe_devices:  # last, so every other slice keeps its place
        sizes.append(("devices", 3 * K))
    out, start = {}, 0
    for name, size in sizes:
        out[name] = slice(start, start + size)
        start += size
    return out


def layout_as_lists(config: SystemConfig) -> dict[str, list[int]]:
    """The observation layout of ``config`` as ``{name: [start, stop]}`` (JSON-able, stored in files)."""
    return {name: [s.start, s.stop] for name, s in observation_layout(config).items()}


def stored_system(system: Any, layout: Any, where: str, error: type[Exception] = ConfigError) -> SystemConfig:
    """The system configuration a file (dataset, checkpoint) was made with, checked against the
    observation layout the current environment gives that system; ``error`` names the problem."""
    try:
        config = SystemConfig.from_dict(system)
    except (ConfigError, TypeError, ValueError, AttributeError) as e:
        raise error(f"{where}: stored system configuration is invalid ({str(e).splitlines()[0] if str(e) else e!r})"
                    ) from None
    current = layout_as_lists(config)
    if layout != current:
        raise error(f"{where}: observation layout {layout} differs from the current environment's {current}; "
                    "it was made by an incompatible version")
    return config


# Box-Muller on 32-bit halves bounds |w| by sqrt(-log(2^-33)): the NLoS draw is never larger.
MAX_NLOS_MAGNITUDE = float(np.sqrt(33.0 * np.log(2.0)))


def channel_observation_bound(config: SystemConfig) -> float:
    """Largest |Re h| or |Im h| of a scaled channel entry: the closest the UAV can come to a
    user (the flight region and the safety separation bound it) sets the path loss, the NLoS
    draw is bounded (above). The distance is floored at 0.1 m."""
    users = np.asarray(config.users)
    closest = np.clip(users, config.region_low, config.region_high)
    d_region = float(np.min(np.linalg.norm(users - closest, axis=1)))
    d_min = max(d_region, config.safety_distance, 0.1)
    k = config.rician_factor
    amp = (config.channel_ref_distance / d_min) ** (0.5 * config.pathloss_exponent)
    return amp * (np.sqrt(k / (k + 1)) + np.sqrt(1 / (k + 1)) * MAX_NLOS_MAGNITUDE)


def observation_bounds(config: SystemConfig) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Box bounds of the observation: channels within +-:func:`channel_observation_bound`,
    pairing and fractions in [0, 1], device offsets within the room seen from the flight
    region (scaled by :func:`device_scale`), everything else in [-1, 1]."""
    lay = observation_layout(config)
    low = np.full(config.observation_dim, -1.0, dtype=np.float32)
    high = np.ones(config.observation_dim, dtype=np.float32)
    bound = channel_observation_bound(config)
    for name in ("channel_real", "channel_imag"):
        low[lay[name]], high[lay[name]] = -bound, bound
    for name in ("pairing", "energy_remaining", "time_fraction"):
        low[lay[name]] = 0.0
    if config.observe_devices:  # any point of the room seen from any point of the flight region
        lo, hi, scale = np.asarray(config.region_low), np.asarray(config.region_high), device_scale(config)
        low[lay["devices"]] = np.tile((0.0 - hi) / scale, config.num_users)
        high[lay["devices"]] = np.tile((np.asarray(config.room) - lo) / scale, config.num_users)
    return low, high
