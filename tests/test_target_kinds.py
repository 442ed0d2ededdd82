"""A new kind of target is one class in the user's own module: every command that takes a
target reads it, and nothing of uavris is edited (tools/targets.py, "The kinds"; the registry in tools/rows.py)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from uavris.cli import main
from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.tools import rows
from uavris.experiments.tools.rows import Row, register_target_kind, resolve_target
from uavris.experiments.tools.targets import Loaded, ModelDir, Target


@dataclass(frozen=True)
class ConstantAction(ModelDir):
    """A directory holding one constant action (constant.json), the same in every slot."""

    kind: ClassVar[str] = "constant"
    marker: ClassVar[str] = "constant.json"

    def load(self, system: SystemConfig | None = None, device: str = "cpu") -> Loaded:
        system = system or SystemConfig()
        value = float(json.loads((self.path / self.marker).read_text())["action"])

        def policy(obs: np.ndarray) -> np.ndarray:
            return np.full((obs.shape[0], system.action_dim), value, dtype=np.float32)

        return Loaded(policy, system, None, self.path)


@pytest.fixture
def constant_kind(monkeypatch: pytest.MonkeyPatch) -> type[ConstantAction]:
    monkeypatch.setattr(rows, "TARGET_KINDS", list(rows.TARGET_KINDS))  # the registry as it was, after
    return register_target_kind(ConstantAction)


def _summary(out: Path) -> dict:
    return json.loads(next(out.glob("*.json")).read_text())


def test_a_kind_registered_in_a_test_module_is_read_by_the_command_line(
        constant_kind: type[ConstantAction], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    zero = tmp_path / "zero"
    zero.mkdir()
    (zero / "constant.json").write_text(json.dumps({"action": 0.0}))
    assert isinstance(resolve_target(str(zero)), ConstantAction)
    args = ["--scenario", "fig2", "--episodes", "3", "--no-progress"]
    assert main(["evaluate", str(zero), *args]) == 0  # its results where the kind says: beside its files
    assert main(["evaluate", "baseline:zero-action", *args, "--out", str(tmp_path / "ref")]) == 0
    mine, reference = _summary(zero / "eval"), _summary(tmp_path / "ref")
    # the all-zero action is the zero action: the same episodes give the same numbers
    assert mine["mean"] == pytest.approx(reference["mean"], abs=1e-12)
    assert mine["references"]["zero-action"]["mean"] == pytest.approx(reference["mean"], abs=1e-12)
    assert "of the oracle" in capsys.readouterr().out
    # a directory of none of the kinds names the new kind's file too, in one line
    (tmp_path / "empty").mkdir()
    assert main(["evaluate", str(tmp_path / "empty"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert "constant.json" in err and "controller.json" in err and "\n" not in err


def test_without_registering_it_the_directory_is_no_target(tmp_path: Path) -> None:
    (tmp_path / "constant.json").write_text(json.dumps({"action": 0.0}))
    with pytest.raises(UavrisError, match="holds no policy"):
        resolve_target(str(tmp_path))


@dataclass(frozen=True)
class Named(Target):
    """A kind held nowhere on disk: ``named:WORD``."""

    @classmethod
    def recognise(cls, name: str, trust_pickle: bool = False) -> Target | None:
        return cls(name) if name.startswith("named:") else None


def test_a_kind_without_files_is_written_under_runs_and_recorded_by_its_name(monkeypatch: pytest.MonkeyPatch,
                                                                             tmp_path: Path) -> None:
    monkeypatch.setattr(rows, "TARGET_KINDS", list(rows.TARGET_KINDS))
    register_target_kind(Named)
    a, b = resolve_target("named:one"), resolve_target("named:two")
    assert isinstance(a, Named) and a.origin() == "named:one" and a.origin() != b.origin()
    assert a.default_out() == Path("runs/policies/named_one/eval")
    # and it is no part of a controller directory (read_controller could not read it back)
    with pytest.raises(UavrisError, match="cannot be exported"):
        rows.write_controller(Row("mine", "mine", target=a), tmp_path / "c")


def test_a_controller_is_not_exported_again(tmp_path: Path) -> None:
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "controller.json").write_text("{}")
    again = resolve_target(str(tmp_path / "c"))
    assert isinstance(again, rows.Controller)
    with pytest.raises(UavrisError, match="cannot be exported"):
        rows.write_controller(Row("c", "c", target=again), tmp_path / "out")

