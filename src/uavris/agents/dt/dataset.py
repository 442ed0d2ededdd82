"""Expert datasets on disk: Minari (HDF5 backend), read back with validation.

Lives here: :func:`write_dataset`, :func:`load_dataset`, :class:`ExpertDataset`. Not here:
what a trajectory is and how the model trains on it (:mod:`.trajectories`), Minari's own calls
(:mod:`.minari_files`, imported only where a dataset's files are written or read).

Dataset layout (a directory ``DIR``)::

    DIR/data/metadata.json   Minari metadata plus a "uavris" entry: format version, the
                             SystemConfig, the observation layout, obs/action sizes and
                             the phase control ("agent": full actions; "optimizer": the
                             6 motion entries, the phases being the optimiser's);
                             env_spec and eval_env_spec: uavris/UavRisD2D-v1 with kwargs
                             config (SystemConfig.to_dict()) and scenario (a name)
    DIR/data/main_data.hdf5  one group per episode: observations (T+1, obs_dim),
                             actions (T, act_dim), rewards, terminations, truncations;
                             attributes seed, scenario, expert, expert_algo

Minari reads it offline: ``minari.MinariDataset("DIR/data")``, or ``minari.load_dataset(ID)``
where ID is the dataset id stored in the metadata and DIR sits at
``$MINARI_DATASETS_PATH/ID`` (Minari's own layout). Nothing is ever downloaded. The id is
derived from DIR's name (:func:`dataset_id_for`): ``uavris/<name>-vN`` for datasets from
``uavris collect``; without a namespace for datasets written before ids had one, or by
:func:`write_dataset` without ``namespace``.

``dataset.recover_environment()`` (and ``eval_env=True``, the same environment) gives
``uavris/UavRisD2D-v1`` with the dataset's system in the dataset's recorded scenario, the
first trajectory's unless the writer named one (``collect``: the first expert's). An episode's
own scenario is in its metadata. Under phase control "optimizer" that environment still
takes full actions, the dataset's being the 6 motion entries (``optimised_action`` adds the
phases).
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

from uavris.agents.dt.trajectories import Trajectory
from uavris.config import SCENARIOS, Scenario, SystemConfig, float_tuple, get_scenario, scenario_at
from uavris.env import ENV_ID
from uavris.env.simulator import layout_as_lists, observation_bounds, stored_system
from uavris.env.wrappers import PHASE_CONTROLS, action_dim_for
from uavris.errors import ConfigError, DatasetError
from uavris.io import contents, replace_folder

DATASET_FORMAT_VERSION = 2  # 2: the environment spec and the phase control always recorded
DATASET_NAMESPACE = "uavris"


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


def dataset_id_for(path: Path, namespace: str | None = None) -> str:
    """Minari id of a dataset directory: its name, ``-v0`` appended unless it ends in ``-vN``.

    With ``namespace``, ``namespace/name-vN`` with the name lower-cased and runs of other
    characters than ``a-z0-9`` made one ``-`` (``runs/Experts_A`` -> ``uavris/experts-a-v0``).
    Without, the id of datasets from before namespaces, unchanged.
    """
    if namespace is None:
        name = re.sub(r"[^-_\w]", "_", path.name) or "uavris"
        return name if re.fullmatch(r"[-_\w]+-v\d+", name) else f"{name}-v0"
    name = re.sub(r"[^a-z0-9]+", "-", path.name.lower()).strip("-") or "experts"
    if not re.fullmatch(r"[a-z0-9-]+-v\d+", name):
        name += "-v0"
    return f"{namespace}/{name}"


def env_spec_for(system: SystemConfig, scenario: str | Scenario):
    """The registered env's spec with the kwargs that rebuild ``system`` in ``scenario``.

    The kwargs are JSON-native (Minari stores the spec as JSON) and survive the round trip
    exactly; the registered entry point takes the config as a dict. A named scenario is
    recorded by its name, any other (a layout's start) as ``{"name": ..., "start": [x, y, z]}``.
    """
    try:
        where = get_scenario(scenario)
        where.validate_for(system)
    except ConfigError as e:
        raise DatasetError(f"cannot record scenario {scenario!r} for the dataset's system ({_one_line(e)})") from None
    named = SCENARIOS.get(where.name) == where
    kwargs = {"config": system.to_dict(), "scenario": where.name if named else where.to_dict()}
    spec = dataclasses.replace(gym.spec(ENV_ID), kwargs=kwargs)
    if EnvSpec.from_json(spec.to_json()).kwargs != kwargs:
        raise DatasetError(f"the environment spec of {ENV_ID} does not survive JSON: {kwargs}")
    return spec


def check_dataset_target(path: Path, force: bool) -> None:
    """Refuse to write a dataset at ``path`` when something is there: a dataset without
    ``force``, and a non-empty directory that is not a dataset ever."""
    if path.exists():
        if not path.is_dir():
            raise DatasetError(f"{path} exists and is not a directory; refusing to overwrite it")
        if not (path / "data" / "metadata.json").exists() and contents(path):
            raise DatasetError(f"{path} exists and is not a dataset; refusing to overwrite it")
        if not force and contents(path):
            raise DatasetError(f"{path} already exists; pass --force to replace it")


def write_dataset(path: str | Path, trajectories: Sequence[Trajectory], system: SystemConfig, *,
                  description: str = "", force: bool = False, phase_control: str = "agent",
                  namespace: str | None = None) -> Path:
    """Write ``trajectories`` as a Minari dataset at ``path`` (see the module docstring).

    The id is :func:`dataset_id_for` ``(path, namespace)``. The environment spec recorded
    for ``recover_environment`` (and as the evaluation one) is ``system`` in the first
    trajectory's scenario: a spec holds one scenario while a dataset may mix several, each
    episode's being in its metadata.

    The dataset is built in a temporary sibling directory and renamed into place, so an
    interrupted write never leaves a half dataset. An existing dataset is replaced only
    with ``force``; a non-empty directory that is not a dataset is never touched.
    """
    given = Path(path)
    path = given.absolute()  # Minari mis-joins relative paths when it sizes the dataset
    if not trajectories:
        raise DatasetError("no trajectories to write")
    check_dataset_target(path, force)
    act_dim = action_dim_for(system, phase_control)
    for tr in trajectories:
        _check_trajectory(tr, system.observation_dim, act_dim, f"trajectory (seed {tr.seed})")
    first = trajectories[0]
    system = first_system(system, first)
    env_spec = env_spec_for(system, scenario_at(first.scenario, first.start))
    tmp = path.parent / f".{path.name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        files = _minari_files()
        algos = sorted({tr.expert_algo for tr in trajectories if tr.expert_algo})
        files.write_data(tmp / "data", *_spaces(system, act_dim), env_spec, {
            "dataset_id": dataset_id_for(path, namespace),
            # Minari falls back to env_spec without it; recorded so the intent is explicit.
            "eval_env_spec": env_spec.to_json(),
            "minari_version": files.MINARI_VERSION,
            "algorithm_name": "+".join(algos) or "unknown",
            "description": description or "uavris expert trajectories",
            "uavris": {"format_version": DATASET_FORMAT_VERSION, "system": system.to_dict(),
                       "observation_layout": layout_as_lists(system), "observation_dim": system.observation_dim,
                       "action_dim": act_dim, "phase_control": phase_control},
        }, trajectories, [_episode_metadata(tr) for tr in trajectories])
        # the data folder swapped, not the directory: the directory keeps its writer's lock (uavris.io.contents)
        path.mkdir(parents=True, exist_ok=True)
        replace_folder(tmp / "data", path / "data", path.parent / f".{path.name}.old")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return given


def first_system(system: SystemConfig, trajectory: Trajectory) -> SystemConfig:
    """``system`` with the devices of ``trajectory``'s layout (a dataset over several layouts
    records one system; each episode its own devices)."""
    return system if trajectory.users is None else system.replace(users=trajectory.users)


def _episode_metadata(tr: Trajectory) -> dict[str, Any]:
    meta: dict[str, Any] = {"scenario": tr.scenario, "expert": tr.expert, "expert_algo": tr.expert_algo}
    if tr.start is not None:
        meta["start"] = list(tr.start)
    if tr.users is not None:
        meta["users"] = [list(u) for u in tr.users]
    if tr.goal is not None:
        meta["goal"] = list(tr.goal)
    return meta


def _minari_files() -> ModuleType:
    """:mod:`.minari_files`, the one home of Minari (the train extra), imported where a dataset's
    files are written or read: the rest of this module serves the light install."""
    import uavris.agents.dt.minari_files

    return uavris.agents.dt.minari_files


def _spaces(system: SystemConfig, act_dim: int) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """The environment's observation and action spaces for ``system``, as a dataset records them."""
    low, high = observation_bounds(system)
    return gym.spaces.Box(low, high, dtype=np.float32), gym.spaces.Box(-1.0, 1.0, (act_dim,), dtype=np.float32)


def _data_dir(path: Path) -> Path:
    if (path / "data" / "metadata.json").exists():
        return path / "data"
    if (path / "metadata.json").exists():
        return path
    raise DatasetError(f"{path} is not a Minari dataset (no data/metadata.json)")


def load_dataset(path: str | Path) -> ExpertDataset:
    """Read and validate a dataset written by :func:`write_dataset`.

    The raw ``metadata.json`` is checked first (:func:`_checked_metadata`), so Minari never sees
    a file that would make it build an environment: with its spaces missing, Minari calls
    ``gym.make`` on the recorded spec, which imports and calls whatever entry point the file
    names. Raises :class:`DatasetError` with one line naming the problem: not a dataset, not
    readable by Minari, missing uavris metadata or per-episode fields, wrong array
    shapes, non-finite values, an observation layout different from the one the
    current environment produces for the stored system configuration, spaces other than the
    environment's, or a recorded environment spec that would recover another environment or
    system.
    """
    path = Path(path)
    data_dir = _data_dir(path).absolute()
    meta, system, phase_control = _checked_metadata(data_dir, str(path))
    try:
        ds = _minari_files().open_data(data_dir)
    except (ValueError, KeyError, OSError, AssertionError, TypeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path} is not a readable Minari dataset ({_one_line(e)})") from None
    obs_dim, act_dim = system.observation_dim, action_dim_for(system, phase_control)
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
                            str(em["scenario"]), int(em["seed"]), str(em["expert"]), str(em.get("expert_algo", "")),
                            *_episode_layout(em, system, f"{path}: episode {i}"), _goal(em, f"{path}: episode {i}"))
            _check_trajectory(tr, obs_dim, act_dim, f"{path}: episode {i}")
            trajectories.append(tr)
    except (KeyError, ValueError, OSError, TypeError, AssertionError, IndexError) as e:
        if isinstance(e, DatasetError):
            raise
        raise DatasetError(f"{path}: episode data is unreadable ({_one_line(e)})") from None
    return ExpertDataset(path, str(meta.get("dataset_id", "")), system, trajectories, str(meta.get("description", "")),
                         phase_control)


def _goal(meta: dict[str, Any], where: str) -> tuple[float, float, float] | None:
    """An episode's recorded goal (where it flew to: a demonstration's plan target), checked, or None."""
    goal = meta.get("goal")
    if goal is None:
        return None
    try:
        return float_tuple(goal, "episode", "goal", "a point [x, y, z] (m)")
    except ConfigError as e:
        raise DatasetError(f"{where}: recorded goal is invalid ({_one_line(e)})") from None


def _episode_layout(meta: dict[str, Any], system: SystemConfig, where: str
                    ) -> tuple[tuple[float, ...] | None, tuple[tuple[float, ...], ...] | None]:
    """An episode's recorded start and devices (None where its trajectory had none: one made
    without a hall, e.g. synthetic data), checked: a layout the dataset's system accepts, with
    its number of devices."""
    start, users = meta.get("start"), meta.get("users")
    try:
        if users is not None:
            layout_system = system.replace(users=[list(u) for u in users])
            if layout_system.num_users != system.num_users:
                raise ConfigError(f"{layout_system.num_users} devices, the dataset's system has {system.num_users}")
            users = layout_system.users
        if start is not None:
            start = scenario_at(str(meta["scenario"]), start).start
    except (ConfigError, TypeError, ValueError) as e:
        raise DatasetError(f"{where}: recorded layout is invalid ({_one_line(e)})") from None
    return start, users


def _checked_metadata(data_dir: Path, where: str) -> tuple[dict[str, Any], SystemConfig, str]:
    """``data_dir/metadata.json`` read as plain JSON and checked before Minari reads it: the uavris
    metadata, the storage format, the spaces (exactly the environment's for the stored system, so
    Minari takes them as written and never builds an environment to learn them) and every
    recorded environment spec (:func:`_check_env_spec`). Returns the metadata, the system and
    the phase control."""
    try:
        meta = json.loads((data_dir / "metadata.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise DatasetError(f"{where} is not a readable Minari dataset ({_one_line(e)})") from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{where}: metadata.json is not a JSON object")
    info = meta.get("uavris")
    if not isinstance(info, dict):
        raise DatasetError(f"{where} was not written by uavris collect (no 'uavris' metadata)")
    for key in ("format_version", "system", "observation_layout", "observation_dim", "action_dim", "phase_control"):
        if key not in info:
            raise DatasetError(f"{where}: the uavris metadata is missing the field {key!r}")
    if info["format_version"] != DATASET_FORMAT_VERSION:
        raise DatasetError(f"{where} has dataset format {info['format_version']!r}; "
                           f"this uavris reads format {DATASET_FORMAT_VERSION}")
    system = stored_system(info["system"], info["observation_layout"], where, DatasetError)
    phase_control = info["phase_control"]
    if phase_control not in PHASE_CONTROLS:
        raise DatasetError(f"{where}: unknown phase control {phase_control!r} in the uavris metadata")
    obs_dim, act_dim = system.observation_dim, action_dim_for(system, phase_control)
    if info["observation_dim"] != obs_dim or info["action_dim"] != act_dim:
        raise DatasetError(f"{where}: observation/action sizes {info['observation_dim']}/{info['action_dim']} "
                           f"do not match the environment's {obs_dim}/{act_dim}")
    if meta.get("data_format") != "hdf5":
        raise DatasetError(f"{where}: storage format {meta.get('data_format')!r}; uavris writes and reads 'hdf5'")
    _check_spaces(meta, system, act_dim, where)
    if meta.get("env_spec") is None:
        raise DatasetError(f"{where}: no environment spec recorded (Minari could not recover the environment)")
    for key in ("env_spec", "eval_env_spec"):
        if key in meta:
            _check_env_spec(meta[key], system, f"{where}: {key}")
    return meta, system, phase_control


def _check_spaces(meta: dict[str, Any], system: SystemConfig, act_dim: int, where: str) -> None:
    """The recorded spaces, exactly as Minari serialises the environment's for ``system``."""
    serialized = _minari_files().serialized_space
    for key, space in zip(("observation_space", "action_space"), _spaces(system, act_dim)):
        try:
            same = isinstance(meta.get(key), str) and json.loads(meta[key]) == serialized(space)
        except ValueError:
            same = False
        if not same:
            raise DatasetError(f"{where}: the recorded {key} is missing or not the environment's for its system")


def _check_env_spec(spec: Any, system: SystemConfig | None, where: str) -> dict[str, Any]:
    """A recorded environment spec (Minari's JSON string) must rebuild
    uavris's registered environment, through its registered entry point and no wrapper, with
    ``system`` (when given): anything else would have Minari's ``recover_environment`` import
    and call what the file names. Returns the spec's kwargs."""
    try:
        fields = json.loads(spec) if isinstance(spec, str) else None
    except ValueError:
        fields = None
    if not isinstance(fields, dict):
        raise DatasetError(f"{where}: the recorded environment spec is not a JSON object")
    registered = gym.spec(ENV_ID)
    if fields.get("id") != ENV_ID:
        raise DatasetError(f"{where}: the recorded environment is {fields.get('id')!r}, not {ENV_ID!r}")
    if fields.get("entry_point") != registered.entry_point \
            or fields.get("vector_entry_point") not in (None, registered.vector_entry_point) \
            or fields.get("additional_wrappers") not in (None, []):
        raise DatasetError(f"{where}: the recorded environment spec names another entry point or wrappers than "
                           f"uavris's {registered.entry_point!r}; refusing it (making it would run that code)")
    kwargs = fields.get("kwargs")
    if not isinstance(kwargs, dict) or not set(kwargs) <= {"config", "scenario"}:
        raise DatasetError(f"{where}: the recorded environment spec's arguments must be 'config' and 'scenario'")
    if system is not None:
        try:
            same = isinstance(kwargs.get("config"), dict) and SystemConfig.from_dict(kwargs["config"]) == system
        except (ConfigError, TypeError, ValueError):
            same = False
        if not same:
            raise DatasetError(f"{where}: the recorded environment spec has another system configuration than "
                               "the uavris metadata")
    return kwargs


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


def episode_environment(dataset: Any, episode: int, eval_env: bool = False) -> Any:
    """The environment of one episode of a Minari dataset (``minari.MinariDataset``): the recorded
    spec's (the dataset's system and first scenario; checked, and made through uavris's registered
    entry point, never the one the file names) with the episode's own
    hall and start from its metadata, so that a dataset over many halls rebuilds each of them.
    Reset it with the episode's seed to replay the episode."""
    recorded = dataset.storage.metadata
    spec = (eval_env and recorded.get("eval_env_spec")) or recorded.get("env_spec")
    if spec is None:
        raise DatasetError("the dataset records no environment spec")
    kwargs = dict(_check_env_spec(spec, None, "the dataset"))  # made below through the registered entry point
    meta = dict(next(iter(dataset.storage.get_episode_metadata([episode]))))
    system = SystemConfig.from_dict(kwargs["config"])
    start, users = _episode_layout(meta, system, f"episode {episode}")
    if users is not None:
        kwargs["config"] = system.replace(users=users).to_dict()
    if start is not None:
        kwargs["scenario"] = scenario_at(str(meta["scenario"]), start).to_dict()
    return gym.make(ENV_ID, **kwargs)
