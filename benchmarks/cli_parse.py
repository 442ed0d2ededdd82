"""What reading each field's help once per process saves a command line's parse, in one run.

The alternative is the parse as tyro does it on its own: tyro empties its caches after every
``tyro.cli`` call, so each parse reads the source of every class it parses again, to find
the fields' help. uavris gives every field its help once per process
(:func:`uavris.cli.field_help.with_help`); the alternative is that function made a no-op, timed
first (the other order would find the help already given). Each side parses, in this one
process pinned to a single CPU, each command line below ``--repeat`` times after one warm-up
parse: lines with a wrong number last, which parse and are refused in one line, as the CLI's
fuzz (tests/test_cli.py) does some 1,600 times. The help each side prints must be the same.

Prints the machine, the command line, a Markdown table with the ratio per command line, and
PASS/FAIL for the help. Exits 0: a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/cli_parse.py            # about 20 s
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import uavris  # noqa: E402, F401, I001 - first: it pins the float path before numpy loads
import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from _machine import cpu_model, pin_to_one_core, table  # noqa: E402

from uavris.cli import main as uavris_main  # noqa: E402
from uavris.cli import parsing  # noqa: E402

LINES = (
    ["train", "--preset", "smoke", "--system.v-max", "-1"],
    ["reproduce", "--preset", "smoke", "--eval-episodes", "0"],
    ["evaluate", "zero-action", "--scenario", "fig2", "--system.nx", "0"],
    ["plan", "paper", "--grid-step", "-1"],
)


def timed(line: list[str], repeat: int) -> float:
    """Seconds per parse of ``line`` (refused in one line: exit 2), after one warm-up parse."""
    with contextlib.redirect_stderr(io.StringIO()):
        if uavris_main(line) != 2:
            raise SystemExit(f"not refused in one line: {' '.join(line)}")
        began = time.perf_counter()
        for _ in range(repeat):
            uavris_main(line)
    return (time.perf_counter() - began) / repeat


def help_of(command: str) -> str:
    """``uavris COMMAND --help`` as it prints."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        uavris_main([command, "--help"])
    return out.getvalue()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20, help="parses per command line and side")
    args = parser.parse_args(argv)
    pinned = pin_to_one_core()
    print(f"# CLI parse: {cpu_model()}, {pinned}\n\ncommand: {' '.join(sys.argv)}\n", flush=True)
    with tempfile.TemporaryDirectory(prefix="uavris-cli-parse-") as tmp:
        lines = [[*line[:1], "--out", f"{tmp}/run", *line[1:]] if line[0] in ("train", "reproduce") else line
                 for line in LINES]
        once = parsing.with_help
        parsing.with_help = lambda cls: cls  # tyro on its own: the help read from the source at each parse
        try:
            plain = [timed(line, args.repeat) for line in lines]
            plain_help = {line[0]: help_of(line[0]) for line in lines}
        finally:
            parsing.with_help = once
        helped = [timed(line, args.repeat) for line in lines]
        same = plain_help == {line[0]: help_of(line[0]) for line in lines}
    rows = [("command line", "tyro alone (ms)", "help read once (ms)", "ratio")]
    rows += [(" ".join(line), f"{1e3 * a:.1f}", f"{1e3 * b:.1f}", f"{a / b:.2f}x")
             for line, a, b in zip(LINES, plain, helped)]
    print(table(rows))
    print()
    print("PASS: the same help on both sides" if same else "FAIL: reading the help once changed a command's help")
    return 0


if __name__ == "__main__":
    sys.exit(main())
