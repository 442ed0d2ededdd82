"""Command-line interface ``uavris COMMAND [FLAGS]``.

Commands:
  train               train a DRL expert (DDPG, PPO, SAC, TD3) in one scenario
  evaluate            evaluate a run, a DT model, a reference or your own policy on seeded episodes
  benchmark           score any of those on the study's protocol, beside the zero action and the oracle
  compare-algorithms  the paper's Fig. 2: several algorithms over several seeds
  collect             roll experts out into a Minari dataset
  pretrain-dt         pre-train the Decision Transformer offline (Algorithm 1, stage 1)
  finetune-dt         fine-tune it online in a scenario (Algorithm 1, stage 2)
  reproduce           the whole study in three tracks, with figures and report
  claims              the paper's claims judged in every track of one or more studies
  from-scratch        fine-tuning against an expert trained from scratch in a study's new halls
  export              a row of a study as one controller directory that every command takes
  plot                learning curves of one or more runs (PNG and PDF)
  plan                where the UAV should go in a hall: the oracle's plan and a rate map
  sweep               the sum rate of policies over a grid of one or two system parameters
  demo                a few simple policies side by side

Lives here: dispatch to a command and the one rule for failures: any bad input (a flag
that does not parse, a value out of range, a path that is missing or of the wrong kind, a
corrupt file) prints one line ``uavris: error: ...`` on stderr and exits with code 2; a
traceback means a bug. Not here: the flags of each command (:mod:`.training`,
:mod:`.evaluation`, :mod:`.tools`, :mod:`.claims`), which are the fields of the library's config dataclasses.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Callable

from uavris.errors import UavrisError

EXIT_BAD_INPUT = 2
# What `pip install 'uavris[train]'` adds (pyproject.toml): the experts, the DT and the study need it
TRAINING_STACK = ("torch", "stable_baselines3", "tensorboard", "minari", "h5py", "safetensors")
PROG = "uavris"


# Each command's module is imported only when it runs, so `uavris evaluate` does not load
# the training stack and `uavris --help` loads nothing.
COMMANDS: dict[str, tuple[str, str]] = {
    "train": ("training", "train_command"),
    "evaluate": ("evaluation", "evaluate_command"),
    "benchmark": ("evaluation", "benchmark_command"),
    "compare-algorithms": ("training", "compare_command"),
    "collect": ("tools", "collect_command"),
    "pretrain-dt": ("training", "pretrain_command"),
    "finetune-dt": ("training", "finetune_command"),
    "reproduce": ("training", "reproduce_command"),
    "claims": ("claims", "claims_command"),
    "from-scratch": ("claims", "from_scratch_command"),
    "export": ("tools", "export_command"),
    "plot": ("tools", "plot_command"),
    "plan": ("tools", "plan_command"),
    "sweep": ("evaluation", "sweep_command"),
    "demo": ("tools", "demo_command"),
}


def command(name: str) -> Callable[[list[str]], None]:
    """The function that runs command ``name`` on its arguments."""
    module, attr = COMMANDS[name]
    return getattr(importlib.import_module(f"uavris.cli.{module}"), attr)


def _usage() -> str:
    """``uavris --help``: the usage line, then the module docstring's list of commands."""
    commands = (__doc__ or "").split("Lives here:")[0].split("\n", 1)[1].strip()
    return (f"uavris: UAV-mounted RIS D2D simulator, DRL experts and Decision Transformer.\n\n"
            f"usage: {PROG} COMMAND [FLAGS]\n\n{commands}\n\n"
            f"`{PROG} COMMAND --help` lists a command's flags and what it writes.\n")


def _run(argv: list[str]) -> None:
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return
    from uavris.cli.parsing import UsageError

    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        raise UsageError(f"unknown command {name!r}; choose one of {', '.join(COMMANDS)} (see {PROG} --help)")
    from uavris.experiments.engine.jobs import configure_threads

    configure_threads(torch_now=False)  # one thread per process: the cores go to the jobs (engine.jobs)
    command(name)(rest)


RESUMABLE = ("train", "pretrain-dt", "finetune-dt")  # the commands with --resume (cli.options.RunOptions)
RERUN_REUSES = ("reproduce", "sweep")  # the commands whose rerun reuses what finished (stages, cells)


def _after_interrupt(argv: list[str] | None) -> str:
    """What to do after Ctrl-C, for the command interrupted (no command offers a flag it lacks)."""
    name = (list(sys.argv[1:] if argv is None else argv) or [""])[0]
    if name in RESUMABLE:
        return "; rerun with --resume to continue from the last checkpoint"
    if name in RERUN_REUSES:
        return "; rerun the same command to continue (what finished is reused)"
    return ""


def main(argv: list[str] | None = None) -> int:
    """Run ``uavris`` on ``argv`` (default: the process's); returns the exit code."""
    try:
        _run(list(sys.argv[1:] if argv is None else argv))
    except UavrisError as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted{_after_interrupt(argv)}", file=sys.stderr)
        return 130
    except ModuleNotFoundError as e:  # `pip install uavris` without its training extra
        root = (e.name or "").split(".")[0]
        if root not in TRAINING_STACK:
            raise
        print(f"{PROG}: error: this needs the training stack ({root} is not installed): "
              "pip install 'uavris[train]'", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as e:  # --help
        return int(e.code or 0) if not isinstance(e.code, str) else EXIT_BAD_INPUT
    except BrokenPipeError:  # `uavris ... --help | head`: the reader left, which is not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
