"""Resumable stages keyed by the hash of their resolved configuration.

A stage's key hashes its own configuration together with the keys of the stages it
depends on, so changing a parameter invalidates exactly that stage and everything
downstream of it, and nothing else. A stage runs in ``OUT/stages/NAME-KEY/`` and is
finished when ``stage.json`` exists there (written last, atomically); a rerun skips
finished stages, and an unfinished one is run again in the same folder, where the
training code resumes from its checkpoints.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from uavris.experiments.io import read_json, to_plain, write_json


@dataclass
class Stage:
    """One step of a pipeline: ``run(stage_dir, deps)`` with ``deps`` mapping names to dirs."""

    name: str
    config: dict[str, Any]
    run: Callable[[Path, dict[str, Path]], dict[str, Any] | None]
    deps: tuple[str, ...] = ()
    key: str = field(default="", init=False)


def stage_key(config: dict[str, Any], dep_keys: list[str]) -> str:
    blob = json.dumps({"config": to_plain(config), "deps": dep_keys}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


@dataclass
class StageRecord:
    name: str
    key: str
    directory: Path
    status: str  # "done", "skipped" (finished earlier), "failed"
    wall_s: float
    result: dict[str, Any] | None
    error: str | None = None


class Pipeline:
    """Stages in dependency order, each skipped when its keyed folder is finished."""

    def __init__(self, out: Path, stages: list[Stage]) -> None:
        self.out = Path(out)
        self.stages: dict[str, Stage] = {}
        for st in stages:
            missing = [d for d in st.deps if d not in self.stages]
            if missing:
                raise ValueError(f"stage {st.name} depends on unknown or later stages {missing}")
            st.key = stage_key(st.config, [self.stages[d].key for d in st.deps])
            self.stages[st.name] = st

    def directory(self, name: str) -> Path:
        st = self.stages[name]
        return self.out / "stages" / f"{name}-{st.key}"

    def is_done(self, name: str) -> bool:
        return (self.directory(name) / "stage.json").exists()

    def run(self, force: tuple[str, ...] = (), on_stage: Callable[[StageRecord], None] | None = None,
            stop_on_failure: bool = False) -> list[StageRecord]:
        unknown = [f for f in force if f not in self.stages]
        if unknown:
            raise ValueError(f"--force names unknown stage(s) {unknown}; stages: {list(self.stages)}")
        records: list[StageRecord] = []
        failed: set[str] = set()
        for name, st in self.stages.items():
            d = self.directory(name)
            if name in force and d.exists():
                shutil.rmtree(d)
            if any(dep in failed for dep in st.deps):
                rec = StageRecord(name, st.key, d, "failed", 0.0, None, "an upstream stage failed")
                failed.add(name)
            elif self.is_done(name):
                meta = read_json(d / "stage.json")
                rec = StageRecord(name, st.key, d, "skipped", float(meta.get("wall_s", 0.0)), meta.get("result"))
            else:
                d.mkdir(parents=True, exist_ok=True)
                t0 = time.perf_counter()
                try:
                    result = st.run(d, {dep: self.directory(dep) for dep in st.deps})
                except Exception as e:  # noqa: BLE001 - report the stage, let independent ones go on
                    rec = StageRecord(name, st.key, d, "failed", time.perf_counter() - t0, None,
                                      f"{type(e).__name__}: {e}")
                    failed.add(name)
                else:
                    wall = time.perf_counter() - t0
                    write_json(d / "stage.json", {"name": name, "key": st.key, "config": st.config,
                                                  "deps": {dep: self.stages[dep].key for dep in st.deps},
                                                  "wall_s": wall, "result": result})
                    rec = StageRecord(name, st.key, d, "done", wall, result)
            records.append(rec)
            if on_stage:
                on_stage(rec)
            if stop_on_failure and rec.status == "failed":
                break
        return records
