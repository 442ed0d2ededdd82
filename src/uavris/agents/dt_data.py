"""Expert trajectories for the Decision Transformer: collection, Minari storage, training windows.

- :func:`record_episodes` rolls any batch policy out on seeded episodes, all in one
  batched simulator, and keeps every trajectory tau (paper eq. 14): the observations S_t
  (plus the final one), the actions actually executed (clipped to [-1, 1]) and the rewards.
- :func:`returns_to_go` is the paper's eq. (15), R_hat_t = sum_{t' >= t} r(t'), computed from
  the stored rewards (never stored itself, so relabelling is automatic).
- :func:`select_elites` is the top-K selection of eq. (18), or its paired variant.
- :func:`write_dataset` / :func:`load_dataset` store trajectories as a Minari dataset (HDF5
  backend) and read them back with validation.
- :class:`TrainingWindows` samples context windows for L_OFF (eq. 16) and L_FT (eq. 19).

Dataset layout (a directory ``DIR``)::

    DIR/data/metadata.json   Minari metadata plus a "uavris" entry: format version, the
                             SystemConfig, the observation layout, obs/action sizes and
                             the phase control ("agent": full actions; "optimizer": the
                             6 motion entries, the phases being the optimiser's)
    DIR/data/main_data.hdf5  one group per episode: observations (T+1, obs_dim),
                             actions (T, act_dim), rewards, terminations, truncations;
                             attributes seed, scenario, expert, expert_algo

Minari reads it offline: ``minari.MinariDataset("DIR/data")``, or
``minari.load_dataset(ID)`` with ``MINARI_DATASETS_PATH`` set to DIR's parent, where ID is
the dataset id stored in the metadata (DIR's name, with ``-v0`` appended unless it ends in
``-vN``). Nothing is ever downloaded.

Normalisation (:func:`normalisation_from`): per-component state mean and standard deviation
over all stored states, the standard deviation floored at 0.1 (observation components are
of order 1 by construction; the floor keeps a component the experts barely vary, such as
a level attitude, from being blown up when it does vary in a new scenario), and the return
scale = the largest episode return, so that R_hat / scale lies in [0, 1] on the data.
"""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
import torch
from numpy.typing import NDArray

from uavris.agents.baselines import BatchPolicy
from uavris.agents.hybrid import PHASE_CONTROLS, action_dim_for, motion_of
from uavris.config import ConfigError, Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator, observation_bounds, observation_layout

if TYPE_CHECKING:
    from uavris.agents.dt_model import DTConfig

DATASET_FORMAT_VERSION = 1
STATE_STD_FLOOR = 0.1


class DatasetError(ValueError):
    """A dataset that is missing, malformed or was made for a different environment."""


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One episode tau (paper eq. 14) with where it came from."""

    observations: NDArray[np.float32]  # (T + 1, obs_dim): S_1 .. S_T and the final observation
    actions: NDArray[np.float32]  # (T, act_dim), as executed (clipped to [-1, 1])
    rewards: NDArray[np.float64]  # (T,) r(t), bps/Hz
    terminated: bool  # energy budget exhausted
    truncated: bool  # horizon reached
    scenario: str
    seed: int
    expert: str = ""
    expert_algo: str = ""

    @property
    def length(self) -> int:
        return int(self.rewards.shape[0])

    @property
    def episode_return(self) -> float:
        """sum_t r(t), the quantity eq. (18) ranks by."""
        return float(self.rewards.sum())


def returns_to_go(rewards: NDArray[np.floating]) -> NDArray[np.float64]:
    """R_hat_t = sum_{t' >= t} r(t') (paper eq. 15, undiscounted)."""
    r = np.asarray(rewards, dtype=np.float64)
    return np.cumsum(r[::-1])[::-1].copy()


ELITE_RULES: tuple[str, ...] = ("return", "paired")


def select_elites(trajectories: Sequence[Trajectory], k: int, rule: str = "return") -> list[Trajectory]:
    """The K elites, best first; ties keep collection order.

    ``rule="return"``: the K largest returns (paper eq. 18). ``rule="paired"``: the K largest
    returns relative to the mean return of the candidates with the same episode seed.
    Episodes with the same seed share every random draw (channels, pairings: common random
    numbers), so this difference measures what the actions did, not the luck of the draw
    (docs/model.md, departures).
    """
    if not 1 <= k <= len(trajectories):
        raise ValueError(f"k must be in [1, {len(trajectories)}], got {k}")
    if rule not in ELITE_RULES:
        raise ValueError(f"unknown elite rule {rule!r}; choose one of {', '.join(ELITE_RULES)}")
    score = np.array([tr.episode_return for tr in trajectories])
    if rule == "paired":
        seeds = np.array([tr.seed for tr in trajectories])
        for s in np.unique(seeds):
            group = seeds == s
            score[group] -= score[group].mean()
    order = sorted(range(len(trajectories)), key=lambda i: -score[i])
    return [trajectories[i] for i in order[:k]]


# ------------------------------------------------------------------------------ collection
def record_episodes(policy: BatchPolicy, config: SystemConfig, scenario: str | Scenario,
                    seeds: Sequence[int] | NDArray[np.integer], *, expert: str = "", expert_algo: str = "",
                    phase_control: str = "agent", batch_size: int = 256) -> list[Trajectory]:
    """Roll ``policy`` out on one episode per seed, ``batch_size`` episodes per simulator.

    Episode j is the one a single environment produces after ``reset(seed=seeds[j])``, as in
    :func:`uavris.agents.evaluation.evaluate`. Returns the trajectories in seed order. With
    ``phase_control="optimizer"`` the trajectories keep only the 6 motion entries of the
    executed actions (the phases were the optimiser's, a function of the state).
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    out: list[Trajectory] = []
    for start in range(0, len(seeds), batch_size):
        out.extend(_record_batch(policy, config, scenario, seeds[start:start + batch_size], expert, expert_algo,
                                 phase_control))
    return out


def _record_batch(policy: BatchPolicy, config: SystemConfig, scenario: str | Scenario, seeds: NDArray[np.int64],
                  expert: str, expert_algo: str, phase_control: str) -> list[Trajectory]:
    n, horizon = len(seeds), config.horizon
    motion_only = action_dim_for(config, phase_control) != config.action_dim
    sim = BatchedSimulator(config, scenario, n)
    sim.seed(seeds)
    sim.reset()
    obs_buf = np.zeros((n, horizon + 1, config.observation_dim), dtype=np.float32)
    act_buf = np.zeros((n, horizon, action_dim_for(config, phase_control)), dtype=np.float32)
    rew_buf = np.zeros((n, horizon))
    length = np.zeros(n, dtype=np.int64)
    terminated = np.zeros(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    obs = sim.observe()
    t = 0
    # All rows advance in lockstep; a finished row keeps stepping (the simulator has no
    # per-row pause) but nothing it does is recorded.
    while alive.any():
        action = np.clip(np.asarray(policy(obs, sim), dtype=np.float32), -1.0, 1.0)
        obs_buf[alive, t] = obs[alive]
        act_buf[alive, t] = (motion_of(action) if motion_only else action)[alive]
        reward, term, trunc, _ = sim.step(action)
        rew_buf[alive, t] = reward[alive]
        obs = sim.observe()
        ended = alive & (term | trunc)
        obs_buf[ended, t + 1] = obs[ended]
        length[ended] = t + 1
        terminated[ended] = term[ended]
        alive &= ~ended
        t += 1
    scen = sim.scenario.name
    return [Trajectory(obs_buf[i, :length[i] + 1].copy(), act_buf[i, :length[i]].copy(), rew_buf[i, :length[i]].copy(),
                       bool(terminated[i]), not bool(terminated[i]), scen, int(seeds[i]), expert, expert_algo)
            for i in range(n)]


# ------------------------------------------------------------------------------ normalisation
@dataclass(frozen=True)
class Normalisation:
    """State mean/std and return scale the model is trained and deployed with."""

    state_mean: NDArray[np.float64]
    state_std: NDArray[np.float64]
    return_scale: float


def normalisation_from(trajectories: Sequence[Trajectory], std_floor: float = STATE_STD_FLOOR) -> Normalisation:
    """Statistics of the states S_1..S_T of ``trajectories`` (see the module docstring)."""
    if not trajectories:
        raise DatasetError("no trajectories to compute normalisation statistics from")
    states = np.concatenate([tr.observations[:-1] for tr in trajectories]).astype(np.float64)
    returns = np.array([tr.episode_return for tr in trajectories])
    scale = float(returns.max()) if returns.max() > 0 else 1.0
    return Normalisation(states.mean(axis=0), np.maximum(states.std(axis=0), std_floor), scale)


def default_target_return(trajectories: Sequence[Trajectory], quantile: float = 0.9) -> float:
    """The documented default target return: the ``quantile`` of the episode returns."""
    return float(np.quantile([tr.episode_return for tr in trajectories], quantile))


# ------------------------------------------------------------------------------ training windows
class TrainingWindows:
    """All slots of a set of trajectories, ready to be cut into context windows.

    A window is the ``context`` slots ending at a slot chosen uniformly among all slots;
    near an episode's start it is left-padded, exactly as the history a deployed DT sees
    at that slot (:mod:`uavris.agents.dt_policy`). The loss covers every real slot of it.

    With ``whole_episodes`` (the banded DT, which reads episodes from slot 0) a sample is
    instead one whole episode chosen uniformly, left-padded to the longest episode.
    """

    def __init__(self, trajectories: Sequence[Trajectory], context: int, whole_episodes: bool = False) -> None:
        if not trajectories:
            raise DatasetError("no trajectories to train on")
        lengths = np.array([tr.length for tr in trajectories])
        self.whole_episodes = whole_episodes
        self.model_context = context
        self.context = int(lengths.max()) if whole_episodes else context
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        self.episode_end = starts + lengths - 1
        self.states = np.concatenate([tr.observations[:-1] for tr in trajectories]).astype(np.float32)
        self.actions = np.concatenate([tr.actions for tr in trajectories]).astype(np.float32)
        self.rtg = np.concatenate([returns_to_go(tr.rewards) for tr in trajectories]).astype(np.float32)
        self.timesteps = np.concatenate([np.arange(n) for n in lengths]).astype(np.int64)
        self.episode_start = np.repeat(starts, lengths)

    @classmethod
    def for_model(cls, trajectories: Sequence[Trajectory], model_config: DTConfig) -> TrainingWindows:
        """The samples a model of this :class:`~uavris.agents.dt_model.DTConfig` trains on."""
        return cls(trajectories, model_config.context, whole_episodes=model_config.attention == "banded")

    @property
    def num_slots(self) -> int:
        return int(self.rtg.shape[0])

    @property
    def samples_per_epoch(self) -> int:
        """Samples of one epoch: one window per slot, or, for whole episodes, ``context``
        draws per episode, so that an epoch predicts about as many actions either way (a
        window predicts ``context`` of them, an episode all of its slots)."""
        return len(self.episode_end) * self.model_context if self.whole_episodes else self.num_slots

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``batch_size`` windows: rtg (B, K), states (B, K, S), actions (B, K, A),
        timesteps (B, K), valid (B, K); padded entries are zero."""
        if self.whole_episodes:
            ends = self.episode_end[rng.integers(0, len(self.episode_end), batch_size)]
        else:
            ends = rng.integers(0, self.num_slots, batch_size)
        pos = ends[:, None] + np.arange(1 - self.context, 1)
        valid = pos >= self.episode_start[ends][:, None]
        idx = np.where(valid, pos, ends[:, None])
        pad = ~valid
        states, actions = self.states[idx], self.actions[idx]
        rtg, steps = self.rtg[idx], self.timesteps[idx]
        states[pad], actions[pad], rtg[pad], steps[pad] = 0.0, 0.0, 0.0, 0
        return {"returns_to_go": torch.from_numpy(rtg), "states": torch.from_numpy(states),
                "actions": torch.from_numpy(actions), "timesteps": torch.from_numpy(steps),
                "valid": torch.from_numpy(valid)}


# ------------------------------------------------------------------------------ Minari storage
@dataclass(frozen=True)
class ExpertDataset:
    """A loaded, validated dataset."""

    path: Path
    dataset_id: str
    system: SystemConfig
    trajectories: list[Trajectory]
    description: str
    phase_control: str = "agent"  # "optimizer": the actions are the 6 motion entries (strong track)

    @property
    def scenarios(self) -> list[str]:
        return sorted({tr.scenario for tr in self.trajectories})

    @property
    def num_slots(self) -> int:
        return sum(tr.length for tr in self.trajectories)


def layout_as_lists(config: SystemConfig) -> dict[str, list[int]]:
    """The observation layout of ``config`` as ``{name: [start, stop]}`` (JSON-able)."""
    return {name: [s.start, s.stop] for name, s in observation_layout(config).items()}


def dataset_id_for(path: Path) -> str:
    """Minari id of a dataset directory: its name, ``-v0`` appended unless it ends in ``-vN``."""
    name = re.sub(r"[^-_\w]", "_", path.name) or "uavris"
    return name if re.fullmatch(r"[-_\w]+-v\d+", name) else f"{name}-v0"


def write_dataset(path: str | Path, trajectories: Sequence[Trajectory], system: SystemConfig, *,
                  description: str = "", force: bool = False, phase_control: str = "agent") -> Path:
    """Write ``trajectories`` as a Minari dataset at ``path`` (see the module docstring).

    The dataset is built in a temporary sibling directory and renamed into place, so an
    interrupted write never leaves a half dataset. An existing dataset is replaced only
    with ``force``; a non-empty directory that is not a dataset is never touched.
    """
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer
    from minari.dataset.minari_storage import MinariStorage

    given = Path(path)
    path = given.absolute()  # Minari mis-joins relative paths when it sizes the dataset
    if not trajectories:
        raise DatasetError("no trajectories to write")
    if path.exists():
        if not (path / "data" / "metadata.json").exists() and any(path.iterdir()):
            raise DatasetError(f"{path} exists and is not a dataset; refusing to overwrite it")
        if not force:
            raise DatasetError(f"{path} already exists; pass --force to replace it")
    act_dim = action_dim_for(system, phase_control)
    for tr in trajectories:
        _check_trajectory(tr, system.observation_dim, act_dim, f"trajectory (seed {tr.seed})")
    tmp = path.parent / f".{path.name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        low, high = observation_bounds(system)
        storage = MinariStorage.new(tmp / "data", observation_space=gym.spaces.Box(low, high, dtype=np.float32),
                                    action_space=gym.spaces.Box(-1.0, 1.0, (act_dim,), dtype=np.float32),
                                    data_format="hdf5", jpeg_encoding=False)
        algos = sorted({tr.expert_algo for tr in trajectories if tr.expert_algo})
        storage.update_metadata({
            "dataset_id": dataset_id_for(path),
            "minari_version": minari.__version__,
            "algorithm_name": "+".join(algos) or "unknown",
            "description": description or "uavris expert trajectories",
            "uavris": {"format_version": DATASET_FORMAT_VERSION, "system": system.to_dict(),
                       "observation_layout": layout_as_lists(system), "observation_dim": system.observation_dim,
                       "action_dim": act_dim, "phase_control": phase_control},
        })
        storage.update_episodes(
            EpisodeBuffer(id=i, seed=tr.seed, observations=tr.observations, actions=tr.actions, rewards=tr.rewards,
                          terminations=_flag_last(tr.length, tr.terminated),
                          truncations=_flag_last(tr.length, tr.truncated))
            for i, tr in enumerate(trajectories))
        storage.update_episode_metadata(
            [{"scenario": tr.scenario, "expert": tr.expert, "expert_algo": tr.expert_algo} for tr in trajectories])
        if path.exists():
            old = path.parent / f".{path.name}.old"
            shutil.rmtree(old, ignore_errors=True)
            path.rename(old)
            tmp.rename(path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return given


def _flag_last(length: int, flag: bool) -> NDArray[np.bool_]:
    """Per-slot flags of an episode: ``flag`` at its last slot, False before."""
    out = np.zeros(length, dtype=bool)
    out[-1] = flag
    return out


def _data_dir(path: Path) -> Path:
    if (path / "data" / "metadata.json").exists():
        return path / "data"
    if (path / "metadata.json").exists():
        return path
    raise DatasetError(f"{path} is not a Minari dataset (no data/metadata.json)")


def load_dataset(path: str | Path) -> ExpertDataset:
    """Read and validate a dataset written by :func:`write_dataset`.

    Raises :class:`DatasetError` with one line naming the problem: not a dataset, not
    readable by Minari, missing uavris metadata or per-episode fields, wrong array
    shapes, non-finite values, or an observation layout different from the one the
    current environment produces for the stored system configuration.
    """
    import minari

    path = Path(path)
    data_dir = _data_dir(path).absolute()
    try:
        ds = minari.MinariDataset(data_dir)
        meta = ds.storage.metadata
    except (ValueError, KeyError, OSError, AssertionError, TypeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path} is not a readable Minari dataset ({_one_line(e)})") from None
    info = meta.get("uavris")
    if not isinstance(info, dict):
        raise DatasetError(f"{path} was not written by uavris collect (no 'uavris' metadata)")
    for key in ("format_version", "system", "observation_layout", "observation_dim", "action_dim"):
        if key not in info:
            raise DatasetError(f"{path}: the uavris metadata is missing the field {key!r}")
    if info["format_version"] != DATASET_FORMAT_VERSION:
        raise DatasetError(f"{path} has dataset format {info['format_version']!r}; "
                           f"this uavris reads format {DATASET_FORMAT_VERSION}")
    try:
        system = SystemConfig.from_stored(info["system"])
    except (ConfigError, TypeError, ValueError) as e:
        raise DatasetError(f"{path}: stored system configuration is invalid ({_one_line(e)})") from None
    current = layout_as_lists(system)
    if info["observation_layout"] != current:
        raise DatasetError(f"{path}: observation layout {info['observation_layout']} differs from the current "
                           f"environment's {current}; re-collect the dataset")
    phase_control = info.get("phase_control", "agent")  # datasets from before the field: full actions
    if phase_control not in PHASE_CONTROLS:
        raise DatasetError(f"{path}: unknown phase control {phase_control!r} in the uavris metadata")
    obs_dim, act_dim = system.observation_dim, action_dim_for(system, phase_control)
    if info["observation_dim"] != obs_dim or info["action_dim"] != act_dim \
            or ds.observation_space.shape != (obs_dim,) or ds.action_space.shape != (act_dim,):
        raise DatasetError(f"{path}: observation/action sizes {ds.observation_space.shape}/{ds.action_space.shape} "
                           f"do not match the environment's ({obs_dim},)/({act_dim},)")
    if ds.total_episodes < 1:
        raise DatasetError(f"{path} holds no episodes")
    trajectories = []
    try:
        episodes = ds.storage.get_episodes(range(ds.total_episodes))
        metas = ds.storage.get_episode_metadata(range(ds.total_episodes))
        for i, (ep, em) in enumerate(zip(episodes, metas)):
            for key in ("scenario", "expert", "seed"):
                if key not in em:
                    raise DatasetError(f"{path}: episode {i} is missing the metadata field {key!r}")
            rewards = np.asarray(ep["rewards"], dtype=np.float64)
            term, trunc = np.asarray(ep["terminations"]), np.asarray(ep["truncations"])
            tr = Trajectory(np.asarray(ep["observations"]), np.asarray(ep["actions"]), rewards,
                            bool(term[-1]) if term.size else False, bool(trunc[-1]) if trunc.size else False,
                            str(em["scenario"]), int(em["seed"]), str(em["expert"]), str(em.get("expert_algo", "")))
            _check_trajectory(tr, obs_dim, act_dim, f"{path}: episode {i}")
            trajectories.append(tr)
    except (KeyError, ValueError, OSError, TypeError, AssertionError, IndexError) as e:
        if isinstance(e, DatasetError):
            raise
        raise DatasetError(f"{path}: episode data is unreadable ({_one_line(e)})") from None
    return ExpertDataset(path, str(meta.get("dataset_id", "")), system, trajectories, str(meta.get("description", "")),
                         phase_control)


def _check_trajectory(tr: Trajectory, obs_dim: int, act_dim: int, where: str) -> None:
    t = tr.rewards.shape[0] if tr.rewards.ndim == 1 else -1
    if t < 1:
        raise DatasetError(f"{where}: rewards must be a non-empty vector, got shape {tr.rewards.shape}")
    if tr.observations.shape != (t + 1, obs_dim):
        raise DatasetError(f"{where}: observations have shape {tr.observations.shape}, expected ({t + 1}, {obs_dim})")
    if tr.actions.shape != (t, act_dim):
        raise DatasetError(f"{where}: actions have shape {tr.actions.shape}, expected ({t}, {act_dim})")
    for name, arr in (("observations", tr.observations), ("actions", tr.actions), ("rewards", tr.rewards)):
        if not np.all(np.isfinite(arr)):
            raise DatasetError(f"{where}: {name} contain NaN or inf")


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__
