"""What a user names as a policy (``uavris evaluate TARGET``, ``benchmark``): one class per kind.

Lives here: :class:`Target`, an object of one class per kind that knows the system it was made
for (read from its files, nothing loaded), how to load its policy, where its results go and how
it is exported, and :class:`Loaded`, a policy with the system it comes with. Not here: the
registry that reads a name into one of these, the controller directory and a report's row
(:mod:`.rows`), importing a user's module (:mod:`.user_policy`), the evaluation itself
(:mod:`.evaluate`), the references (:mod:`uavris.agents.references`).

The kinds, in the order :func:`uavris.experiments.tools.rows.resolve_target` tries a name:

- :class:`Reference`: ``baseline:NAME``, or a bare reference ``NAME`` that is not an existing
  directory (:data:`uavris.agents.references.REFERENCES`), made for the system asked for;
- :class:`LearnedValue`: a directory holding a learned value of a pose (``value.json``): the
  learned planner's place, flown by the oracle's controller;
- :class:`uavris.experiments.tools.rows.Controller`: a controller directory
  (``controller.json``, ``uavris export``): a row of a study with its models;
- :class:`DTModel`: a directory holding a DT model (``model.json``) or a DT run;
- :class:`ExpertRun`: any other directory with a ``config.yaml``: an expert's training run
  (``uavris train``);
- :class:`UserPolicy`: ``MODULE:NAME`` or ``FILE.py:NAME`` (README, "Your own controller").

The DT, the learned value and an expert's run are read with torch (and SB3): what reads them
(:mod:`.trained_loaders`) is imported where a target of that kind is read or loaded, so that a
light install (no ``[train]`` extra) evaluates references and a user's policy.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

from uavris.agents.dt.goals import PlannedGoals
from uavris.agents.oracle import PlanningOracle
from uavris.agents.references import REFERENCE_SEED, REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.tools.user_policy import load_user_policy
from uavris.io import file_part

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
    """A policy named by the user; each kind a subclass (the module docstring lists them).

    A kind says how a name is recognised as one of it (:meth:`recognise`), how its policy is
    loaded (:meth:`load`), the system it was made for (:meth:`own_system`), where ``uavris
    evaluate`` writes its results (:meth:`default_out`) and what a result records of it
    (:meth:`origin`); the defaults below are those of a policy made for the system asked for.
    """

    name: str  # as written
    kind: ClassVar[str] = ""  # the kind's name, as a controller directory records it
    trained: ClassVar[bool] = False  # a model trained in some hall (flown elsewhere: an extrapolation)
    marker: ClassVar[str] = ""  # a directory kind: the file that makes a directory one of it (for the error line)
    describes: ClassVar[str] = ""  # what that file says the directory is, in the error line

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        """This kind's target named ``name``, or None when the name is not one."""
        return None

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        raise NotImplementedError

    def own_system(self) -> SystemConfig:
        """The system the target was made for, read from its configuration only (the paper's
        where the target is made for any)."""
        return SystemConfig()

    def location(self) -> Path | None:
        """The directory the target's files are in (None: nothing on disk)."""
        return None

    def goal_source(self) -> PlannedGoals:
        """Where a goal-conditioned controller is told to go by this target, per hall and start."""
        raise ConfigError(f"{self.name} tells no goal (a learned value or the oracle does)")

    def planner(self) -> str:
        """The planner this target is, as a goal source names it (:meth:`goal_source`)."""
        return self.name

    def origin(self) -> str:
        """Where the policy comes from, as a result records it: its directory's absolute path, or
        its name where it has none. Two targets that differ never share it (the name of a result
        file carries a hash of it)."""
        where = self.location()
        return str(where.resolve()) if where is not None else self.name

    def default_out(self) -> Path:
        """Where ``uavris evaluate`` writes when no ``--out`` is given: beside its files, or
        ``runs/policies/NAME/eval``."""
        where = self.location()
        return where / "eval" if where is not None else Path("runs/policies") / self.file_token() / "eval"

    def file_token(self) -> str:
        """What a result file's name starts with when this target is evaluated alone."""
        return file_part(Path(self.name).name)

    def exported(self, dest: Path) -> dict[str, Any]:
        """The target as a part of a controller directory ``dest``
        (:func:`uavris.experiments.tools.rows.write_controller`): its files copied there, and the
        record ``controller.json`` keeps of it."""
        raise ConfigError(f"a {self.kind or type(self).__name__} target cannot be exported")


@dataclass(frozen=True)
class Reference(Target):
    """A reference (:data:`uavris.agents.references.REFERENCES`), made for the system asked for,
    with its own fixed seed (:data:`~uavris.agents.references.REFERENCE_SEED`), so ``uavris
    evaluate oracle`` gives the reports' numbers on whatever episodes it is evaluated."""

    reference: str = ""
    kind: ClassVar[str] = "reference"

    @classmethod
    def named(cls, reference: str) -> Reference:
        return cls(reference, reference=reference)

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        if name.startswith(BASELINE_PREFIX):
            ref = name[len(BASELINE_PREFIX):]
            if ref not in REFERENCES:
                raise UavrisError(f"unknown baseline {ref!r}; choose one of {', '.join(REFERENCES)}")
            return cls(name, reference=ref)
        return cls(name, reference=name) if name in REFERENCES and not Path(name).is_dir() else None

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        system = system or SystemConfig()
        return Loaded(reference_policy(self.reference, system, REFERENCE_SEED), system, None, None)

    def goal_source(self) -> PlannedGoals:
        if self.reference != "oracle":
            return super().goal_source()
        oracle = PlanningOracle()
        return PlannedGoals(lambda config, start: oracle.plan(config, start).target, "planning oracle")

    def planner(self) -> str:
        return "planning oracle" if self.reference == "oracle" else self.name

    def origin(self) -> str:
        return f"reference {self.reference}"

    def default_out(self) -> Path:
        return Path("runs/baselines") / self.reference / "eval"

    def file_token(self) -> str:
        return file_part(self.reference)

    def exported(self, dest: Path) -> dict[str, Any]:
        return {"kind": self.kind, "reference": self.reference}


@dataclass(frozen=True)
class UserPolicy(Target):
    """A user's policy, ``MODULE:NAME`` or ``FILE.py:NAME``, made for the system asked for."""

    kind: ClassVar[str] = "user"

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        if name.count(":") != 1 or Path(name).is_dir():
            return None
        where, attr = name.split(":")
        return cls(name) if attr and (where.endswith(".py") or bool(_MODULE.fullmatch(where))) else None

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        system = system or SystemConfig()
        return Loaded(load_user_policy(self.name, system), system, None, None)

    def file_name(self) -> str:
        """``path/FILE.py:NAME`` as ``FILE_py_NAME``, ``pkg.module:NAME`` as ``pkg_module_NAME``."""
        where, attr = self.name.rsplit(":", 1)
        return file_part(f"{Path(where).name}_{attr}")

    def origin(self) -> str:
        where, attr = self.name.rsplit(":", 1)
        return f"{Path(where).resolve()}:{attr}" if where.endswith(".py") else self.name

    def default_out(self) -> Path:
        return Path("runs/policies") / self.file_name() / "eval"

    def file_token(self) -> str:
        return self.file_name()


@dataclass(frozen=True)
class ModelDir(Target):
    """A target held in a directory (which may not exist yet: a study's model before its stage)."""

    path: Path = Path()
    files: ClassVar[tuple[str, ...]] = ()  # what an export copies, from :meth:`model_dir`

    @classmethod
    def at(cls, path: Path | str, **fields: Any) -> ModelDir:
        """The target in directory ``path``, named by it."""
        return cls(str(path), path=Path(path), **fields)

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        return cls.at(name) if Path(name).is_dir() and (Path(name) / cls.marker).is_file() else None

    def location(self) -> Path | None:
        return self.path

    def model_dir(self) -> Path:
        """The directory its weights are read from."""
        return self.path

    def exported(self, dest: Path) -> dict[str, Any]:
        if EXPORTED_KINDS.get(self.kind) is not type(self):  # read_controller could not read it back
            return super().exported(dest)
        dest.mkdir(parents=True, exist_ok=True)
        for name in self.files:
            shutil.copyfile(self.model_dir() / name, dest / name)
        return {"kind": self.kind, "path": dest.name, "top_k": 0}


@dataclass(frozen=True)
class LearnedValue(ModelDir):
    """A learned value of a pose (``value.json``): the learned planner's place (``top_k`` 0: V's
    argmax; else V's top places and staying, valued by ``R``), or the deployed place
    (``deployed``: V proposes, R disposes, :func:`uavris.agents.place.planner.decided_plan`),
    flown by the oracle's controller (:class:`uavris.agents.place.planner.LearnedPlanner`)."""

    top_k: int = 0
    deployed: bool = False
    kind: ClassVar[str] = "value"
    marker: ClassVar[str] = "value.json"
    describes: ClassVar[str] = "a learned value"
    files: ClassVar[tuple[str, ...]] = ("value.safetensors", "value.json")

    def planner_model(self) -> Any:
        return _trained().load_value(self.path)[0]

    def _planner(self) -> Any:
        trained = _trained()
        return trained.LearnedPlanner(self.planner_model(), trained.PlaceSettings(top_k=self.top_k), self.deployed)

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        return Loaded(self._planner(), system or SystemConfig(), None, self.path)

    def goal_source(self) -> PlannedGoals:
        return PlannedGoals(self._planner().target, f"learned planner ({self.name})")

    def planner(self) -> str:
        if self.deployed:
            return "deployed place (V proposes, R disposes)"
        return (f"semi-amortised planner (V's top {self.top_k} places and staying, valued by R)" if self.top_k
                else "learned planner (V's argmax)")

    def exported(self, dest: Path) -> dict[str, Any]:
        return {**super().exported(dest), "top_k": self.top_k, "deployed": self.deployed}


@dataclass(frozen=True)
class DTModel(ModelDir):
    """A Decision Transformer's model directory (``model.json``), or a DT run (its model, or the
    latest checkpoint of an unfinished one)."""

    kind: ClassVar[str] = "dt"
    trained: ClassVar[bool] = True
    marker: ClassVar[str] = "model.json"
    describes: ClassVar[str] = "a DT model"
    files: ClassVar[tuple[str, ...]] = ("model.safetensors", "model.json")

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        if not Path(name).is_dir():
            return None
        return cls.at(name) if _trained().dt_model_dir(name) is not None else None

    def model_dir(self) -> Path:
        return _trained().dt_model_dir(self.path) or self.path

    def own_system(self) -> SystemConfig:
        return _trained().dt_system(self.path)

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        dt = _trained().load_dt_policy(self.path, device=device)
        return Loaded(dt.policy, dt.system, dt.scenario, self.path)


@dataclass(frozen=True)
class ExpertRun(ModelDir):
    """An expert's training run (``uavris train``; ``trust_pickle``: one with SB3's pickled archive
    only may be loaded, ``--trust-pickle``)."""

    trust_pickle: bool = False
    kind: ClassVar[str] = "expert"
    trained: ClassVar[bool] = True
    marker: ClassVar[str] = "config.yaml"
    describes: ClassVar[str] = "a training run"
    files: ClassVar[tuple[str, ...]] = ("config.yaml", "policy.safetensors", "policy.json")

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        found = super().recognise(name)
        return dataclasses.replace(found, trust_pickle=trust_pickle) if found is not None else None

    def own_system(self) -> SystemConfig:
        return _trained().load_run_config(self.path).system

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        cfg, policy = _trained().load_run_policy(self.path, device, self.trust_pickle)
        return Loaded(policy, cfg.system, cfg.resolved_scenario, self.path, cfg.expert_kind)


def _trained() -> ModuleType:
    """:mod:`.trained_loaders`: what the trained kinds are read and loaded with (torch, the train
    extra), imported where a target of one of them is read or loaded, so that a light install
    resolves and scores references and a user's policy."""
    import uavris.experiments.tools.trained_loaders

    return uavris.experiments.tools.trained_loaders


EXPORTED_KINDS: dict[str, type[ModelDir]] = {k.kind: k for k in (DTModel, LearnedValue, ExpertRun)}

