"""What a user names as a policy (``uavris evaluate TARGET``, ``benchmark``), resolved once, and
a row of a report: a policy as the study evaluates it.

Lives here: the one policy registry: :func:`resolve_target` reads a name once into a
:class:`Target`, an object of one class per kind that knows the system it was made for (read
from its files, nothing loaded), how to load its policy, where its results go and how it is
exported; and :class:`Row`, a target (or an ensemble of them, or another hall's plan) with how
a report evaluates it (the attitude safety layer, the attitude held level) and what the report
calls it. Not here: importing a user's module (:mod:`.user_policy`), the evaluation itself
(:mod:`.evaluate`), the references (:mod:`uavris.agents.references`), which rows a study has
(:mod:`uavris.experiments.study.tracks`).

The kinds (:data:`TARGET_KINDS`, in the order a name is tried; :func:`register_target_kind`
puts a new one first):

- :class:`Reference`: ``baseline:NAME``, or a bare reference ``NAME`` that is not an existing
  directory (:data:`uavris.agents.references.REFERENCES`), made for the system asked for;
- :class:`LearnedValue`: a directory holding a learned value of a pose (``value.json``): the
  learned planner's place, flown by the oracle's controller;
- :class:`Controller`: a controller directory (``controller.json``, written by
  :func:`write_controller`, ``uavris export``): a row of a study with its models (a
  goal-conditioned DT with its learned planner, an ensemble, under the safety layer or held
  level), evaluated as the study evaluates it;
- :class:`DTModel`: a directory holding a DT model (``model.json``) or a DT run;
- :class:`ExpertRun`: any other directory with a ``config.yaml``: an expert's training run
  (``uavris train``);
- :class:`UserPolicy`: ``MODULE:NAME`` or ``FILE.py:NAME`` (README, "Your own controller").

The DT, the learned value and an expert's run are read with torch (and SB3): their modules are
imported where a target of that kind is loaded, so that a light install (no ``[train]``
extra) evaluates references and a user's policy.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

from uavris.agents.dt.goals import PlannedGoals
from uavris.agents.oracle import PlanningOracle
from uavris.agents.oracle.policy import PlannedFlight
from uavris.agents.policy import LevelAttitude
from uavris.agents.references import REFERENCE_SEED, REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.tools.user_policy import load_user_policy
from uavris.io import file_part, read_checkpoint_meta, refuse_links_out, write_json
from uavris.layouts import Site

CONTROLLER_FILE, CONTROLLER_KIND, CONTROLLER_FORMAT = "controller.json", "uavris-controller", 1
# The controller shipped with the package: the make run's goal-conditioned DT (seed 0) told the deployed place by
# its learned value (docs/results/pretrained.md); every command takes it by this name
PRETRAINED_NAME = "pretrained"
PRETRAINED = Path(__file__).resolve().parents[2] / "pretrained" / "deployment"
# What a row of a report is: a learned controller or place (the DT family, behaviour cloning, the learned
# planner), the expert trained where it is deployed, a policy transferred from a training deployment, a reference.
RowKind = Literal["learned", "expert", "transfer", "reference"]
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

    def as_row(self) -> Row:
        """The target as a row of its own."""
        return Row(self.name, self.name, target=self)

    def exported(self, dest: Path) -> dict[str, Any]:
        """The target as a part of a controller directory ``dest`` (:func:`write_controller`): its
        files copied there, and the record ``controller.json`` keeps of it."""
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
        from uavris.agents.place.checkpoint import load_value

        return load_value(self.path)[0]

    def _planner(self) -> Any:
        from uavris.agents.place.planner import LearnedPlanner, PlaceSettings

        return LearnedPlanner(self.planner_model(), PlaceSettings(top_k=self.top_k), self.deployed)

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


def shipped_controller(name: str | Path) -> Path | None:
    """:data:`PRETRAINED` where ``name`` is :data:`PRETRAINED_NAME` and no path of that name exists
    (a folder of the user's called so is theirs); one line where this install ships none."""
    if str(name) != PRETRAINED_NAME or Path(name).exists():
        return None
    if not (PRETRAINED / CONTROLLER_FILE).is_file():
        raise UavrisError(f"this install of uavris ships no pretrained controller ({PRETRAINED} is missing)")
    return PRETRAINED


@dataclass(frozen=True)
class Controller(ModelDir):
    """A controller directory (``uavris export``): the row it holds, in its own system. The name
    ``pretrained`` is the controller shipped with the package (:data:`PRETRAINED`, docs/results/pretrained.md)."""

    kind: ClassVar[str] = "controller"
    marker: ClassVar[str] = CONTROLLER_FILE
    describes: ClassVar[str] = "uavris export"

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        shipped = shipped_controller(name)
        return cls.at(shipped) if shipped is not None else super().recognise(name, trust_pickle)

    def as_row(self) -> Row:
        return read_controller(self.path)

    def own_system(self) -> SystemConfig:
        return self.as_row().own_system()

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        row = self.as_row()
        return row.load(row.system(system or row.own_system()), device)


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
        from uavris.agents.dt.checkpoint import dt_model_dir

        return cls.at(name) if dt_model_dir(name) is not None else None

    def model_dir(self) -> Path:
        from uavris.agents.dt.checkpoint import dt_model_dir

        return dt_model_dir(self.path) or self.path

    def own_system(self) -> SystemConfig:
        from uavris.agents.dt.checkpoint import dt_system

        return dt_system(self.path)

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        from uavris.agents.dt.policy import load_dt_policy

        dt = load_dt_policy(self.path, device=device)
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
        from uavris.experiments.training.train_expert import load_run_config

        return load_run_config(self.path).system

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        from uavris.experiments.training.train_expert import load_run_policy

        cfg, policy = load_run_policy(self.path, device, self.trust_pickle)
        return Loaded(policy, cfg.system, cfg.resolved_scenario, self.path, cfg.expert_kind)


TARGET_KINDS: list[type[Target]] = [Reference, LearnedValue, Controller, DTModel, ExpertRun, UserPolicy]
EXPORTED_KINDS: dict[str, type[ModelDir]] = {k.kind: k for k in (DTModel, LearnedValue, ExpertRun)}


def register_target_kind(kind: type[Target]) -> type[Target]:
    """Add a kind of target (a :class:`Target` subclass), tried before the others, in this
    process: what resolves a name here (:func:`resolve_target`; ``uavris.cli.main(["evaluate",
    ...])`` or ``["benchmark", ...]`` called from the script that registered it) reads it. A
    process that did not register it does not (a ``sweep`` job on other workers, a shell's
    ``uavris``)."""
    if kind not in TARGET_KINDS:
        TARGET_KINDS.insert(0, kind)
    return kind


def resolve_target(name: str | Path, trust_pickle: bool = False) -> Target:
    """What ``name`` names (the first of :data:`TARGET_KINDS` that recognises it); one line
    naming the problem when it names nothing: an unknown baseline, a missing path, a directory
    that holds no policy. ``trust_pickle``: an expert's run with SB3's pickled archive only may
    be loaded."""
    name = str(name)
    # a folder reads only its own files: a link out of it is refused before any kind reads its configuration
    refuse_links_out(name, "a run, model, value or controller folder")
    for kind in TARGET_KINDS:
        found = kind.recognise(name, trust_pickle=trust_pickle)
        if found is not None:
            return found
    path = Path(name)
    if path.is_dir():
        held = [f"{k.marker} ({k.describes or k.__name__})" for k in reversed(TARGET_KINDS) if k.marker]
        raise UavrisError(f"{path} holds no policy uavris reads: none of {', '.join(held[:-1])} or {held[-1]}")
    raise UavrisError(f"{path} is not a directory (expected a run directory, a model directory, one of the "
                      f"references {', '.join(REFERENCES)} or MODULE:NAME / FILE.py:NAME)")


@dataclass(frozen=True)
class Row:
    """One row of a report: a policy as the study evaluates it, and what the report calls it.

    The policy is one :class:`Target`, or an ensemble of DT models acting as one
    (``members``: the mean of their actions, :class:`uavris.agents.dt.policy.DTEnsemble`), or
    the planning oracle's plan of another hall flown here (``plan_of``:
    :class:`uavris.agents.oracle.policy.PlannedFlight`). How it is evaluated: under the
    attitude safety layer (``front_margin_deg``: the system's margin, docs/model.md section
    3), with its attitude held level (``level``: :class:`uavris.agents.policy.LevelAttitude`).
    ``seed`` is the pre-training seed of its model where the study trains a row over several
    (the report averages a row over its seeds). A goal-conditioned controller is told where to
    go by ``goal_from`` (:meth:`Target.goal_source`: the learned planner or the oracle; a model
    fine-tuned in a hall keeps the place it chose there). Its :attr:`key`,
    ``NAME[-level][-safe][@sK]``, names it in a stage's results, its files and ``uavris evaluate --row``;
    what it is (``kind``, a transfer's ``rank`` by distance, a data-curve model's
    ``training_halls``, and the fields above) the stage results record beside its numbers
    (:meth:`facts`), and a report reads them there, never from the key.
    """

    name: str  # the row without its variants: "dt-zero-shot", "bc", "transfer-layout-train-5", "oracle"
    label: str  # what the report calls it, without its variants and seed (label_for adds them)
    target: Target | None = None
    members: tuple[Target, ...] = ()
    plan_of: Site | None = None
    seed: int | None = None
    front_margin_deg: float | None = None
    level: bool = False
    goal_from: Target | None = None
    kind: RowKind = "learned"
    rank: int | None = None  # a transferred policy's rank by the distance of its deployment (0: the nearest)
    training_halls: int | None = None  # a model of the data curve: the training halls it saw

    def __post_init__(self) -> None:
        if sum((self.target is not None, bool(self.members), self.plan_of is not None)) != 1:
            raise ConfigError(f"row {self.name!r}: give exactly one of a target, ensemble members or a plan's hall")

    @classmethod
    def reference(cls, name: str, **how: Any) -> Row:
        """The reference ``name`` (:data:`uavris.agents.references.REFERENCES`) as a row."""
        return cls(name, REFERENCES[name].label, Reference.named(name), kind="reference", **how)

    @property
    def variant(self) -> str:
        """The row over all its seeds: its name with how it is evaluated."""
        return variant_key(self.name, self.front_margin_deg is not None, self.level)

    def facts(self) -> dict[str, Any]:
        """What the row is, as the stage results record it beside its numbers."""
        return {"name": self.name, "kind": self.kind, "variant": self.variant, "seed": self.seed,
                "front_margin_deg": self.front_margin_deg, "level": self.level, "rank": self.rank,
                "training_halls": self.training_halls,
                "plan_of": self.plan_of.name if self.plan_of is not None else None,
                "goal_from": self.goal_from.planner() if self.goal_from is not None else None}

    @property
    def key(self) -> str:
        return self.variant + (f"@s{self.seed}" if self.seed else "")

    def origin(self) -> dict[str, Any]:
        """The model a result was made with, as the result records it: the row's key and seed,
        the origin of each of its models (:meth:`Target.origin`), its goal source and the hall
        whose plan it flies."""
        parts = [self.target] if self.target is not None else list(self.members)
        return {"row": self.key, "seed": self.seed, "models": [t.origin() for t in parts],
                "goal_from": self.goal_from.origin() if self.goal_from is not None else None,
                "plan_of": self.plan_of.name if self.plan_of is not None else None}

    def label_for(self, expert_kind: str | None = None) -> str:
        """The report's label: an expert's algorithm first, then the seed and how it is evaluated."""
        return ((f"{expert_kind} " if expert_kind else "") + self.label + (f", seed {self.seed}" if self.seed else "")
                + (", safety layer" if self.front_margin_deg is not None else "")
                + (", attitude held level" if self.level else ""))

    def replace(self, **changes: Any) -> Row:
        return dataclasses.replace(self, **changes)

    def system(self, base: SystemConfig) -> SystemConfig:
        """The system this row is evaluated in: ``base``, under the safety layer where the row says so."""
        return base if self.front_margin_deg is None else base.replace(front_margin_deg=self.front_margin_deg)

    def own_system(self) -> SystemConfig:
        """The system the row's policy was made for (:meth:`Target.own_system`; a plan's hall's own)."""
        if self.plan_of is not None:
            return self.plan_of.system
        return (self.target or self.members[0]).own_system()

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        """The row's policy (:meth:`Target.load` for a single target), its attitude held level
        where the row says so; the system it is evaluated in is :meth:`system`'s."""
        if self.target is not None:
            loaded = self.target.load(system, device)
            if self.goal_from is not None:
                loaded = dataclasses.replace(loaded, policy=loaded.policy.with_goals(self.goal_from.goal_source()))
        elif self.members:
            from uavris.agents.dt.policy import DTEnsemble

            parts = [m.load(system, device) for m in self.members]
            loaded = Loaded(DTEnsemble([p.policy for p in parts]), parts[0].system, None, None)
        else:
            there = self.plan_of
            assert there is not None
            loaded = Loaded(PlannedFlight(PlanningOracle().plan(there.system, there.scenario.start)), there.system,
                            None, None)
        if self.level:
            loaded = dataclasses.replace(loaded, policy=LevelAttitude(loaded.policy))
        return loaded


def variant_key(name: str, safe: bool = False, level: bool = False) -> str:
    """The key of row ``name`` over all its seeds, evaluated under the safety layer (``safe``)
    or with its attitude held level (:attr:`Row.variant`)."""
    return name + "-level" * level + "-safe" * safe


def as_row(target: str | Path | Target | Row) -> Row:
    """A row for what ``uavris evaluate`` takes: a row as it is, a target (or its name) as a row of its own."""
    if isinstance(target, Row):
        return target
    return (target if isinstance(target, Target) else resolve_target(target)).as_row()


# ------------------------------------------------------------------------------ controller directories
def write_controller(row: Row, dest: Path) -> Path:
    """``row`` as a directory of its own (``uavris export``): the files of its models (weights
    and JSON only) and ``controller.json`` (how the row evaluates them: its goal source, safety
    margin, level attitude, ensemble); :func:`read_controller` gives the row back. A row that
    flies another hall's plan is that hall's, not a controller: one line."""
    if row.plan_of is not None:
        raise ConfigError(f"{row.key} flies the plan of {row.plan_of.name}, a hall of the study: it is no controller "
                          "of its own to export")
    dest = Path(dest)

    def copied(t: Target, folder: str) -> dict[str, Any]:
        try:
            return t.exported(dest / folder)
        except ConfigError as e:
            raise ConfigError(f"{row.key}: {e}") from None

    record = {"kind": CONTROLLER_KIND, "format_version": CONTROLLER_FORMAT, "name": row.name, "label": row.label,
              "seed": row.seed, "front_margin_deg": row.front_margin_deg, "level": row.level,
              "target": copied(row.target, "model") if row.target is not None else None,
              "members": [copied(m, f"member-{i}") for i, m in enumerate(row.members)],
              "goal_from": copied(row.goal_from, "goal") if row.goal_from is not None else None}
    write_json(dest / CONTROLLER_FILE, record)
    return dest


def read_controller(path: Path) -> Row:
    """The row a controller directory holds (:func:`write_controller`); one line when it is not one."""
    meta = read_checkpoint_meta(path, CONTROLLER_FILE, CONTROLLER_KIND, CONTROLLER_FORMAT, "a controller directory",
                                "a controller")

    def target(part: Any) -> Target | None:
        if part is None:
            return None
        kind = part.get("kind") if isinstance(part, dict) else None
        if not isinstance(kind, str) or (kind != Reference.kind and kind not in EXPORTED_KINDS):
            raise ConfigError(f"{path / CONTROLLER_FILE}: a part of the controller is {part!r}")
        if kind == Reference.kind:
            return Reference.named(str(part["reference"]))
        folder = Path(path) / str(part["path"])
        if folder.resolve().parent != Path(path).resolve():  # the controller's own folders, nothing outside
            raise ConfigError(f"{path / CONTROLLER_FILE}: {part['path']!r} is not a folder of the controller")
        chosen = {"top_k": int(part.get("top_k", 0)), "deployed": bool(part.get("deployed", False))} \
            if kind == LearnedValue.kind else {}
        return EXPORTED_KINDS[kind].at(folder, **chosen)

    try:
        return Row(str(meta["name"]), str(meta["label"]), target=target(meta["target"]),
                   members=tuple(target(m) for m in meta["members"]), goal_from=target(meta["goal_from"]),
                   seed=meta["seed"], front_margin_deg=meta["front_margin_deg"], level=bool(meta["level"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(f"{path / CONTROLLER_FILE} is not a controller ({type(e).__name__}: {e})") from None
