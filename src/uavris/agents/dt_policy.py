"""Deploying a Decision Transformer: a stateful batch policy conditioned on a target return.

Zero-shot deployment (paper Sec. IV-D): the first action of an episode is predicted from
the target return R_hat_1 and the first state; after each slot the return-to-go is
updated as R_hat_{t+1} = R_hat_t - r(t), and the last ``context`` slots of (R_hat, S, A)
form the next input (window layout), or, for a banded DT, the three new tokens of the slot
are added to the model's key/value cache (:class:`uavris.agents.dt_model.KVCache`). With
``noise_sigma`` > 0 the executed action is A_t = clip(A_hat_t + eps_t, -1, 1),
eps_t ~ N(0, sigma^2 I) (Algorithm 1, stage 2), and the history holds the executed action,
which is also what the trajectory records.

:class:`DTBatchPolicy` is a batch policy ``policy(obs, sim) -> actions`` like every other
policy of :mod:`uavris.agents`, so it is scored by :func:`uavris.agents.evaluation.evaluate`
on the same seeded episodes. All rows of the batch advance together with one forward
pass per slot. A row whose slot counter ``sim.t`` is 0 starts a new episode.

The policy interface passes no reward, so the policy recomputes r(t) of the slot it just
acted in from the simulator state it saw then (channels, incidence, pairing) and the
action it returned, with the very calls :meth:`BatchedSimulator.step` makes
(:func:`slot_reward`; a test checks it against the simulator's reward).

Strong track (``phase_control="optimizer"``): the model predicts the 6 motion entries and
the per-slot phase optimiser sets the phases (:func:`uavris.agents.hybrid.full_action`); the
history holds the motion actions, the reward is that of the full action executed.

Default target return: the checkpoint's ``target_return``, set at pre-training to the
0.9 quantile of the dataset's episode returns (a high but attained return: conditioning
far above anything in the data asks the model to extrapolate). Callers may override it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.agents.dt_model import DecisionTransformer, load_dt
from uavris.agents.hybrid import MOTION_DIM, check_phase_control, full_action
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator, decode_action


def slot_reward(channels: NDArray[np.complex128], cos_theta: NDArray[np.float64], pairing: NDArray[np.float64],
                action: NDArray[np.float32], config: SystemConfig) -> NDArray[np.float64]:
    """r(t) paid for ``action`` in the slot with channels H(t), incidence cosines and pairing P(t)."""
    _, phase, amp, _ = decode_action(action, config)
    if amp is None:
        refl = ph.effective_reflection_from_phases(phase, cos_theta, config.angle_dependent_reflection)
    else:
        refl = ph.effective_reflection(amp * np.exp(1j * phase), cos_theta, config.angle_dependent_reflection)
    gains = ph.cascaded_gains(channels, refl)
    return ph.pair_rates(gains, pairing, config.tx_power_w, config.noise_w).sum(axis=(-2, -1))


class DTBatchPolicy:
    """A DT acting on a batch of episodes; see the module docstring.

    Args:
        model: the Decision Transformer (put in eval mode when it acts: no dropout).
        target_return: R_hat_1 of every episode.
        noise_sigma: standard deviation of the Gaussian exploration noise (0: deterministic).
        seed: seed of the noise.
        phase_control: ``"agent"`` (the model sets every action entry) or ``"optimizer"``
            (the model sets the motion, the optimiser the phases).
    """

    def __init__(self, model: DecisionTransformer, target_return: float, noise_sigma: float = 0.0,
                 seed: int | None = None, phase_control: str = "agent") -> None:
        if not np.isfinite(target_return):
            raise ValueError(f"target_return must be finite, got {target_return!r}")
        if noise_sigma < 0:
            raise ValueError(f"noise_sigma must be >= 0, got {noise_sigma!r}")
        check_phase_control(phase_control)
        if phase_control == "optimizer" and model.cfg.act_dim != MOTION_DIM:
            raise ValueError(f"phase_control 'optimizer' needs a model of the {MOTION_DIM} motion entries, "
                             f"this one predicts {model.cfg.act_dim}")
        self.phase_control = phase_control
        self.model = model
        self.target_return = float(target_return)
        self.noise_sigma = float(noise_sigma)
        self._rng = np.random.default_rng(seed)
        self._sim: BatchedSimulator | None = None
        self._n = 0
        self._pending: tuple[Any, ...] | None = None

    # ------------------------------------------------------------------ history
    def begin(self, n: int) -> None:
        """Allocate the history of ``n`` rows, all at the start of an episode."""
        self._n = n
        self._history = _CachedHistory(self.model, n) if self.model.cfg.band is not None else _Window(self.model, n)
        self.remaining = np.full(n, self.target_return)  # R_hat_t of the current slot, float64
        self._pending = None

    def reset_rows(self, rows: NDArray[np.bool_] | NDArray[np.intp]) -> None:
        """Start new episodes in ``rows``."""
        self._history.reset(rows)
        self.remaining[rows] = self.target_return

    def act(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """Append S_t with the current R_hat_t and return the action of every row."""
        if self.model.training:  # acting is always deterministic apart from the explicit noise
            self.model.eval()
        with torch.inference_mode():
            pred = self._history.predict(self.remaining, obs)
        if self.noise_sigma > 0:
            pred = pred + self._rng.normal(0.0, self.noise_sigma, pred.shape)
        return np.clip(pred, -1.0, 1.0).astype(np.float32)

    def record(self, actions: NDArray[np.float32], rewards: NDArray[np.float64]) -> None:
        """Store the executed A_t and update R_hat_{t+1} = R_hat_t - r(t)."""
        self._history.record(actions)
        self.remaining = self.remaining - rewards

    # ------------------------------------------------------------------ batch-policy interface
    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        n = obs.shape[0]
        fresh = np.asarray(sim.t) == 0
        if sim is not self._sim or n != self._n:
            if not fresh.all():
                raise ValueError("a DT policy must see its episodes from slot 0 (sim.t == 0 for every row)")
            self.begin(n)
            self._sim = sim
        elif self._pending is not None:
            channels, cos_theta, pairing, action, executed = self._pending
            self.record(action, slot_reward(channels, cos_theta, pairing, executed, sim.config))
            if fresh.any():
                self.reset_rows(fresh)
        elif not fresh.all():
            raise ValueError("a DT policy lost track of its episodes (called twice without a step?)")
        action = self.act(obs)
        executed = full_action(sim, action) if self.phase_control == "optimizer" else action
        # Copies: a partial reset may write into the simulator's current arrays in place.
        self._pending = (sim.channels.copy(), sim.cos_theta.copy(), sim.pairing.copy(), action, executed)
        return executed


class _Window:
    """The last ``context`` slots of every row, re-read by the model at each slot (window layout)."""

    def __init__(self, model: DecisionTransformer, n: int) -> None:
        k, c = model.cfg.context, model.cfg
        self.model = model
        self.rtg = np.zeros((n, k), dtype=np.float32)
        self.states = np.zeros((n, k, c.state_dim), dtype=np.float32)
        self.actions = np.zeros((n, k, c.act_dim), dtype=np.float32)
        self.steps = np.zeros((n, k), dtype=np.int64)
        self.valid = np.zeros((n, k), dtype=bool)
        self.filled = np.zeros(n, dtype=np.int64)
        self.t = np.zeros(n, dtype=np.int64)

    def reset(self, rows: NDArray[np.bool_] | NDArray[np.intp]) -> None:
        for buf in (self.rtg, self.states, self.actions, self.steps):
            buf[rows] = 0
        self.valid[rows] = False
        self.filled[rows] = 0
        self.t[rows] = 0

    def predict(self, remaining: NDArray[np.float64], obs: NDArray[np.float32]) -> NDArray[np.float32]:
        for buf in (self.rtg, self.states, self.actions, self.steps, self.valid):
            buf[:, :-1] = buf[:, 1:]
        self.rtg[:, -1] = remaining
        self.states[:, -1] = obs
        self.actions[:, -1] = 0.0  # A_t is not known yet; the model never reads it
        self.steps[:, -1] = self.t
        self.valid[:, -1] = True
        self.filled = np.minimum(self.filled + 1, self.model.cfg.context)
        # When every row is early in its episode the leading columns are padding for all
        # rows: drop them (exact, and the forward pass gets shorter).
        sl = slice(self.model.cfg.context - int(self.filled.max()), None)
        return self.model(torch.from_numpy(self.rtg[:, sl]), torch.from_numpy(self.states[:, sl]),
                          torch.from_numpy(self.actions[:, sl]), torch.from_numpy(self.steps[:, sl]),
                          torch.from_numpy(self.valid[:, sl]), last_only=True).numpy()

    def record(self, actions: NDArray[np.float32]) -> None:
        self.actions[:, -1] = actions
        self.t += 1


class _CachedHistory:
    """Banded layout: the model's key/value cache plus A_{t-1}; three new tokens per slot."""

    def __init__(self, model: DecisionTransformer, n: int) -> None:
        self.model = model
        self.cache = model.new_cache(n)
        self.prev_action = np.zeros((n, model.cfg.act_dim), dtype=np.float32)  # read only where t > 0
        self.t = np.zeros(n, dtype=np.int64)

    def reset(self, rows: NDArray[np.bool_] | NDArray[np.intp]) -> None:
        self.cache.reset(rows)
        self.t[rows] = 0

    def predict(self, remaining: NDArray[np.float64], obs: NDArray[np.float32]) -> NDArray[np.float32]:
        return self.model.step(self.cache, torch.from_numpy(remaining.astype(np.float32)),
                               torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32)),
                               torch.from_numpy(self.prev_action), torch.from_numpy(self.t)).numpy()

    def record(self, actions: NDArray[np.float32]) -> None:
        self.prev_action = np.asarray(actions, dtype=np.float32).copy()
        self.t += 1


def dt_policy_from_checkpoint(directory: str | Path, target_return: float | None = None, noise_sigma: float = 0.0,
                              seed: int | None = None) -> tuple[DTBatchPolicy, dict[str, Any]]:
    """Load a checkpoint directory as a deterministic (or noisy) batch policy; returns it and
    the checkpoint's metadata. ``target_return`` defaults to the checkpoint's."""
    model, meta = load_dt(directory)
    target = meta.get("target_return") if target_return is None else target_return
    if target is None:
        raise ValueError(f"{directory} stores no target return; pass one")
    return DTBatchPolicy(model, float(target), noise_sigma, seed, meta.get("phase_control", "agent")), meta
