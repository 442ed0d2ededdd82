"""A row of a report, the controller directory that holds one, and the one registry of what a
user names.

Lives here: :class:`Row`, a target (or an ensemble of them, or another hall's plan) with how a
report evaluates it (the attitude safety layer, the attitude held level) and what the report
calls it; the controller directory (:func:`write_controller`, ``uavris export``; read back by
:func:`read_controller` and by :class:`Controller`, the kind of target it is; the controller
shipped with the package is one, :data:`PRETRAINED`); and the registry: :func:`resolve_target`
reads a name once into a :class:`~uavris.experiments.tools.targets.Target` of the first kind of
:data:`TARGET_KINDS` that recognises it (:func:`register_target_kind` puts a new one first), and
:func:`as_row` makes any of these a row. Not here: the kinds themselves (:mod:`.targets`), which
rows a study has (:mod:`uavris.experiments.study.tracks`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

from uavris.agents.oracle import PlanningOracle
from uavris.agents.oracle.policy import PlannedFlight
from uavris.agents.policy import LevelAttitude
from uavris.agents.references import REFERENCES
from uavris.config import SystemConfig
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.tools.targets import (
    EXPORTED_KINDS,
    DTModel,
    ExpertRun,
    LearnedValue,
    Loaded,
    ModelDir,
    Reference,
    Target,
    UserPolicy,
)
from uavris.io import read_checkpoint_meta, refuse_links_out, write_json
from uavris.layouts import Site

CONTROLLER_FILE, CONTROLLER_KIND, CONTROLLER_FORMAT = "controller.json", "uavris-controller", 1
# The controller shipped with the package: the make run's goal-conditioned DT (seed 0) told the deployed place by
# its learned value (docs/results/pretrained.md); every command takes it by this name
PRETRAINED_NAME = "pretrained"
PRETRAINED = Path(__file__).resolve().parents[2] / "pretrained" / "deployment"
# What a row of a report is: a learned controller or place (the DT family, behaviour cloning, the learned
# planner), the expert trained where it is deployed, a policy transferred from a training deployment, a reference.
RowKind = Literal["learned", "expert", "transfer", "reference"]


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

    def own_system(self) -> SystemConfig:
        return read_controller(self.path).own_system()

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        row = read_controller(self.path)
        return row.load(row.system(system or row.own_system()), device)


TARGET_KINDS: list[type[Target]] = [Reference, LearnedValue, Controller, DTModel, ExpertRun, UserPolicy]


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
    """A row for what ``uavris evaluate`` takes: a row as it is, a controller directory as the row it
    holds, any other target (or its name) as a row of its own."""
    if isinstance(target, Row):
        return target
    found = target if isinstance(target, Target) else resolve_target(target)
    if isinstance(found, Controller):
        return read_controller(found.path)  # the row it holds: its goal source, safety layer, ensemble
    return Row(found.name, found.name, target=found)


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

