"""What a user names as a policy (``uavris evaluate TARGET``, ``benchmark``), resolved once, and
a row of a report: a policy as the study evaluates it.

Lives here: the one policy registry: :func:`resolve_target`, which reads the name once into
a :class:`Target` that knows its kind (a reference, a user's policy, a DT model or run, an
expert's run), the system it was made for (read from its files, nothing loaded) and how to
load its policy (:meth:`Target.load`); and :class:`Row`, a target (or an ensemble of them,
or another hall's plan) with how a report evaluates it (the attitude safety layer, the
attitude held level) and what the report calls it. Not here: importing a user's module
(:mod:`.user_policy`), the evaluation itself (:mod:`.evaluate`), the references
(:mod:`uavris.agents.references`), which rows a study has (:mod:`uavris.experiments.study.tracks`).

The kinds, in the order a name is tried:

- ``baseline:NAME``, or a bare reference ``NAME`` that is not an existing directory: the
  reference (:data:`uavris.agents.references.REFERENCES`), made for the system asked for;
- ``MODULE:NAME`` or ``FILE.py:NAME``: a user's policy (README, "Your own controller");
- a directory holding a DT model (``model.json``) or a DT run (pre-training, fine-tuning);
- a directory holding a learned value of a pose (``value.json``): the learned planner's
  place, flown by the oracle's controller (:class:`uavris.agents.place.planner.LearnedPlanner`);
- a controller directory (``controller.json``, written by :func:`write_controller`, ``uavris
  export``): a row of a study with its models (a goal-conditioned DT with its learned planner,
  an ensemble, under the safety layer or held level), evaluated as the study evaluates it;
- any other directory: an expert's training run (``uavris train``).
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from uavris.agents.references import REFERENCE_SEED, REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig
from uavris.errors import ConfigError, UavrisError
from uavris.io import file_part
from uavris.layouts import Site

TargetKind = Literal["reference", "user", "dt", "expert", "value", "controller"]
CONTROLLER_FILE, CONTROLLER_KIND, CONTROLLER_FORMAT = "controller.json", "uavris-controller", 1
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
    """A policy named by the user, of a known kind (see the module docstring)."""

    name: str  # as written
    kind: TargetKind
    reference: str | None = None  # the reference's name (kind "reference")
    path: Path | None = None  # the directory (kinds "dt", "expert" and "value")
    top_k: int = 0  # kind "value": the top places valued by R (0: the learned value alone)
    trust_pickle: bool = False  # kind "expert": a run with SB3's pickled archive only may be loaded (--trust-pickle)

    def planner_model(self) -> Any:
        """A learned value's network (kind "value")."""
        from uavris.agents.place.checkpoint import load_value

        return load_value(self.path)[0]

    def goal_source(self) -> Any:
        """Where a goal-conditioned controller is told to go by this target: the learned
        planner's place (kind "value") or the planning oracle's target (the reference
        ``oracle``), per hall and start (:class:`uavris.agents.dt.goals.PlannedGoals`)."""
        from uavris.agents.dt.goals import PlannedGoals

        if self.kind == "value":
            from uavris.agents.place.planner import LearnedPlanner, PlaceSettings

            planner = LearnedPlanner(self.planner_model(), PlaceSettings(top_k=self.top_k))
            return PlannedGoals(planner.target, f"learned planner ({self.name})")
        if self.kind == "reference" and self.reference == "oracle":
            from uavris.agents.oracle import PlanningOracle

            oracle = PlanningOracle()
            return PlannedGoals(lambda config, start: oracle.plan(config, start).target, "planning oracle")
        raise ConfigError(f"{self.name} tells no goal (a learned value or the oracle does)")

    def own_system(self) -> SystemConfig:
        """The system the target was made for, read from its configuration only: a run's, a DT
        checkpoint's, or the paper's for a reference or a user's policy."""
        if self.kind == "dt":
            from uavris.agents.dt.checkpoint import dt_system

            return dt_system(self.path)
        if self.kind == "expert":
            from uavris.experiments.training.train_expert import load_run_config

            return load_run_config(self.path).system
        if self.kind == "controller":
            return read_controller(self.path).own_system()
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
        if self.kind == "dt":
            from uavris.agents.dt.policy import load_dt_policy

            dt = load_dt_policy(self.path, device=device)
            return Loaded(dt.policy, dt.system, dt.scenario, self.path)
        if self.kind == "controller":  # the row it holds, in its own system (its safety layer, if any)
            row = read_controller(self.path)
            return row.load(row.system(system or row.own_system()), device)
        if self.kind == "value":
            from uavris.agents.place.planner import LearnedPlanner, PlaceSettings

            system = system or SystemConfig()
            return Loaded(LearnedPlanner(self.planner_model(), PlaceSettings(top_k=self.top_k)), system, None,
                          self.path)
        from uavris.experiments.training.train_expert import load_run_policy

        cfg, policy = load_run_policy(self.path, device, self.trust_pickle)
        return Loaded(policy, cfg.system, cfg.resolved_scenario, self.path, cfg.expert_kind)

    @classmethod
    def of_reference(cls, name: str) -> Target:
        return cls(name, "reference", reference=name)

    @classmethod
    def of_model(cls, path: Path, kind: TargetKind = "dt") -> Target:
        """A DT model or an expert's run of a study, named by its directory (which may not exist yet)."""
        return cls(str(path), kind, path=Path(path))

    def file_name(self) -> str:
        """A user's policy as one part of a file's name: ``path/FILE.py:NAME`` as ``FILE_py_NAME``,
        ``pkg.module:NAME`` as ``pkg_module_NAME``."""
        where, attr = self.name.rsplit(":", 1)
        return file_part(f"{Path(where).name}_{attr}")

    def planner(self) -> str:
        """The planner this target is, as a goal source names it (:meth:`goal_source`)."""
        if self.kind == "value":
            return (f"semi-amortised planner (V's top {self.top_k} places and staying, valued by R)" if self.top_k
                    else "learned planner (V's argmax)")
        return "planning oracle" if self.kind == "reference" and self.reference == "oracle" else self.name

    def origin(self) -> str:
        """Where the policy comes from, as a result records it: a reference's name, a user's
        policy with its file's absolute path, a model's or run's absolute directory. Two targets
        that differ never share it (the name of a result file carries a hash of it)."""
        if self.kind == "reference":
            return f"reference {self.reference}"
        if self.kind == "user":
            where, attr = self.name.rsplit(":", 1)
            return f"{Path(where).resolve()}:{attr}" if where.endswith(".py") else self.name
        return str(Path(str(self.path)).resolve())

    def default_out(self) -> Path:
        """Where ``uavris evaluate`` writes when no ``--out`` is given."""
        if self.kind == "user":
            return Path("runs/policies") / self.file_name() / "eval"
        if self.kind == "reference":
            return Path("runs/baselines") / str(self.reference) / "eval"
        return Path(str(self.path)) / "eval"


def _is_user_policy(name: str) -> bool:
    """``MODULE:NAME`` or ``FILE.py:NAME`` (called after references and directories are ruled out)."""
    if name.count(":") != 1:
        return False
    where, attr = name.split(":")
    return bool(attr) and (where.endswith(".py") or bool(_MODULE.fullmatch(where)))


def resolve_target(name: str | Path, trust_pickle: bool = False) -> Target:
    """What ``name`` names (the module docstring's rules); one line naming the problem when it
    names nothing: an unknown baseline, a missing path, a file where a directory is expected.
    ``trust_pickle``: an expert's run with SB3's pickled archive only may be loaded."""
    name = str(name)
    path = Path(name)
    if name.startswith(BASELINE_PREFIX):
        ref = name[len(BASELINE_PREFIX):]
        if ref not in REFERENCES:
            raise UavrisError(f"unknown baseline {ref!r}; choose one of {', '.join(REFERENCES)}")
        return Target(name, "reference", reference=ref)
    if path.is_dir():
        from uavris.agents.dt.checkpoint import dt_model_dir
        from uavris.agents.place.checkpoint import is_value_dir

        if is_value_dir(path):
            return Target(name, "value", path=path)
        if (path / CONTROLLER_FILE).is_file():
            return Target(name, "controller", path=path)
        if dt_model_dir(path) is not None:
            return Target(name, "dt", path=path)
        if not (path / "config.yaml").is_file():
            raise UavrisError(f"{path} holds no policy uavris reads: none of config.yaml (a training run), model.json "
                              f"(a DT model), value.json (a learned value) or {CONTROLLER_FILE} (uavris export)")
        return Target(name, "expert", path=path, trust_pickle=trust_pickle)
    if name in REFERENCES:
        return Target(name, "reference", reference=name)
    if _is_user_policy(name):
        return Target(name, "user")
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
        return cls(name, REFERENCES[name].label, Target.of_reference(name), kind="reference", **how)

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
            from uavris.agents.oracle import PlanningOracle
            from uavris.agents.oracle.policy import PlannedFlight

            there = self.plan_of
            assert there is not None
            loaded = Loaded(PlannedFlight(PlanningOracle().plan(there.system, there.scenario.start)), there.system,
                            None, None)
        if self.level:
            from uavris.agents.policy import LevelAttitude

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
    t = target if isinstance(target, Target) else resolve_target(target)
    if t.kind == "controller":
        return read_controller(t.path)
    return Row(t.name, t.name, target=t)


# ------------------------------------------------------------------------------ controller directories
def write_controller(row: Row, dest: Path) -> Path:
    """``row`` as a directory of its own (``uavris export``): the files of its models (weights
    and JSON only) and ``controller.json`` (how the row evaluates them: its goal source, safety
    margin, level attitude, ensemble); :func:`read_controller` gives the row back. A row that
    flies another hall's plan is that hall's, not a controller: one line."""
    import shutil

    from uavris.io import write_json

    if row.plan_of is not None:
        raise ConfigError(f"{row.key} flies the plan of {row.plan_of.name}, a hall of the study: it is no controller "
                          "of its own to export")

    def copied(t: Target, folder: str) -> dict[str, Any]:
        if t.kind == "reference":
            return {"kind": "reference", "reference": t.reference}
        if t.kind not in ("dt", "value", "expert"):
            raise ConfigError(f"{row.key}: a {t.kind} target cannot be exported")
        src = t.path
        if t.kind == "dt":
            from uavris.agents.dt.checkpoint import dt_model_dir

            src = dt_model_dir(t.path)
        names = {"dt": ("model.safetensors", "model.json"), "value": ("value.safetensors", "value.json"),
                 "expert": ("config.yaml", "policy.safetensors", "policy.json")}[t.kind]
        (dest / folder).mkdir(parents=True, exist_ok=True)
        for name in names:
            shutil.copyfile(Path(src) / name, dest / folder / name)
        return {"kind": t.kind, "path": folder, "top_k": t.top_k}

    dest = Path(dest)
    record = {"kind": CONTROLLER_KIND, "format_version": CONTROLLER_FORMAT, "name": row.name, "label": row.label,
              "seed": row.seed, "front_margin_deg": row.front_margin_deg, "level": row.level,
              "target": copied(row.target, "model") if row.target is not None else None,
              "members": [copied(m, f"member-{i}") for i, m in enumerate(row.members)],
              "goal_from": copied(row.goal_from, "goal") if row.goal_from is not None else None}
    write_json(dest / CONTROLLER_FILE, record)
    return dest


def read_controller(path: Path) -> Row:
    """The row a controller directory holds (:func:`write_controller`); one line when it is not one."""
    from uavris.io import read_checkpoint_meta

    meta = read_checkpoint_meta(path, CONTROLLER_FILE, CONTROLLER_KIND, CONTROLLER_FORMAT, "a controller directory",
                                "a controller")

    def target(part: Any) -> Target | None:
        if part is None:
            return None
        if not isinstance(part, dict) or part.get("kind") not in ("reference", "dt", "value", "expert"):
            raise ConfigError(f"{path / CONTROLLER_FILE}: a part of the controller is {part!r}")
        if part["kind"] == "reference":
            return Target.of_reference(str(part["reference"]))
        folder = Path(path) / str(part["path"])
        if folder.resolve().parent != Path(path).resolve():  # the controller's own folders, nothing outside
            raise ConfigError(f"{path / CONTROLLER_FILE}: {part['path']!r} is not a folder of the controller")
        return dataclasses.replace(Target.of_model(folder, part["kind"]), top_k=int(part.get("top_k", 0)))

    try:
        return Row(str(meta["name"]), str(meta["label"]), target=target(meta["target"]),
                   members=tuple(target(m) for m in meta["members"]), goal_from=target(meta["goal_from"]),
                   seed=meta["seed"], front_margin_deg=meta["front_margin_deg"], level=bool(meta["level"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ConfigError(f"{path / CONTROLLER_FILE} is not a controller ({type(e).__name__}: {e})") from None
