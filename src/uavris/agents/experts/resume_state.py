"""The training state a checkpoint needs, beyond SB3's model and replay buffer, for a resumed
run to continue exactly as an uninterrupted one would.

Lives here: :func:`capture`, :func:`restore` and :data:`STATE_VERSION`. Not here: when a
checkpoint is taken and what else it holds
(:func:`uavris.experiments.training.train_expert.save_checkpoint`) and the ``latest.json`` pointer
(:mod:`uavris.runs`).

``model.save`` keeps weights, optimisers and counters, and ``save_replay_buffer`` the
buffer. Not kept by SB3: the environments mid-episode (``load`` discards ``_last_obs``, so
a resumed run would start fresh episodes) and the random streams of exploration noise,
replay sampling, warm-up actions and TD3/SAC's target noise (numpy's and Python's global
generators, torch's CPU generator, the action space's generator). :func:`capture` takes
those at a consistent point: between a finished gradient update and the next env step,
which is SB3's ``on_rollout_start`` (and the end of ``learn``). :func:`restore` puts them
back on a freshly loaded model.

The blob is a pickle, like SB3's own replay buffer file: it is trusted local state,
written and read by uavris only.
"""

from __future__ import annotations

import pickle
import random
from typing import Any

import numpy as np
import torch

from uavris.agents.experts.vec_env import UavRisVecEnv

STATE_VERSION = 1
_MODEL_FIELDS = ("_last_obs", "_last_episode_starts", "_last_original_obs", "_episode_num")


def capture(model: Any) -> bytes:
    """The environments, the episode bookkeeping of ``model`` and every random stream."""
    env = model.get_env()
    if not isinstance(env, UavRisVecEnv):
        raise TypeError(f"exact resume needs a UavRisVecEnv, got {type(env).__name__}")
    state = {
        "version": STATE_VERSION,
        "num_timesteps": int(model.num_timesteps),
        "env": env.get_state(),
        "model": {name: getattr(model, name, None) for name in _MODEL_FIELDS},
        "numpy": np.random.get_state(),
        "python": random.getstate(),
        "torch": torch.get_rng_state(),
        "action_space": model.action_space.np_random.bit_generator.state,
    }
    return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)


def restore(model: Any, blob: bytes) -> None:
    """Apply :func:`capture`'s output to a model loaded from the same checkpoint.

    Raises ValueError when the blob is unreadable or belongs to another step.
    """
    try:
        state = pickle.loads(blob)
        ok = isinstance(state, dict) and state.get("version") == STATE_VERSION
    except Exception as e:  # noqa: BLE001 - any unpickling failure means a corrupt file
        raise ValueError(f"unreadable ({type(e).__name__})") from None
    if not ok:
        raise ValueError("not a uavris resume state of this version")
    if state["num_timesteps"] != int(model.num_timesteps):
        raise ValueError(f"state is for step {state['num_timesteps']}, model is at {model.num_timesteps}")
    model.get_env().set_state(state["env"])
    for name, value in state["model"].items():
        setattr(model, name, value)
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    torch.set_rng_state(state["torch"])
    model.action_space.np_random.bit_generator.state = state["action_space"]
