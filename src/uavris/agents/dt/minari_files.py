"""A dataset's files as Minari writes and reads them: the one module of uavris that imports Minari.

Lives here: :func:`write_data` (a ``data`` folder from trajectories, spaces, the environment
spec and the metadata), :func:`open_data` (Minari's reader of one), :func:`serialized_space`
(a space as Minari records it) and :data:`MINARI_VERSION`. Not here: what a dataset holds and
every check of it (:mod:`.dataset`, which imports this module where a dataset's files are
written or read: Minari is the ``train`` extra's, and the rest of :mod:`.dataset` serves the
light install).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import gymnasium as gym
import minari
import numpy as np
from minari.data_collector import EpisodeBuffer
from minari.dataset.minari_storage import MinariStorage
from minari.serialization import serialize_space
from numpy.typing import NDArray

from uavris.agents.dt.trajectories import Trajectory

MINARI_VERSION = minari.__version__


def write_data(data_dir: Path, observation_space: gym.Space, action_space: gym.Space, env_spec: Any,
               metadata: dict[str, Any], trajectories: Sequence[Trajectory],
               episode_metadata: list[dict[str, Any]]) -> None:
    """A Minari ``data`` folder at ``data_dir`` (HDF5): the spaces, the environment spec, ``metadata``
    and one episode per trajectory with its ``episode_metadata``."""
    storage = MinariStorage.new(data_dir, observation_space=observation_space, action_space=action_space,
                                env_spec=env_spec, data_format="hdf5", jpeg_encoding=False)
    storage.update_metadata(metadata)
    storage.update_episodes(
        EpisodeBuffer(id=i, seed=tr.seed, observations=tr.observations, actions=tr.actions, rewards=tr.rewards,
                      terminations=_flag_last(tr.length, tr.terminated),
                      truncations=_flag_last(tr.length, tr.truncated))
        for i, tr in enumerate(trajectories))
    storage.update_episode_metadata(episode_metadata)


def open_data(data_dir: Path) -> Any:
    """Minari's dataset (``minari.MinariDataset``) of the ``data`` folder ``data_dir``; the caller
    has checked its metadata first (:func:`uavris.agents.dt.dataset.load_dataset`)."""
    return minari.MinariDataset(data_dir)


def serialized_space(space: gym.Space) -> Any:
    """``space`` as Minari records it in the metadata (parsed, not a string)."""
    return serialize_space(space, to_string=False)


def _flag_last(length: int, flag: bool) -> NDArray[np.bool_]:
    """Per-slot flags of an episode: ``flag`` at its last slot, False before."""
    out = np.zeros(length, dtype=bool)
    out[-1] = flag
    return out
