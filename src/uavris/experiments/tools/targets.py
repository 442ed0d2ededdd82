"""What a user names as a policy (``uavris evaluate TARGET``, ``benchmark``, the study's rows), resolved once.

Lives here: :func:`resolve_target`, which reads the name once into a :class:`Target` that
knows its kind (a reference, a user's policy, a DT model or run, an expert's run), the
system it was made for (read from its files, nothing loaded) and how to load its policy
(:meth:`Target.load`). Not here: importing a user's module (:mod:`.user_policy`), the
evaluation itself (:mod:`.evaluate`), the references (:mod:`uavris.agents.references`).

The kinds, in the order a name is tried:

- ``baseline:NAME``, or a bare reference ``NAME`` that is not an existing directory: the
  reference (:data:`uavris.agents.references.REFERENCES`), made for the system asked for;
- ``MODULE:NAME`` or ``FILE.py:NAME``: a user's policy (README, "Your own controller");
- a directory holding a DT model (``model.json``) or a DT run (pre-training, fine-tuning);
- any other directory: an expert's training run (``uavris train``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from uavris.agents.references import REFERENCE_SEED, REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig
from uavris.errors import UavrisError

TargetKind = Literal["reference", "user", "dt", "expert"]
BASELINE_PREFIX = "baseline:"
_MODULE = re.compile(r"[A-Za-z_][\w]*(\.[A-Za-z_][\w]*)*")


@dataclass(frozen=True)
class Loaded:
    """A target's policy with the system and scenario it comes with."""

    policy: Any  # a batch policy (uavris.agents.policy)
    system: SystemConfig
    scenario: Scenario | None  # a run's own (None: a reference, a user's policy or a pre-trained DT)
    run_dir: Path | None  # None for a reference or a user's policy
    expert_kind: str | None = None  # an expert run's algorithm ("PPO", "oracle imitation"); None otherwise


@dataclass(frozen=True)
class Target:
    """A policy named by the user, of a known kind (see the module docstring)."""

    name: str  # as written
    kind: TargetKind
    reference: str | None = None  # the reference's name (kind "reference")
    path: Path | None = None  # the directory (kinds "dt" and "expert")

    def own_system(self) -> SystemConfig:
        """The system the target was made for, read from its configuration only: a run's, a DT
        checkpoint's, or the paper's for a reference or a user's policy."""
        if self.kind == "dt":
            from uavris.experiments.training.dt_runs import dt_system

            return dt_system(self.path)
        if self.kind == "expert":
            from uavris.experiments.training.train_expert import load_run_config

            return load_run_config(self.path).system
        return SystemConfig()

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        """The policy; a reference or a user's policy is made for ``system`` (default: the
        paper's), a run or a DT model comes with its own. References use their own fixed seed
        (:data:`~uavris.agents.references.REFERENCE_SEED`), so ``uavris evaluate oracle`` gives
        the reports' numbers on whatever episodes it is evaluated."""
        if self.kind == "reference":
            system = system or SystemConfig()
            return Loaded(reference_policy(str(self.reference), system, REFERENCE_SEED), system, None, None)
        if self.kind == "user":
            from uavris.experiments.tools.user_policy import load_user_policy

            system = system or SystemConfig()
            return Loaded(load_user_policy(self.name, system), system, None, None)
        from uavris.experiments.engine.jobs import configure_threads

        configure_threads()
        if self.kind == "dt":
            from uavris.experiments.training.dt_runs import load_dt_policy

            policy, own, scenario = load_dt_policy(self.path, device=device)
            return Loaded(policy, own, scenario, self.path)
        from uavris.experiments.training.train_expert import load_run_policy

        cfg, policy = load_run_policy(self.path, device)
        return Loaded(policy, cfg.system, cfg.resolved_scenario, self.path, cfg.expert_kind)

    def default_out(self) -> Path:
        """Where ``uavris evaluate`` writes when no ``--out`` is given."""
        if self.kind == "user":
            return Path("runs/policies") / re.sub(r"[^\w.-]+", "_", self.name) / "eval"
        if self.kind == "reference":
            return Path("runs/baselines") / str(self.reference) / "eval"
        return Path(str(self.path)) / "eval"


def _is_user_policy(name: str) -> bool:
    """``MODULE:NAME`` or ``FILE.py:NAME`` (called after references and directories are ruled out)."""
    if name.count(":") != 1:
        return False
    where, attr = name.split(":")
    return bool(attr) and (where.endswith(".py") or bool(_MODULE.fullmatch(where)))


def resolve_target(name: str | Path) -> Target:
    """What ``name`` names (the module docstring's rules); one line naming the problem when it
    names nothing: an unknown baseline, a missing path, a file where a directory is expected."""
    name = str(name)
    path = Path(name)
    if name.startswith(BASELINE_PREFIX):
        ref = name[len(BASELINE_PREFIX):]
        if ref not in REFERENCES:
            raise UavrisError(f"unknown baseline {ref!r}; choose one of {', '.join(REFERENCES)}")
        return Target(name, "reference", reference=ref)
    if path.is_dir():
        from uavris.experiments.training.dt_runs import dt_model_dir

        return Target(name, "dt" if dt_model_dir(path) is not None else "expert", path=path)
    if name in REFERENCES:
        return Target(name, "reference", reference=name)
    if _is_user_policy(name):
        return Target(name, "user")
    raise UavrisError(f"{path} is not a directory (expected a run directory, a model directory, one of the "
                      f"references {', '.join(REFERENCES)} or MODULE:NAME / FILE.py:NAME)")
