"""A user's own controller as an evaluation target: ``pkg.module:NAME`` or ``path/to/file.py:NAME``.

Lives here: importing such a target (:func:`load_user_policy`) and :class:`CheckedPolicy`,
which turns a wrong action into one line naming the controller. Not here: telling such a
name from a run or a reference (:mod:`.targets`), the contract itself
(:mod:`uavris.agents.policy` documents what a policy receives and returns) and the evaluation.

``NAME`` is either a policy (a callable ``policy(obs) -> actions``: a function with one
required parameter, or an object) or a factory that makes one: a class or a function that
takes no argument or ``system`` (its only required parameter may be ``system``). A factory
that accepts a ``system`` argument gets the :class:`~uavris.config.SystemConfig` the policy
is evaluated in. A class or function with other required parameters (``def f(obs, gain)``)
is one :class:`~uavris.errors.ConfigError` line naming them.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.env.wrappers import MOTION_DIM, check_phase_control
from uavris.errors import ActionError, ConfigError


def _import(where: str, target: str) -> Any:
    if where.endswith(".py"):
        path = Path(where)
        if not path.is_file():
            raise ConfigError(f"{target}: no such file {path}")
        module_name = f"uavris_user_{abs(hash(str(path.resolve())))}"
        spec = importlib.util.spec_from_file_location(module_name, path)
        if spec is None or spec.loader is None:
            raise ConfigError(f"{target}: {path} cannot be imported as a Python module")
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module  # dataclasses and pickling look the module up
        try:
            spec.loader.exec_module(module)
        except Exception as e:  # the user's code: any failure is reported, in one line
            sys.modules.pop(module_name, None)
            raise ConfigError(f"{target}: importing {path} failed: {type(e).__name__}: {e}") from e
        return module
    if os.getcwd() not in sys.path:  # like `python -m`: a module beside the user is importable
        sys.path.insert(0, os.getcwd())
    try:
        return importlib.import_module(where)
    except Exception as e:
        raise ConfigError(f"{target}: cannot import module {where!r}: {type(e).__name__}: {e}") from e


def _is_factory(obj: Any, target: str) -> bool:
    """A class, or a function whose required parameters are none or ``system``, is a factory; a
    function with one other required parameter (the observation batch) is a policy."""
    if not (inspect.isclass(obj) or inspect.isfunction(obj) or inspect.ismethod(obj)):
        return False  # an object with __call__ is a policy
    try:
        params = inspect.signature(obj).parameters.values()
    except (TypeError, ValueError):  # a builtin without a signature: call it as a factory and see
        return inspect.isclass(obj)
    required = [p.name for p in params if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if set(required) <= {"system"}:
        return True
    if len(required) == 1 and not inspect.isclass(obj):
        return False
    raise ConfigError(f"{target}: {obj.__name__}({', '.join(required)}) requires {len(required)} arguments; a "
                      "policy takes one (the observation batch), a policy factory none or system")


def load_user_policy(target: str, system: SystemConfig) -> CheckedPolicy:
    """The policy ``target`` names, made for ``system`` and wrapped in :class:`CheckedPolicy`."""
    where, name = target.split(":")
    module = _import(where, target)
    if not hasattr(module, name):
        raise ConfigError(f"{target}: {where} has no attribute {name!r}")
    obj = getattr(module, name)
    if _is_factory(obj, target):
        try:
            takes_system = "system" in inspect.signature(obj).parameters
            obj = obj(system=system) if takes_system else obj()
        except Exception as e:
            raise ConfigError(f"{target}: making the policy failed: {type(e).__name__}: {e}") from e
    if not callable(obj):
        raise ConfigError(f"{target} is a {type(obj).__name__}, not a policy (a callable obs -> actions, or a "
                          "factory that returns one)")
    if getattr(obj, "privileged", False):
        raise ConfigError(f"{target} declares itself privileged; a user's policy sees the observation only")
    mode = getattr(obj, "phase_control", "agent")
    try:
        check_phase_control(mode)
    except ConfigError as e:
        raise ConfigError(f"{target}: {e}") from e
    return CheckedPolicy(obj, target, system, mode)


class CheckedPolicy:
    """A user's policy whose every answer is checked: shape ``(n, 22)`` (or ``(n, 6)`` with the
    optimiser setting the phases), finite; anything else is one :class:`ActionError` line."""

    def __init__(self, policy: Any, name: str, system: SystemConfig, phase_control: str) -> None:
        self.policy, self.name, self.phase_control = policy, name, phase_control
        self.act_dims = (MOTION_DIM, system.action_dim) if phase_control == "optimizer" else (system.action_dim,)
        if hasattr(policy, "observation_dim"):  # checked against the system like the experts' and the DT's
            self.observation_dim = policy.observation_dim
        for hook in ("begin", "record"):  # episodic policies keep their memory
            if callable(getattr(policy, hook, None)):
                setattr(self, hook, getattr(policy, hook))

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        try:
            out = self.policy(obs)
        except Exception as e:
            raise ActionError(f"{self.name} failed on an observation batch of shape {obs.shape}: "
                              f"{type(e).__name__}: {e}") from e
        try:
            a = np.asarray(out, dtype=np.float32)
        except (TypeError, ValueError) as e:
            raise ActionError(f"{self.name} returned {type(out).__name__}, not an array of actions") from e
        want = " or ".join(f"({obs.shape[0]}, {d})" for d in self.act_dims)
        if a.ndim != 2 or a.shape[0] != obs.shape[0] or a.shape[1] not in self.act_dims:
            raise ActionError(f"{self.name} returned actions of shape {a.shape} for {obs.shape[0]} observations; "
                              f"expected {want} (phase control {self.phase_control!r})")
        if not np.all(np.isfinite(a)):
            row, col = (int(i) for i in np.argwhere(~np.isfinite(a))[0])
            raise ActionError(f"{self.name} returned a non-finite action (row {row}, entry {col}); actions must be "
                              "finite numbers in [-1, 1]")
        return a
