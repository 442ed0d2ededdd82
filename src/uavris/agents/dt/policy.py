"""Deploying a Decision Transformer: a stateful batch policy conditioned on a target return.

Lives here: :class:`DTBatchPolicy`, :class:`DTEnsemble` (several DTs, one mean action) and
:func:`load_dt_policy`, the one way a DT is loaded to act. Not here: the
model (:mod:`.model`) and the rollout loop that drives it (:func:`uavris.env.rollout.rollout`).

Zero-shot deployment (paper Sec. IV-D): the first action of an episode is predicted from
the target return R_hat_1 and the first state; after each slot the return-to-go is
updated as R_hat_{t+1} = R_hat_t - r(t), and the last ``context`` slots of (R_hat, S, A)
form the next input (window layout), or, for a banded DT, the three new tokens of the slot
are added to the model's key/value cache (:class:`uavris.agents.dt.cache.KVCache`). With
``noise_sigma`` > 0 the executed action is A_t = clip(A_hat_t + eps_t, -1, 1),
eps_t ~ N(0, sigma^2 I) (Algorithm 1, stage 2), and the history holds the executed action,
which is also what the trajectory records.

:class:`DTBatchPolicy` is an episodic policy (:class:`uavris.agents.policy.EpisodicPolicy`):
the rollout loop tells it when a batch of episodes starts (:meth:`~DTBatchPolicy.begin`) and
hands it every slot's actions and rewards (:meth:`~DTBatchPolicy.record`), so it is scored
by :func:`uavris.agents.evaluation.evaluate` on the same seeded episodes as every other
policy. All rows advance together with one forward pass per slot.

Strong track (``phase_control="optimizer"``): the model predicts the 6 motion entries and
the per-slot phase optimiser sets the phases (:mod:`uavris.env.wrappers`); the history holds
the motion actions, the reward is that of the full action executed.

Default target return: the checkpoint's ``target_return``, set at pre-training to the
0.9 quantile of the dataset's episode returns (a high but attained return: conditioning
far above anything in the data asks the model to extrapolate). Callers may override it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from uavris.agents.dt.checkpoint import checkpoint_system, dt_model_dir, load_dt
from uavris.agents.dt.goals import GOAL_DIM, FixedGoals, GoalSource, first_goals, goal_offsets
from uavris.agents.dt.model import DecisionTransformer
from uavris.config import Scenario, SystemConfig, scenario_at
from uavris.env.wrappers import MOTION_DIM, check_phase_control
from uavris.errors import CheckpointError, ConfigError, UavrisError


class DTBatchPolicy:
    """A DT acting on a batch of episodes; see the module docstring.

    Args:
        model: the Decision Transformer (put in eval mode when it acts: no dropout).
        target_return: R_hat_1 of every episode.
        noise_sigma: standard deviation of the Gaussian exploration noise (0: deterministic).
        seed: seed of the noise.
        phase_control: ``"agent"`` (the model sets every action entry) or ``"optimizer"``
            (the model sets the motion, the optimiser the phases).
        goals: where a goal-conditioned model is told to go (:mod:`.goals`), asked at each
            batch's first slot; ``system``: the system the observations are of (the goal's
            offsets are read against it; :meth:`for_system` sets it).
    """

    def __init__(self, model: DecisionTransformer, target_return: float, noise_sigma: float = 0.0,
                 seed: int | None = None, phase_control: str = "agent", goals: GoalSource | None = None,
                 system: SystemConfig | None = None) -> None:
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
        self._seed = seed
        self._rng = np.random.default_rng(seed)
        self.goals, self.system = goals, system
        self.episode_goals: NDArray[np.float64] | None = None  # (n, 3) m, this batch's (a goal-conditioned model)

    @property
    def observation_dim(self) -> int:
        """Entries of the observation the model reads (:func:`uavris.agents.policy.check_policy_fits`)."""
        return self.model.cfg.state_dim

    def for_system(self, system: SystemConfig) -> DTBatchPolicy:
        """This policy in a system of another number of devices (the same RIS, device positions
        observed): the same weights read it if the model has the device-set encoder
        (:meth:`~uavris.agents.dt.model.DecisionTransformer.for_devices`); ``self`` where
        nothing differs or the model cannot (the caller's fit check then says why)."""
        cfg = self.model.cfg
        model = self.model
        if not (system.observation_dim == cfg.state_dim or cfg.state_encoder != "devices" or not system.observe_devices
                or system.num_elements != cfg.elements):
            model = self.model.for_devices(system.num_users)
        elif not cfg.goal or system == self.system:
            return self
        return DTBatchPolicy(model, self.target_return, self.noise_sigma, self._seed, self.phase_control, self.goals,
                             system)

    def with_goals(self, goals: GoalSource, noise_sigma: float | None = None, seed: int | None = None
                   ) -> DTBatchPolicy:
        """This policy told where to go by ``goals`` (a goal-conditioned model), with other noise
        if given; the same model (its weights shared)."""
        if not self.model.cfg.goal:
            raise ValueError("only a goal-conditioned DT (DTConfig.goal) is told a goal")
        return DTBatchPolicy(self.model, self.target_return, self.noise_sigma if noise_sigma is None else noise_sigma,
                             self._seed if seed is None else seed, self.phase_control, goals, self.system)

    # ------------------------------------------------------------------ history
    def begin(self, n: int) -> None:
        """Allocate the history of ``n`` rows, all at the start of an episode."""
        self._n = n
        self._history = _CachedHistory(self.model, n) if self.model.cfg.band is not None else _Window(self.model, n)
        self.remaining = np.full(n, self.target_return)  # R_hat_t of the current slot, float64
        self.episode_goals = None

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """Append S_t with the current R_hat_t and return the action of every row (motion only
        under the optimiser). A batch of another size than the last one starts anew (:meth:`begin`)."""
        if getattr(self, "_n", None) != obs.shape[0]:
            self.begin(obs.shape[0])
        if self.model.training:  # acting is always deterministic apart from the explicit noise
            self.model.eval()
        offsets = None
        if self.model.cfg.goal:
            if self.goals is None or self.system is None:
                raise ValueError("a goal-conditioned DT acts only when told its goals and its system "
                                 "(DTBatchPolicy(goals=..., system=...), or for_system)")
            if self.episode_goals is None:  # the batch's first slot: where each episode goes
                self.episode_goals = first_goals(self.goals, obs, self.system)
            offsets = goal_offsets(obs, self.episode_goals, self.system)
        with torch.inference_mode():
            pred = self._history.predict(self.remaining, obs, offsets)
        if self.noise_sigma > 0:
            pred = pred + self._rng.normal(0.0, self.noise_sigma, pred.shape)
        return np.clip(pred, -1.0, 1.0).astype(np.float32)

    def record(self, actions: NDArray[np.float32], rewards: NDArray[np.float64]) -> None:
        """Store the executed A_t and update R_hat_{t+1} = R_hat_t - r(t)."""
        self._history.record(actions)
        self.remaining = self.remaining - rewards


class DTEnsemble:
    """Several pre-trained DTs acting as one: the mean of their actions (each model's history
    holds the executed mean action and the same returns). Models of several pre-training seeds
    fail in different halls (docs/study.md section 2); their mean action is one controller
    whose failures do not move with the seed. An episodic batch policy like :class:`DTBatchPolicy`."""

    def __init__(self, members: list[DTBatchPolicy]) -> None:
        if not members:
            raise ValueError("an ensemble needs at least one DT")
        controls = {m.phase_control for m in members}
        dims = {(m.model.cfg.state_dim, m.model.cfg.act_dim) for m in members}
        if len(controls) != 1 or len(dims) != 1:
            raise ValueError("the DTs of an ensemble must read the same observation and set the same actions")
        self.members = members
        self.phase_control = members[0].phase_control

    @property
    def observation_dim(self) -> int:
        return self.members[0].observation_dim

    def for_system(self, system: SystemConfig) -> DTEnsemble:
        """Every member in ``system`` (:meth:`DTBatchPolicy.for_system`)."""
        return DTEnsemble([m.for_system(system) for m in self.members])

    def begin(self, n: int) -> None:
        for m in self.members:
            m.begin(n)

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        # Summed in a fixed order, so the same models give the same action whatever else runs.
        total = self.members[0](obs).astype(np.float64)
        for m in self.members[1:]:
            total += m(obs)
        return (total / len(self.members)).astype(np.float32)

    def record(self, actions: NDArray[np.float32], rewards: NDArray[np.float64]) -> None:
        for m in self.members:
            m.record(actions, rewards)


def _tensor(x: np.ndarray, model: DecisionTransformer) -> torch.Tensor:
    # On the CPU .to() returns the same tensor: no copy, and the numbers stay bit-identical.
    return torch.from_numpy(x).to(model.return_scale.device)


def _numpy(t: torch.Tensor) -> NDArray[np.float32]:
    return t.cpu().numpy()


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
        self.goals = np.zeros((n, k, GOAL_DIM), dtype=np.float32)  # the goal's offsets (a goal-conditioned model)
        self.filled = np.zeros(n, dtype=np.int64)
        self.t = np.zeros(n, dtype=np.int64)

    def predict(self, remaining: NDArray[np.float64], obs: NDArray[np.float32],
                offsets: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
        for buf in (self.rtg, self.states, self.actions, self.steps, self.valid, self.goals):
            buf[:, :-1] = buf[:, 1:]
        if offsets is not None:
            self.goals[:, -1] = offsets
        self.rtg[:, -1] = remaining
        self.states[:, -1] = obs
        self.actions[:, -1] = 0.0  # A_t is not known yet; the model never reads it
        self.steps[:, -1] = self.t
        self.valid[:, -1] = True
        self.filled = np.minimum(self.filled + 1, self.model.cfg.context)
        # When every row is early in its episode the leading columns are padding for all
        # rows: drop them (exact, and the forward pass gets shorter).
        sl = slice(self.model.cfg.context - int(self.filled.max()), None)
        m = self.model
        goals = _tensor(self.goals[:, sl], m) if offsets is not None else None
        return _numpy(m(_tensor(self.rtg[:, sl], m), _tensor(self.states[:, sl], m), _tensor(self.actions[:, sl], m),
                        _tensor(self.steps[:, sl], m), _tensor(self.valid[:, sl], m), last_only=True, goals=goals))

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

    def predict(self, remaining: NDArray[np.float64], obs: NDArray[np.float32],
                offsets: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
        m = self.model
        return _numpy(m.step(self.cache, _tensor(remaining.astype(np.float32), m),
                             _tensor(np.ascontiguousarray(obs, dtype=np.float32), m),
                             _tensor(self.prev_action, m), _tensor(self.t, m),
                             None if offsets is None else _tensor(np.ascontiguousarray(offsets), m)))

    def record(self, actions: NDArray[np.float32]) -> None:
        self.prev_action = np.asarray(actions, dtype=np.float32).copy()
        self.t += 1


@dataclass(frozen=True)
class LoadedDT:
    """A DT model directory as a policy, with where it comes from."""

    policy: DTBatchPolicy
    system: SystemConfig  # the system it was trained (fine-tuned) on
    scenario: Scenario | None  # a fine-tuned model's scenario; None for a pre-trained one
    meta: dict[str, Any]  # its model.json
    directory: Path  # the model directory (a run directory stands for its final or latest model)


def load_dt_policy(path: str | Path, target_return: float | None = None, noise_sigma: float = 0.0,
                   seed: int | None = None, device: str = "cpu") -> LoadedDT:
    """The one loader of a Decision Transformer: a DT run or model directory
    (:func:`~.checkpoint.dt_model_dir`) as a deterministic (or, with ``noise_sigma``, noisy)
    batch policy on the torch ``device``, conditioned on ``target_return`` (default: the
    checkpoint's), with the system and scenario it was made for."""
    model_dir = dt_model_dir(path)
    if model_dir is None:
        raise UavrisError(f"{path} is not a DT model directory (no model.json)")
    model, meta = load_dt(model_dir, device)
    target = meta.get("target_return") if target_return is None else target_return
    if target is None:
        raise CheckpointError(f"{model_dir} stores no target return; pass one (--target-return)")
    # a goal-conditioned model fine-tuned in a hall keeps the place it chose there (its "goal")
    goals = FixedGoals(meta["goal"]) if model.cfg.goal and meta.get("goal") is not None else None
    policy = DTBatchPolicy(model, float(target), noise_sigma, seed, meta.get("phase_control", "agent"), goals)
    name = meta.get("scenario")
    try:
        scenario = None if name is None else scenario_at(str(name), meta.get("start"))
    except ConfigError as e:
        raise CheckpointError(f"{model_dir}: stored scenario is invalid ({e})") from None
    return LoadedDT(policy, checkpoint_system(meta, model_dir), scenario, meta, model_dir)
