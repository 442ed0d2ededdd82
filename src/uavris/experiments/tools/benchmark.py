"""``uavris benchmark``: any target on the study's protocol, in one table comparable with the report.

Lives here: the protocol's cells (:func:`protocol_cells`: the paper's unseen scenarios and
the deployment track's unseen layouts) and :func:`benchmark`, which scores a target beside
the zero action and the oracle in every cell. Not here: resolving and evaluating a target
(:mod:`uavris.experiments.tools.evaluate`, the code ``uavris evaluate`` runs, so a cell's numbers
equal ``uavris evaluate TARGET --scenario S`` / ``--layout L`` on the same episodes).

The protocol is the report's (docs/study.md, section 2): the preset's evaluation episodes
(:data:`~uavris.presets.STUDY`) from :data:`~uavris.presets.EVAL_SEED`, the unseen scenarios
of the paper in the paper's hall, and the preset's unseen layouts of the study's generator
(seed 0). Fractions of the oracle are per cell; over layouts, their mean with a Student-t 95%
interval (each layout one sample; printed from :data:`MIN_UNITS_FOR_CI` layouts on, since two
give one degree of freedom and an interval such as 84.2% [11.5, 156.8]); against the zero
action, the paired difference on the same episodes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
from uavris.config import UNSEEN_SCENARIOS, ConfigError, SystemConfig, get_scenario
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.display.tables import counted, interval, markdown_table, num, pct, rate_interval, signed
from uavris.experiments.tools.evaluate import evaluate_target, layout_origin
from uavris.experiments.tools.rows import as_row, resolve_target
from uavris.experiments.tools.targets import Target
from uavris.float_paths import warn_if_unpinned
from uavris.io import atomic_write_text, other_inputs, read_csv, write_csv, write_json
from uavris.layouts import resolve_layout
from uavris.presets import EVAL_SEED, STUDY, check_preset
from uavris.stats import over_units, t_interval

Cells = Literal["all", "scenarios", "layouts"]
MIN_UNITS_FOR_CI = 3  # an interval over cells (halls, scenarios) is printed from this many on
COLUMNS = ("cell", "kind", "mean", "ci_low", "ci_high", "zero_action", "hover_optimizer", "oracle", "bound",
           "fraction_of_oracle", "minus_zero_action", "minus_zero_action_low", "minus_zero_action_high",
           "minus_hover_optimizer", "minus_hover_optimizer_low", "minus_hover_optimizer_high", "minus_oracle",
           "minus_oracle_low", "minus_oracle_high")


@dataclass(frozen=True)
class Cell:
    """One place of the protocol: a scenario of the paper's hall, or an unseen layout."""

    name: str
    kind: str  # "scenario" or "layout"
    ref: str | None = None  # what resolves the layout when it is not the name (a YAML file's path)

    @property
    def hall(self) -> str:
        return self.ref or self.name


def protocol_cells(preset: str, cells: Cells = "all") -> list[Cell]:
    check_preset(preset)
    out = []
    if cells in ("all", "scenarios"):
        out += [Cell(s, "scenario") for s in UNSEEN_SCENARIOS]
    if cells in ("all", "layouts"):
        out += [Cell(f"layout-unseen-{j}", "layout") for j in range(STUDY[preset]["unseen_layouts"])]
    return out


def _episodes(path: Path) -> np.ndarray:
    return np.array([float(r["avg_sum_rate"]) for r in read_csv(path.with_suffix(".csv"))])


def default_benchmark_dir(target: str) -> Path:
    """Where ``benchmark`` writes without ``--out``: runs/benchmarks/ and the target's last part
    (a study's row: its key)."""
    return Path("runs/benchmarks") / Path(target.replace(":", "_")).name


def benchmark(target: str, preset: str = "quick", cells: Cells = "all", out: Path | None = None,
              device: str = "cpu", progress: bool = False, system: SystemConfig | None = None,
              phase_control: str | None = None, layout: str | None = None, trust_pickle: bool = False
              ) -> tuple[list[dict[str, Any]], Path]:
    """Score ``target`` (whatever ``uavris evaluate`` takes; ``trust_pickle``: an expert's run with
    SB3's pickled archive only may be loaded) and the references in every cell.

    Writes OUT/CELL/ (each policy's per-episode CSV and summary JSON, as ``uavris evaluate``
    writes them) and OUT/benchmark.{csv,json,md}. Returns the rows and the markdown path.
    ``layout`` (a hall :func:`~uavris.layouts.resolve_layout` reads) is the one cell instead.
    """
    warn_if_unpinned("benchmark")  # a result meant to be compared with another machine's
    check_preset(preset)
    episodes = STUDY[preset]["eval_episodes"]
    resolved = resolve_target(target, trust_pickle)
    system = system or resolved.own_system()
    # --layout: the user's own hall (its devices and start) instead of the protocol's cells
    todo = [Cell(Path(layout).stem, "layout", layout)] if layout is not None else protocol_cells(preset, cells)
    for cell in todo:  # every cell fits the target's system before any rollout: one line, nothing written
        try:
            if cell.kind == "layout":
                resolve_layout(cell.hall, system).resolve(system)
            else:
                get_scenario(cell.name).validate_for(system)
        except ConfigError as e:
            raise ConfigError(f"benchmark cell {cell.name} does not fit the system: {e}") from None
    out = Path(out) if out is not None else default_benchmark_dir(target)
    inputs = {"target": target, "model": as_row(resolved).origin(), "preset": preset,
              "cells": [c.name for c in todo], "layout": layout_origin(layout), "system": system.to_dict(),
              "phase_control": phase_control}
    old = other_inputs(out / "benchmark.json", inputs, "inputs")
    if old is not None:
        raise ConfigError(f"{out} holds the benchmark of {old.get('target') if isinstance(old, dict) else 'another'} "
                          "target or protocol; give this one another --out (nothing there is replaced)")
    rows = []
    with progress_bar(len(todo), "benchmark", "cell", progress) as bar:
        for cell in todo:
            rows.append(_cell(resolved, cell, episodes, out / cell.name, system, phase_control, device))
            bar.update(1)
    # the system of the hall benchmarked where there is one (--layout); each cell records its own hall
    summary = {"inputs": inputs, "target": target, "model": inputs["model"], "preset": preset, "episodes": episodes,
               "seed": EVAL_SEED, "layout": inputs["layout"],
               "system": rows[0]["hall"]["system"] if layout is not None else system.to_dict(), "cells": rows,
               "over": _over(rows)}
    write_csv(out / "benchmark.csv", COLUMNS, ([r[c] for c in COLUMNS] for r in rows))
    write_json(out / "benchmark.json", summary)
    md = out / "benchmark.md"
    atomic_write_text(md, benchmark_table(summary))
    return rows, md


def _cell(target: Target, cell: Cell, episodes: int, out: Path, system: SystemConfig, phase_control: str | None,
          device: str) -> dict[str, Any]:
    """The target, the zero action and the oracle in one cell, each written under ``out``."""
    # a scenario of the paper is a start in the paper's hall, whatever hall the target was trained in
    place = dict(scenario=cell.name, layout="paper") if cell.kind == "scenario" else dict(scenario=None,
                                                                                           layout=cell.hall)
    paths, warning = {}, None
    for key, who in (("target", target), (ZERO_ACTION, ZERO_ACTION), (HOVER_OPTIMIZER, HOVER_OPTIMIZER),
                     (ORACLE, ORACLE)):
        pc = phase_control if key == "target" else None
        summary, paths[key] = evaluate_target(who, episodes=episodes, seed=EVAL_SEED, out=out / key, phase_control=pc,
                                              device=device, system=system, references=False, **place)
        warning = warning or summary.get("warning")
        if key == "target":
            hall = {k: summary[k] for k in ("hall", "layout", "start", "system")}
            bound = summary["bound"]["mean"]
    x, zero, hover, oracle = (_episodes(paths[k]) for k in ("target", ZERO_ACTION, HOVER_OPTIMIZER, ORACLE))
    low, high = t_interval(x)
    d_low, d_high = t_interval(x - zero)
    paired = {}  # the target minus each reference, per episode (the same episodes): mean and t interval
    for name, ref in (("hover_optimizer", hover), ("oracle", oracle)):
        lo, hi = t_interval(x - ref)
        paired.update({f"minus_{name}": float((x - ref).mean()), f"minus_{name}_low": lo, f"minus_{name}_high": hi})
    return {"cell": cell.name, "kind": cell.kind, "mean": float(x.mean()), "ci_low": low, "ci_high": high,
            "zero_action": float(zero.mean()), "oracle": float(oracle.mean()), "bound": bound,
            "fraction_of_oracle": float(x.mean() / oracle.mean()), "minus_zero_action": float((x - zero).mean()),
            "minus_zero_action_low": d_low, "minus_zero_action_high": d_high, "hover_optimizer": float(hover.mean()),
            **paired, "hall": hall, **({"warning": warning} if warning else {})}


def _over(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per kind of cell: the fraction of the oracle and the gain over the zero action, over cells."""
    out = {}
    for kind in ("scenario", "layout"):
        part = [r for r in rows if r["kind"] == kind]
        if part:
            out[kind] = {"fraction_of_oracle": over_units([r["fraction_of_oracle"] for r in part]),
                         "minus_zero_action": over_units([r["minus_zero_action"] for r in part])}
    return out


def benchmark_table(summary: dict[str, Any]) -> str:
    """The benchmark as markdown: one row per cell, then the means over cells of each kind."""
    def percent(x: float) -> str:
        return f"{100 * x:.1f}"

    def minus(r: dict[str, Any], ref: str) -> str:
        return f"{signed(r[f'minus_{ref}'])} {interval(r[f'minus_{ref}_low'], r[f'minus_{ref}_high'], signed)}"

    rows = [(r["cell"], f"{num(r['mean'])} {rate_interval(r['ci_low'], r['ci_high'])}", num(r["zero_action"]),
             num(r["hover_optimizer"]), num(r["oracle"]), num(r.get("bound")), pct(r["fraction_of_oracle"]),
             minus(r, "zero_action"),
             minus(r, "hover_optimizer"), minus(r, "oracle"))
            for r in summary["cells"]]
    for kind, s in summary["over"].items():
        f, d = s["fraction_of_oracle"], s["minus_zero_action"]
        if f["n"] < 2:
            continue  # one cell is its own row
        few = f"[n/a: {f['n']} {kind}{'s' * (f['n'] != 1)}]"  # Student's t on 1 degree of freedom reads nothing
        ci = interval(f["ci_low"], f["ci_high"], percent) if f["n"] >= MIN_UNITS_FOR_CI else few
        dci = interval(d["ci_low"], d["ci_high"], signed) if d["n"] >= MIN_UNITS_FOR_CI else few
        rows.append((f"**mean over {f['n']} {kind}s** (95% CI over {kind}s)", "", "", "", "", "",
                     f"{percent(f['mean'])}% {ci}", f"{signed(d['mean'])} {dci}", "", ""))
    where = ("on the study's protocol" if summary.get("layout") is None else
             f"in your hall {Path(summary['layout']).name} (the protocol's episodes)")
    lines = [f"# {summary['target']} {where} ({summary['preset']} preset)", "",
             f"{counted(summary['episodes'], 'episode')} per cell from seed {summary['seed']}, the same as the "
             f"report's; average sum rate in bps/Hz, 95% CIs over episodes (a rate's bounded below at 0); the "
             "differences are paired on the same episodes. The means over cells have a "
             f"Student-t 95% CI over cells from {MIN_UNITS_FOR_CI} cells on (n/a with fewer: on one degree of "
             "freedom the interval spans more than the values it summarises).", "",
             *markdown_table(("cell", "target [95% CI]", "zero action", "hover, optimiser's phases", "oracle",
                              "bound (no controller above)", "fraction of oracle", "target - zero action [95% CI]",
                              "target - hover, optimiser's phases [95% CI]", "target - oracle [95% CI]"), rows,
                             "lrrrrrrrrr")]
    return "\n".join(lines) + "\n"
