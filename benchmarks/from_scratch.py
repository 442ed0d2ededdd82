"""Fewer interactions, measured: fine-tuning in a new hall against an expert trained there from scratch.

The paper's claim: the pre-trained DT, fine-tuned in an unseen scenario, reaches the expert's
level "with fewer interactions". Here, in the deployment track of a finished study (``--study``,
``uavris reproduce --track deployment``), in its first ``--halls`` unseen halls (default 4):

- fine-tuning: the goal-conditioned DT fine-tuned by trying places (the study's
  ``deploy-finetune-places-LAYOUT`` stages, every pre-training seed, ``--ablation``): its level
  (the mean over seeds of the study's score of ``dt-goal-finetuned-safe``, 32 episodes; the
  zero-shot ``dt-goal-safe`` beside it) and the interactions it used (the mean over seeds of
  its ``env_interactions``);
- from scratch: hybrid PPO on the motion entries with the optimiser's phases (the strong
  track's learner, no imitation, the quick hyperparameters), trained in the hall from its
  start under the attitude safety layer, evaluated every ``--eval-every`` environment steps
  on the study's 32 evaluation episodes, for at most ``--steps`` steps: the first evaluation
  at or above the fine-tuned level.

Printed per hall: both levels, fine-tuning's interactions, the expert's (or "not within N"),
and their ratio (fine-tuning's over the expert's: a bound when the expert never got there).
Each PPO run is one process pinned to one core. The pre-training's own interactions (the
oracle's demonstrations in the training halls) are printed beside it: with them counted,
fine-tuning's interactions are those plus its own.

    .venv/bin/python benchmarks/from_scratch.py --study runs/ablation   # a study made with --ablation
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402  (benchmarks/_machine.py)


def stage(study: Path, name: str) -> dict:
    """A stage's record by its name (the folder is NAME-KEY: the name, then a 12-hex hash)."""
    found = [p for p in (study / "stages").glob(f"{name}-*") if len(p.name) == len(name) + 13]
    if len(found) != 1:
        raise SystemExit(f"{study}: expected one stage {name}-KEY, found {len(found)}")
    return json.loads((found[0] / "stage.json").read_text())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, required=True, help="a finished study with the deployment track")
    parser.add_argument("--halls", type=int, default=4, help="unseen halls (default: 4)")
    parser.add_argument("--steps", type=int, default=200_000, help="the expert's budget of environment steps")
    parser.add_argument("--eval-every", type=int, default=10_000, help="environment steps between evaluations")
    parser.add_argument("--json", type=Path, help="also write the per-hall numbers here (uavris claims --from-scratch)")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    import torch

    torch.set_num_threads(1)
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.tracks import SAFE_MARGIN_DEG, TRACK_SPECS
    from uavris.experiments.training.train_expert import TrainConfig, train
    from uavris.io import read_yaml

    spec = read_yaml(args.study / "study.yaml")
    rc = ReproduceConfig.from_dict({k: v for k, v in spec.items() if k in ReproduceConfig.__dataclass_fields__})
    track = TRACK_SPECS["deployment"]
    _, unseen = rc.sites(track)
    demos = stage(args.study, "deploy-dataset")["result"]
    print(f"# fewer interactions: fine-tuning against an expert from scratch\n- cpu: {cpu_model()}; {pinning}\n"
          f"- study: {args.study}; expert: hybrid PPO (quick hyperparameters), at most {args.steps:,} steps, "
          f"evaluated every {args.eval_every:,} on {rc.eval_episodes} episodes\n"
          f"- pre-training's demonstrations: {demos['slots']:,} environment steps "
          f"({demos['episodes']:,} episodes in {demos['halls']} halls)\n")
    rows = [("hall", "zero-shot level", "fine-tuned level", "fine-tuning's interactions", "expert's best",
             "expert reaches the fine-tuned level after", "fine-tuning / expert", "expert's training (s)")]
    measured = []
    for where in unseen[:args.halls]:
        res = stage(args.study, f"deploy-evaluate-{where.name}")["result"]
        seeds = [k for k in res if k.startswith("dt-goal-finetuned-safe")]
        level = float(np.mean([res[k]["mean"] for k in seeds]))
        zero_shot = float(np.mean([res[k]["mean"] for k in res if k.startswith("dt-goal-safe")]))
        used = []
        for k in seeds:
            suffix = k.split("@s")[1] if "@s" in k else None
            ft = stage(args.study, f"deploy-finetune-places-{where.name}" + (f"-s{suffix}" if suffix else ""))
            used.append(ft["result"]["env_interactions"])
        cfg = TrainConfig(algo="ppo", scenario=where.name, start=where.scenario.start, seed=0, preset="quick",
                          total_steps=args.steps, eval_every=args.eval_every, eval_episodes=rc.eval_episodes,
                          phase_control="optimizer", system=where.system.replace(front_margin_deg=SAFE_MARGIN_DEG))
        with tempfile.TemporaryDirectory() as tmp:
            began = time.perf_counter()
            train(cfg, Path(tmp) / "run", progress=False)
            wall = time.perf_counter() - began
            with open(Path(tmp) / "run" / "evals.csv", newline="") as f:
                evals = [(int(r["env_steps"]), float(r["mean"])) for r in csv.DictReader(f)]
        reached = next((steps for steps, mean in evals if mean >= level), None)
        mean_used = float(np.mean(used))
        rows.append((where.name, f"{zero_shot:.2f}", f"{level:.2f}", f"{mean_used:,.0f}",
                     f"{max(m for _, m in evals):.2f}",
                     f"{reached:,}" if reached else f"not within {args.steps:,}",
                     f"{mean_used / reached:.1%}" if reached else f"< {mean_used / args.steps:.1%}", f"{wall:.0f}"))
        print(table(rows), flush=True)
        measured.append({"hall": where.name, "level": level, "oracle": float(res["oracle-safe"]["mean"]),
                         "finetune_interactions": mean_used,
                         "expert_to_level": float(reached or args.steps), "reached": reached is not None,
                         "expert_steps": args.steps})
        if args.json:
            from uavris.io import write_json

            write_json(args.json, {"study": str(args.study), "cpu": cpu_model(), "halls": measured})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
