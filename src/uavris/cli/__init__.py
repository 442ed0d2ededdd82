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
  pages               every results page from one version: the studies they read, run, and the pages stamped
  export              a row of a study as one controller directory that every command takes
  plot                learning curves of one or more runs (PNG and PDF)
  plan                where the UAV should go in a hall: the oracle's plan and a rate map
  sweep               the sum rate of policies over a grid of one or two system parameters
  demo                a few simple policies side by side

Lives here: dispatch to a command and the one rule for failures: any bad input (a flag
that does not parse, a value out of range, a path that is missing or of the wrong kind, a
corrupt file) prints one line ``uavris: error: ...`` on stderr and exits with code 2; a
traceback means a bug. Ctrl-C and SIGTERM stop the command and its workers, print one line and
exit with 130 and 143 (:class:`_OnStop`). Not here: the flags of each command (:mod:`.training`,
:mod:`.evaluation`, :mod:`.tools`, :mod:`.claims`), which are the fields of the library's config dataclasses.
"""

from __future__ import annotations

import _thread
import contextlib
import errno
import importlib
import os
import signal
import sys
import threading
import warnings
from types import FrameType
from typing import Any, Callable, Iterator

from uavris.errors import UavrisError
from uavris.experiments.engine.process import configure_threads
from uavris.physics.phase_opt import CompileNotice  # loaded by `import uavris` already (env.wrappers)

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT  # 130, what a shell reports for a process Ctrl-C ended
EXIT_TERMINATED = 128 + signal.SIGTERM  # 143, likewise for SIGTERM
# What `pip install 'uavris[train]'` adds (pyproject.toml): the experts, the DT and the study need it
TRAINING_STACK = ("torch", "stable_baselines3", "tensorboard", "minari", "h5py", "safetensors")
PROG = "uavris"
NOTICES = (CompileNotice,)  # the warnings a command shows as one line `uavris: ...` (_notices)


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
    "pages": ("claims", "pages_command"),
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

    configure_threads(torch_now=False)  # one thread per process: the cores go to the jobs (engine.process)
    command(name)(rest)


RESUMABLE = ("train", "pretrain-dt", "finetune-dt")  # the commands with --resume (cli.outputs.RunOptions)
RERUN_REUSES = ("reproduce", "sweep")  # the commands whose rerun reuses what finished (stages, cells)


def _after_interrupt(argv: list[str] | None) -> str:
    """What to do after Ctrl-C or SIGTERM, for the command stopped (no command offers a flag it lacks)."""
    name = (list(sys.argv[1:] if argv is None else argv) or [""])[0]
    if name in RESUMABLE:
        return "; rerun with --resume to continue from the last checkpoint"
    if name in RERUN_REUSES:
        return "; rerun the same command to continue (what finished is reused)"
    return ""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system at its time limit, a container being stopped), raised in
    the main thread as Ctrl-C raises KeyboardInterrupt. A KeyboardInterrupt, so that every path
    that stops on Ctrl-C (a job runner's context closing with abort, a ``finally``) stops on it
    too; the default action would end the command at once and leave its workers running."""


class _OnStop:
    """The Ctrl-C and SIGTERM handler of one :func:`main`. The first of them has a thread stop
    the job runners' workers (:func:`~uavris.experiments.engine.jobs.abort_runners`): the main
    thread unwinds at once, but a study waits for its stage threads, and they for their jobs,
    before it closes its runner, so that without it the study would go on to their end (SIGTERM
    reaches the command alone, and the pool's workers ignore Ctrl-C: stopping them is this
    handler's work)."""

    def __init__(self) -> None:
        self.first: int | None = None  # the signal that stops the command
        self.stopped = threading.Event()

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        if self.first is None:
            self.first = signum
            # _thread, not threading.Thread: its start takes a lock that the interrupted main thread may hold
            _thread.start_new_thread(self._stop_workers, ())
        elif signum == signal.SIGTERM:
            return  # a second SIGTERM (`kill` again) must not cut the cleanup short; Ctrl-C may
        raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt

    def _stop_workers(self) -> None:
        try:
            jobs = sys.modules.get("uavris.experiments.engine.jobs")  # not imported: no runner to stop
            if jobs is not None:
                jobs.abort_runners()
        finally:
            self.stopped.set()

    def join(self) -> None:
        """Wait until the workers are stopped (the command's own unwinding waits for it too)."""
        if self.first is not None:
            self.stopped.wait()


@contextlib.contextmanager
def _stopping_on_signals() -> Iterator[_OnStop]:
    """Ctrl-C and SIGTERM stop the command in the block (:class:`_OnStop`); the previous
    handlers are back after it. Only the main thread may set a handler: elsewhere (a library
    calling :func:`main` from a thread) the signals keep theirs. Ctrl-C is left alone where
    Python does not raise KeyboardInterrupt for it (ignored, in a shell's background job)."""
    handler = _OnStop()
    if threading.current_thread() is not threading.main_thread():
        yield handler
        return
    ours = [signal.SIGTERM] + ([signal.SIGINT] if signal.getsignal(signal.SIGINT) is signal.default_int_handler else [])
    previous = {signum: signal.signal(signum, handler) for signum in ours}
    try:
        yield handler
    finally:
        for signum, old in previous.items():
            signal.signal(signum, signal.SIG_DFL if old is None else old)


def main(argv: list[str] | None = None) -> int:
    """Run ``uavris`` on ``argv`` (default: the process's); returns the exit code."""
    with _stopping_on_signals() as stop, _notices():
        return _main(argv, stop)


@contextlib.contextmanager
def _notices() -> Iterator[None]:
    """What the library says while a command runs (the optimiser being compiled, once), as one line
    ``uavris: ...`` on stderr rather than Python's warning with its file and line. Scoped to
    uavris's own notices (:data:`NOTICES`), and to the command: any other warning keeps its form,
    and a library user gets the notice as a warning (filtered like any other)."""
    show = warnings.showwarning

    def one_line(message: Warning | str, category: type[Warning], filename: str, lineno: int, file: Any = None,
                 line: str | None = None) -> None:
        if issubclass(category, NOTICES):
            print(f"{PROG}: {message}", file=sys.stderr, flush=True)
        else:
            show(message, category, filename, lineno, file, line)

    warnings.showwarning = one_line
    try:
        yield
    finally:
        warnings.showwarning = show


def _main(argv: list[str] | None, stop: _OnStop) -> int:
    try:
        _run(list(sys.argv[1:] if argv is None else argv))
    except UavrisError as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        stop.join()
        # by the signal, not the exception's type: Ray turns any interrupt into a plain KeyboardInterrupt
        if stop.first == signal.SIGTERM:
            print(f"{PROG}: terminated (SIGTERM){_after_interrupt(argv)}", file=sys.stderr)
            return EXIT_TERMINATED
        print(f"{PROG}: interrupted{_after_interrupt(argv)}", file=sys.stderr)
        return EXIT_INTERRUPTED
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
    except OSError as e:
        if e.errno not in MACHINE_ERRORS:
            raise
        print(f"{PROG}: error: {os_error_line(e)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0


# What the machine says, not a bug: a full disk or quota, a name the file system refuses, a
# folder that cannot be written. One line naming the file, as for any bad input.
MACHINE_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.ENAMETOOLONG, errno.EROFS, errno.EACCES,
                            errno.EPERM, errno.EMFILE, errno.EFBIG})


def os_error_line(e: OSError) -> str:
    """``e`` as one line: the file (the first 120 characters of a name too long to show) and the
    system's words, with what to do about a full disk."""
    name = str(e.filename) if e.filename is not None else ""
    if len(name) > 120:
        name = f"{name[:60]}...{name[-57:]} ({len(name)} characters)"
    advice = "; free some space and rerun (what finished is kept)" if e.errno in (errno.ENOSPC, errno.EDQUOT) \
        else ""
    return f"{name + ': ' if name else ''}{e.strerror or e}{advice}"


if __name__ == "__main__":
    sys.exit(main())
