"""The controller shipped with the package: the make run's goal-conditioned DT and its learned value.

Lives here: :func:`ship` (a finished quick study's ``dt-goal-safe`` row, seed 0, exported into
the package's ``pretrained/deployment`` folder, with ``card.json``: the stage keys it came from
and its scores), :func:`make_keys` (the keys this code's make run makes for those stages, built
without running anything), :func:`stale_card` (where the shipped files' keys differ from them:
a stale shipped model is a failing test) and :func:`write_card_page` (its model card, stamped,
``docs/results/pretrained.md``). Not here: reading the shipped controller, which every command
takes by the name ``pretrained`` (:class:`uavris.experiments.tools.rows.Controller`).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import ORACLE
from uavris.errors import UavrisError
from uavris.experiments.display.tables import markdown_table, pct, with_ci
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.finished import Study
from uavris.experiments.study.pipeline import build_pipeline
from uavris.experiments.study.stage_names import DATASET, VALUE_LABELS, value_stage
from uavris.experiments.study.stamp import make_stamp, stamped
from uavris.experiments.study.tracks import TRACK_SPECS
from uavris.experiments.tools.rows import write_controller
from uavris.io import atomic_write_text, read_json, replace_folder, write_json
from uavris.stats import over_units

ROW = "dt-goal-safe"  # the deployment track's controller: the goal-conditioned DT told the deployed place
# what the shipped files come from: the demonstrations, V's labels, seed 0's V and goal-conditioned DT
STAGES = tuple(TRACK_SPECS["deployment"].stage(kind) for kind in (DATASET, VALUE_LABELS, value_stage(0), "goal"))
CARD = "card.json"


def make_keys(config: ReproduceConfig | None = None) -> dict[str, str]:
    """The keys of :data:`STAGES` in this code's make run (``uavris reproduce --preset quick``; or
    in the study of ``config``), from its pipeline built in a scratch folder, nothing run."""
    with tempfile.TemporaryDirectory() as tmp:
        pipeline = build_pipeline(config or ReproduceConfig("quick"), Path(tmp), StudyContext(1, "local", None))
        return shipped_keys(pipeline)


def shipped_keys(pipeline: Any) -> dict[str, str]:
    """The keys of :data:`STAGES` in ``pipeline`` (a study's): what the shipped files come from."""
    return {name: pipeline.stages[name].key for name in STAGES}


def scores(study: Study) -> list[dict[str, Any]]:
    """The row's fraction of the oracle (its seed 0's and the mean of its seeds) per device count
    of the study's unseen halls, with the Student-t 95% CI over halls."""
    track = TRACK_SPECS["deployment"]
    per: dict[tuple[int, str], list[tuple[float, float]]] = {}
    for w in study.sites(track)[1]:
        found = study.evaluation(track, w.name)
        if found is None:
            continue
        res = found[1]
        seeds = [v["mean"] for v in res.values() if v.get("variant") == ROW]
        if ROW in res and seeds:
            per.setdefault((w.devices, w.split), []).append((res[ROW]["mean"] / res[ORACLE]["mean"],
                                                              float(np.mean(seeds)) / res[ORACLE]["mean"]))
    return [{"devices": k, "halls": split, "n": len(v), "seed0": over_units([a for a, _ in v]),
             "seeds_mean": over_units([b for _, b in v])} for (k, split), v in sorted(per.items(), key=_card_order)]


def _card_order(item: tuple[tuple[int, str], Any]) -> tuple[int, bool]:
    """The card's order of its halls: by device count, the unseen halls before the other generator's."""
    (devices, split), _ = item
    return devices, split != "unseen"


def ship(study_dir: Path, dest: Path, made_by: ReproduceConfig | None = None,
         scored_in: Sequence[Path] = ()) -> Path:
    """Export the quick study ``study_dir``'s controller (:data:`ROW`, seed 0) into ``dest`` (put
    in place whole) with ``card.json``: the keys of :data:`STAGES` in that study, its preset and
    seed, and its scores (:func:`scores`), also in the halls of the studies ``scored_in`` (the
    device-count study: the same models, the same keys, or one line) where ``study_dir`` has
    none of that count and generator. The study must be this code's make run (or this code's
    study of ``made_by``: its keys :func:`make_keys`'s): the card would be stale at once."""
    study = Study.open(study_dir)
    keys = shipped_keys(study.pipeline)
    if keys != make_keys(made_by):
        raise UavrisError(f"{study_dir} is not this code's make run (its keys of {', '.join(STAGES)} are not this "
                          "code's): run `make run` and ship from its study")
    scored = {(s["devices"], s["halls"]): s for s in scores(study)}
    for other_dir in scored_in:
        other = Study.open(other_dir)
        if shipped_keys(other.pipeline) != keys:
            raise UavrisError(f"{other_dir} evaluates other models than {study_dir} (its keys of "
                              f"{', '.join(STAGES)} differ): its scores are not the shipped controller's")
        for s in scores(other):
            scored.setdefault((s["devices"], s["halls"]), s)
    unseen = study.sites("deployment")[1]
    row = study.row(ROW, "deployment", unseen[0])
    dest.parent.mkdir(parents=True, exist_ok=True)
    made = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", dir=dest.parent))
    try:
        write_controller(row, made)
        train = study.sites("deployment")[0]
        write_json(made / CARD, {"row": ROW, "seed": row.seed or 0, "preset": study.config.preset,
                                 "training_halls": len(train), "training_devices": sorted({w.devices for w in train}),
                                 "episodes_per_hall": study.config.layout_trajectories, "stage_keys": keys,
                                 "scores": [s for _, s in sorted(scored.items(), key=_card_order)]})
        made.chmod(0o755)
        replace_folder(made, dest, dest.with_name(f".{dest.name}.old"))
    finally:
        shutil.rmtree(made, ignore_errors=True)
    return dest


def stale_card(shipped: Path, made_by: ReproduceConfig | None = None) -> list[str]:
    """Where the shipped controller's stage keys differ from this code's make run's (or its study's
    of ``made_by``; empty: none)."""
    card = read_json(shipped / CARD)
    now = make_keys(made_by)
    return [f"{name}: shipped {card['stage_keys'].get(name)}, this code's make run {key}"
            for name, key in now.items() if card["stage_keys"].get(name) != key]


def write_card_page(shipped: Path, page: Path, command: str, studies: Sequence[str] = (),
                    scored_by: Sequence[str] = ()) -> Path:
    """The model card (``docs/results/pretrained.md``, stamped): what the shipped controller is, the
    data and halls it learned from, its scores at each device count with intervals, its stage keys;
    ``studies``: the studies it was shipped from and scored in (the stamp's); ``scored_by``: the
    commands of the studies that scored it at other device counts."""
    card = read_json(shipped / CARD)
    rows = [(f"{s['devices']} devices" + (", another generator" if s["halls"] == "other" else ""), str(s["n"]),
             with_ci(s["seed0"], pct), with_ci(s["seeds_mean"], pct)) for s in card["scores"]]
    lines = ["# The shipped controller", "",
             "`uavris evaluate pretrained`, `uavris benchmark pretrained` and `uavris plan HALL --learned pretrained` "
             "take the controller shipped with the package (`src/uavris/pretrained/deployment`): the make run's "
             "goal-conditioned DT (pre-training seed 0, a device-set encoder, under the attitude safety layer), told "
             "where to go by the deployed place of its learned value `V` (V proposes, R disposes: docs/places.md). "
             f"It learned from the planning oracle's demonstrations in {card['training_halls']} generated training "
             f"halls of {' or '.join(map(str, card['training_devices']))} devices ({card['episodes_per_hall']} "
             "episodes each); `V` from the optimised-phase rate `R` at poses of training halls of 3 to 8 "
             "devices, level and tilted, and the poses the demonstrations' teacher valued. It reads any number of "
             "devices (a set encoder); it was not trained on halls of another generator or of 10 devices.", "",
             f"Made by `{command}`"
             + "".join(f"; scored at the other device counts by `{line}`" for line in scored_by)
             + ". Its fraction of the oracle in the studies' unseen halls (mean [95% CI over halls]; the shipped "
             "seed, and the mean of the pre-training seeds' controllers):", "",
             *markdown_table(("halls", "n", "shipped (seed 0)", "mean of the seeds"), rows, "lrll"), "",
             "The stage keys it came from (a test fails when this code's make run makes others: the shipped "
             "model is then stale and shipped again):", "",
             *markdown_table(("stage", "key"), [(k, f"`{v}`") for k, v in card["stage_keys"].items()], "ll"), ""]
    stamp = make_stamp("pretrained", list(studies) or [str(shipped)], card["preset"], command)
    atomic_write_text(page, stamped(stamp, "\n".join(lines)))
    return page
