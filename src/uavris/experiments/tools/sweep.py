"""``uavris sweep``: the sum rate of policies over a grid of one or two system parameters.

Lives here: :class:`Axis` and :func:`parse_axis` (what ``--param NAME VALUES`` means),
:func:`sweep` (every cell and policy as a job of the engine, resumable, then the CSV and the
figure) and :func:`sweep_cell` (one job). Not here: what a policy name names
(:mod:`.targets`), the evaluation (:func:`uavris.agents.evaluation.evaluate`), the job runner
(:mod:`uavris.experiments.engine.jobs`).

The figures of every RIS paper: the sum rate against the transmit power, the number of
elements, the number of users, the Rician factor. A parameter is any numeric field of
:class:`~uavris.config.SystemConfig` (``rician_factor``, ``pathloss_exponent``,
``noise_dbm``, ``safety_distance``, ``nx``, ...), or one of three a paper states otherwise:

- ``tx_power_dbm``: the devices' transmit power in dBm (``tx_power_w = 10^(dBm/10) / 1000``);
- ``ris_size``: an ``n x n`` RIS (``nx = ny = n``, ``N = n^2`` elements);
- ``devices``: ``K`` devices, each cell over ``halls`` generated halls of K devices
  (:class:`~uavris.layouts.LayoutGenerator`, unseen split, layout seed 0), each from its own
  start; the interval is then over halls (each hall one sample), not over episodes.

A model (a run or a DT) that reads the devices' positions is given them in every cell, and a
DT with the device-set encoder reads the cell's number of devices whatever it was trained
on (:meth:`~uavris.agents.dt.model.DecisionTransformer.for_devices`): a devices sweep of a
deployment DT is its zero-shot transfer across the count.

Every policy is scored on the same seeded episodes in every cell (``EVAL_SEED ..``): the
curves differ by the parameter and the policy, never by the draws. A cell's result is a
JSON file under ``OUT/cells/`` named by a hash of everything that determines it (a rerun
skips the cells it finds), and ``OUT/sweep.csv`` / ``sweep.png`` / ``sweep.pdf`` are written
from all of them at the end.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from uavris.agents.evaluation import check_episodes, evaluate
from uavris.agents.policy import fit_policy
from uavris.config import SCENARIOS, Scenario, SystemConfig, get_scenario
from uavris.errors import ConfigError, UavrisError
from uavris.experiments.display.plots import plt, save_figure
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.engine.jobs import run_jobs
from uavris.experiments.engine.worker import Job
from uavris.experiments.tools.evaluate import hall_name, layout_origin, outside_training
from uavris.experiments.tools.rows import as_row, resolve_target
from uavris.io import other_inputs, read_json, to_plain, write_csv, write_json
from uavris.layouts import LayoutGenerator
from uavris.presets import EVAL_SEED
from uavris.runs.lock import locked
from uavris.stats import over_units, t_interval

VIRTUAL = {"tx_power_dbm": "transmit power (dBm)", "ris_size": "RIS size n (n x n elements)",
           "devices": "devices K (generated halls)"}
# An axis's label: the parameter's name as a reader of the figure says it, with its unit
# (SystemConfig's field comments), for every parameter parse_axis accepts (a test checks).
LABELS = {
    **VIRTUAL,
    "nx": "RIS elements along x (nx)", "ny": "RIS elements along y (ny)",
    "element_spacing": "element spacing (wavelengths)", "rician_factor": "Rician factor \u03ba",
    "pathloss_exponent": "path-loss exponent \u03b1", "tx_power_w": "transmit power (W)",
    "noise_dbm": "noise power (dBm)", "reference_gain_db": "path gain at 1 m (dB)", "slot_s": "slot length (s)",
    "horizon": "episode length T (slots)", "v_max": "largest UAV speed (m/s)",
    "a_max": "largest UAV acceleration (m/s\u00b2)", "attitude_step_deg": "largest attitude step per slot (\u00b0)",
    "z_min": "lowest UAV altitude (m)", "z_max": "highest UAV altitude (m)",
    "safety_distance": "safety distance (m)", "front_margin_deg": "RIS front margin (\u00b0)",
    "min_device_spacing": "least device spacing (m)", "energy_budget_j": "energy budget (J)",
    "max_active_pairs": "most active D2D pairs per slot", "channel_ref_distance": "channel observation scale (m)",
}
MAX_CELLS = 400  # a typo's bound (a range with a tiny step): beyond it a sweep takes days
COLUMNS = ("policy", "x", "y", "mean", "ci_low", "ci_high", "samples", "unit")


@dataclass(frozen=True)
class Axis:
    """One parameter of a sweep and its values."""

    name: str  # a SystemConfig field or a key of VIRTUAL
    values: tuple[float, ...]

    @property
    def label(self) -> str:
        """The axis's label: the parameter's name with its unit (:data:`LABELS`)."""
        return LABELS.get(self.name, self.name.replace("_", " "))

    @property
    def symbol(self) -> str:
        """A short name for legends: P (dBm), n, K or the field."""
        return {"tx_power_dbm": "P", "ris_size": "n", "devices": "K"}.get(self.name, self.name)

    def apply(self, system: SystemConfig, value: float) -> SystemConfig:
        """``system`` at this parameter's ``value`` (``devices`` is applied by the cell)."""
        if self.name == "tx_power_dbm":
            return system.replace(tx_power_w=10.0 ** (value / 10.0) / 1000.0)
        if self.name == "ris_size":
            return system.replace(nx=int(value), ny=int(value))
        if self.name == "devices":
            return system
        whole = self.name in ("nx", "ny", "horizon", "max_active_pairs")
        return system.replace(**{self.name: int(value) if whole else float(value)})


def sweepable() -> set[str]:
    """Every parameter a sweep may vary: SystemConfig's numeric fields and :data:`VIRTUAL`'s."""
    numeric = {f for f, v in vars(SystemConfig()).items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    numeric |= {"max_active_pairs", "front_margin_deg"}  # numbers whose default is None
    return numeric | set(VIRTUAL)


def parse_axis(name: str, spec: str) -> Axis:
    """``--param NAME VALUES``: ``NAME`` a parameter (``system.`` prefix and dashes allowed),
    ``VALUES`` ``start:stop:step`` (stop included) or ``v1,v2,...``; one line naming the problem."""
    key = name.removeprefix("system.").replace("-", "_")
    if key not in sweepable():
        raise ConfigError(f"--param {name}: not a numeric system parameter; choose one of "
                          f"{', '.join(sorted(sweepable()))}")
    try:
        if ":" in spec:
            start, stop, step = (float(x) for x in spec.split(":"))
            if not step > 0 or stop < start:
                raise ValueError
            count = int(math.floor((stop - start) / step + 1e-9)) + 1
            values = tuple(float(start + i * step) for i in range(count))
        else:
            values = tuple(float(x) for x in spec.split(","))
    except ValueError:
        raise ConfigError(f"--param {name} {spec}: values are start:stop:step (step > 0, stop >= start) or "
                          "v1,v2,...") from None
    bad = [v for v in values if not math.isfinite(v)]
    if bad:
        raise ConfigError(f"--param {name} {spec}: every value must be a finite number, got {bad[0]}")
    if not values or len(values) > MAX_CELLS:
        raise ConfigError(f"--param {name} {spec}: between 1 and {MAX_CELLS} values, got {len(values)}")
    if key in ("devices", "ris_size", "nx", "ny") and not all(v == int(v) and v >= (2 if key == "devices" else 1)
                                                            for v in values):
        raise ConfigError(f"--param {name} {spec}: whole numbers >= {2 if key == 'devices' else 1}")
    return Axis(key, values)


def cell_systems(base: SystemConfig, axes: Sequence[Axis], point: Sequence[float], halls: int,
                 scenario: str | Any | None) -> list[tuple[SystemConfig, Any]]:
    """The (system, start) pairs a cell is evaluated in: one, or ``halls`` generated halls of
    the cell's number of devices (``devices`` axis); checked before any job runs."""
    system = base
    for axis, value in zip(axes, point):
        system = axis.apply(system, value)
    devices = next((int(v) for a, v in zip(axes, point) if a.name == "devices"), None)
    if devices is None:
        where = get_scenario(scenario or "fig2")
        where.validate_for(system)
        return [(system, where)]
    gen = LayoutGenerator(devices=devices, seed=0)
    return [layout.resolve(system) for layout in gen.layouts("unseen", halls, system)]


def _key(payload: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(to_plain(payload), sort_keys=True).encode()).hexdigest()[:12]


def sweep_cell(target: str, system: dict[str, Any], scenario: dict[str, Any], episodes: int, out: str,
               trust_pickle: bool = False) -> None:
    """A job: ``target`` in one hall of one cell on episodes ``EVAL_SEED ..``; its mean and its
    per-episode rates to the JSON file ``out``."""
    cfg = SystemConfig.from_dict(system)
    row = as_row(resolve_target(target, trust_pickle))  # a controller's row: its safety layer, its goals
    if row.own_system().observe_devices:
        # A model that reads the devices' positions is given them: they add entries to the
        # observation and change nothing in the physics (the references' numbers stay).
        cfg = cfg.replace(observe_devices=True)
    cfg = row.system(cfg)
    loaded = row.load(cfg)
    policy = fit_policy(loaded.policy, cfg, target)
    res = evaluate(policy, cfg, Scenario(scenario["name"], tuple(scenario["start"])), episodes, EVAL_SEED)
    write_json(Path(out), {"target": target, "model": row.origin(), "mean": float(res.avg_sum_rate.mean()),
                           "rates": res.avg_sum_rate.tolist(), "system": cfg.to_dict(),
                           "scenario": scenario["name"], "start": list(scenario["start"])})


def sweep(targets: Sequence[str], axes: Sequence[Axis], out: Path, *, base: SystemConfig | None = None,
          scenario: str | Any | None = None, episodes: int = 16, halls: int = 4, workers: int = 1,
          backend: str = "local", progress: bool = False, trust_pickle: bool = False,
          warn: Callable[[str], None] | None = None, layout: str | None = None) -> list[Path]:
    """Every ``target`` in every cell of the grid of ``axes`` (one or two), written to ``out``
    (module docstring); returns the paths of the CSV and the figures. ``layout``: the layout the
    hall came from (the CLI's ``--layout``), recorded in ``sweep.json``."""
    if not 1 <= len(axes) <= 2 or len({a.name for a in axes}) != len(axes):
        raise ConfigError("a sweep takes one or two different --param")
    if not targets:
        raise ConfigError("name at least one policy to sweep (e.g. hover-optimizer oracle)")
    check_episodes(episodes, EVAL_SEED, "--")  # the command's flags
    if not 2 <= halls <= 1000:
        raise ConfigError(f"--halls must be in [2, 1000] (an interval over halls needs two), got {halls}")
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    base = base or SystemConfig()
    for t in targets:
        resolve_target(t)  # a name that names nothing: one line before anything runs
    grid = [(x,) for x in axes[0].values] if len(axes) == 1 else [(x, y) for x in axes[0].values
                                                                   for y in axes[1].values]
    if len(grid) > MAX_CELLS:
        raise ConfigError(f"the grid has {len(grid)} cells; at most {MAX_CELLS}")
    places = {point: cell_systems(base, axes, point, halls, scenario) for point in grid}  # every cell checked first
    if warn is not None:  # a trained model flown outside what it was trained in, once per policy
        for t in targets:
            row = as_row(resolve_target(t, trust_pickle))
            found = next((w for where in places.values() for system, _ in where
                          if (w := outside_training(row, system, policy_label(t)))), None)
            if found:
                warn(found)
    spec = {"targets": list(targets), "axes": [to_plain(a) for a in axes], "episodes": episodes, "seed": EVAL_SEED,
            "halls": halls, "scenario": scenario, "system": base.to_dict(),
            **({"layout": layout_origin(layout)} if layout is not None else {})}
    old = other_inputs(Path(out) / "sweep.json", spec)
    if old is not None:
        raise ConfigError(f"{out} holds another sweep ({'; '.join(spec_differences(old, spec))}); give this one "
                          "another --out (its cells would be kept, its table and figure replaced)")
    hall = swept_hall(base, scenario, axes, halls)
    with locked(out, "uavris sweep"):  # one invocation writes a sweep at a time
        return _run(targets, axes, Path(out), places, spec, episodes, workers, backend, progress, trust_pickle, hall)


def spec_differences(stored: Any, spec: dict[str, Any]) -> list[str]:
    """What makes the sweep stored in a folder (its ``sweep.json``) another one than ``spec``,
    "there" against "here", in a user's words. A hall changes without a flag changing (a
    device moved in a layout file, a generated layout of another generator): the refusal
    names the device or the room, so the user is not left looking for a parameter."""
    old = stored if isinstance(stored, dict) else {}
    new = to_plain(spec)
    out = []
    if old.get("targets") != new["targets"]:
        out.append(f"the policies differ: {', '.join(map(str, old.get('targets') or []))} there")
    if old.get("axes") != new["axes"]:
        out.append(f"the parameters differ: {_axes_text(old.get('axes'))} there")
    old_system = old.get("system") if isinstance(old.get("system"), dict) else {}
    hall = _hall_changes(old_system, new["system"])
    if hall:
        out.append("the hall differs: " + ", ".join(hall))
    if old.get("scenario") != new["scenario"]:
        out.append(f"the start differs: {_start(old.get('scenario'))} there, {_start(new['scenario'])} here")
    other = [k for k in new["system"] if k not in ("users", "room") and old_system.get(k) != new["system"][k]]
    if other:
        out.append("the system differs: " + ", ".join(f"{k} {_text(old_system.get(k))} there, "
                                                      f"{_text(new['system'][k])} here" for k in other))
    out += [f"{key} {_text(old.get(key))} there, {new[key]} here" for key in ("episodes", "halls", "seed")
            if old.get(key) != new[key]]
    return out or ["made by another version of uavris"]


def _hall_changes(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """How the stored system's hall (its devices and room) differs from ``new``'s."""
    changes = []
    before, after = old.get("users") or [], new["users"]
    if len(before) != len(after):
        changes.append(f"{len(before)} devices there, {len(after)} here")
    else:
        changes += [f"device {k + 1} moved from {_text(a)} to {_text(b)}"
                    for k, (a, b) in enumerate(zip(before, after)) if a != b]
    if old.get("room") != new["room"]:
        changes.append(f"the room is {_text(old.get('room'))} m there, {_text(new['room'])} m here")
    return changes


def _text(value: Any) -> str:
    """A stored value as a message shows it: numbers without trailing zeros, lists bracketed."""
    if isinstance(value, list):
        return "[" + ", ".join(_text(v) for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _axes_text(axes: Any) -> str:
    """Stored axes as "name v1, v2 and name v1, v2"."""
    return " and ".join(f"{a.get('name')} {', '.join(_text(v) for v in a.get('values', []))}"
                        for a in axes or [] if isinstance(a, dict)) or "none"


def _start(scenario: Any) -> str:
    """A stored scenario: a name (None: fig2's) or a layout's ``{name, start}``."""
    if isinstance(scenario, dict):
        return f"{scenario.get('name')} {_text(scenario.get('start'))}"
    return str(scenario or "fig2")


def swept_hall(base: SystemConfig, scenario: str | Any | None, axes: Sequence[Axis], halls: int) -> str:
    """Where the sweep flew, for its figure's title: a rate is a hall's, and the same policy
    scores differently in another (the paper's hall and a start of it, a layout by its name,
    or a devices sweep's generated halls)."""
    if any(a.name == "devices" for a in axes):
        return f"{halls} generated halls per device count (layout seed 0)"
    where = get_scenario(scenario or "fig2")
    if where.name in SCENARIOS:  # a start of the paper's hall, in it or in devices of --system.users
        return f"{hall_name(base, None, where.name)}, start {where.name}"
    return hall_name(base, where.name, where.name)


def _run(targets: Sequence[str], axes: Sequence[Axis], out: Path, places: dict[tuple, list], spec: dict[str, Any],
         episodes: int, workers: int, backend: str, progress: bool, trust_pickle: bool, hall: str) -> list[Path]:
    jobs, files = [], {}
    for point, where in places.items():
        for target in targets:
            for i, (system, start) in enumerate(where):
                payload = {"target": target, "system": system.to_dict(), "start": list(start.start),
                           "episodes": episodes, "seed": EVAL_SEED}
                path = Path(out) / "cells" / f"{_key(payload)}.json"
                files[(target, point, i)] = path
                if not path.exists():
                    jobs.append(Job(f"{target} {point} {i}", sweep_cell,
                                    (target, system.to_dict(), {"name": start.name, "start": list(start.start)},
                                     episodes, str(path), trust_pickle), Path(out) / "logs" / f"{path.stem}.log"))
    with progress_bar(len(jobs), "sweep", "cell", progress) as bar:
        results = run_jobs(jobs, workers, lambda r: bar.update(1), backend=backend)
    failed = [r for r in results if not r.ok]
    if failed:
        raise UavrisError(f"{len(failed)} of {len(jobs)} sweep cells failed; first: {failed[0].name}: "
                          f"{failed[0].error} (log {failed[0].log})")
    rows = _rows(targets, axes, places, files)
    # the columns of the parameters carry their names (x and y only inside this module)
    columns = ["policy", axes[0].name, *([axes[1].name] if len(axes) > 1 else []), *COLUMNS[3:]]
    write_csv(Path(out) / "sweep.csv", columns,
              [[r["policy"], r["x"], *([r["y"]] if len(axes) > 1 else []), *(r[c] for c in COLUMNS[3:])]
               for r in rows])
    write_json(Path(out) / "sweep.json", spec)
    return [Path(out) / "sweep.csv", *sweep_figure(rows, axes, Path(out) / "sweep", hall)]


def policy_label(target: str) -> str:
    """A legend's name for a policy: a reference's name, a model's folder (not its whole path)."""
    path = Path(target)
    if len(path.parts) < 2:
        return target
    return path.parent.name if path.name in ("model", "value") else path.name


def _rows(targets: Sequence[str], axes: Sequence[Axis], places: dict[tuple, list], files: dict) -> list[dict]:
    """One row per (policy, cell): the mean with its Student-t 95% interval over the episodes,
    or over the halls where the cell is over generated halls."""
    rows = []
    for target in targets:
        for point, where in places.items():
            cells = [read_json(files[(target, point, i)]) for i in range(len(where))]
            if len(cells) == 1:
                rates = np.asarray(cells[0]["rates"])
                low, high = t_interval(rates)
                mean, samples, unit = float(rates.mean()), len(rates), "episodes"
            else:
                s = over_units([c["mean"] for c in cells])
                mean, low, high, samples, unit = s["mean"], s["ci_low"], s["ci_high"], s["n"], "halls"
            rows.append({"policy": target, "x": point[0], "y": point[1] if len(point) > 1 else "",
                         "mean": mean, "ci_low": low, "ci_high": high, "samples": samples, "unit": unit})
    return rows


def sweep_figure(rows: list[dict], axes: Sequence[Axis], stem: Path, hall: str) -> list[Path]:
    """The sum rate against the first parameter, a line with its 95% band per policy (and per
    value of the second parameter, by line style), on the parameter's natural axis; the title
    names the ``hall`` swept (:func:`swept_hall`)."""
    fig, ax = plt.subplots(figsize=(4.8, 3.6))
    styles = ("-", "--", ":", "-.")
    ys = sorted({r["y"] for r in rows}, key=lambda v: (v == "", v))
    for i, target in enumerate(dict.fromkeys(r["policy"] for r in rows)):
        color = f"C{i}"
        for j, y in enumerate(ys):
            part = sorted((r for r in rows if r["policy"] == target and r["y"] == y), key=lambda r: r["x"])
            x = [r["x"] for r in part]
            label = policy_label(target) + (f", {axes[1].symbol} = {y:g}" if y != "" else "")
            ax.plot(x, [r["mean"] for r in part], styles[j % len(styles)], color=color, marker="o", ms=3,
                    lw=1.3, label=label)
            # a rate's interval, as every command shows it, bounded below at 0 (sweep.csv keeps the raw one)
            ax.fill_between(x, [max(0.0, r["ci_low"]) for r in part], [r["ci_high"] for r in part], color=color,
                            alpha=0.15,
                            lw=0)
    if axes[0].name in ("ris_size", "nx", "ny") and min(r["x"] for r in rows) > 0:
        ax.set_xscale("log", base=2)
    ax.set_xlabel(axes[0].label)
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(f"{hall}\nmean and 95% CI (over " + rows[0]["unit"] + ")"
                 + (f"; {axes[1].symbol}: {axes[1].label}" if len(axes) > 1 else ""), fontsize=8)
    ax.legend(fontsize=6, frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return save_figure(fig, stem)
