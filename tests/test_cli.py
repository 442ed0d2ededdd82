"""The command line: bad input is one line and exit code 2, never a traceback, never a changed file.

The fuzz walks every numeric flag of every command (read from the dataclasses the CLI
parses, so a new config field is fuzzed without editing this file) with values that are
wrong for it, plus wrong paths, and checks the contract of :mod:`uavris.cli`.
"""

from __future__ import annotations

import dataclasses
import json
import re
import typing
from pathlib import Path

import pytest

from uavris.cli import COMMANDS, main
from uavris.cli import claims as cli_claims
from uavris.cli import evaluation as cli_evaluation
from uavris.cli import tools as cli_tools
from uavris.cli import training as cli_training
from uavris.cli.claims import ClaimsArgs, FromScratchArgs, PagesArgs
from uavris.cli.evaluation import BenchmarkArgs, EvaluateArgs, SweepArgs
from uavris.cli.tools import CollectArgs, DemoArgs, ExportArgs, PlanArgs, PlotArgs
from uavris.cli.training import CompareArgs, FinetuneArgs, PretrainArgs, ReproduceArgs, TrainArgs

# Arguments that make each command parse up to its numeric flags (paths that exist are
# added per test); the fuzzed flag comes last, so it is the one that fails.
BASE = {
    "train": ["train", "--preset", "smoke"],
    "evaluate": ["evaluate", "zero-action", "--scenario", "fig2"],
    "compare-algorithms": ["compare-algorithms", "--preset", "smoke"],
    "collect": ["collect"],
    "pretrain-dt": ["pretrain-dt", "--preset", "smoke"],
    "finetune-dt": ["finetune-dt", "--scenario", "unseen1", "--preset", "smoke"],
    "reproduce": ["reproduce", "--preset", "smoke"],
    "demo": ["demo"],
    "plan": ["plan", "paper"],
    "benchmark": ["benchmark", "zero-action", "--cells", "scenarios"],
    "plot": ["plot"],
    "sweep": ["sweep", "zero-action", "--param", "system.nx", "2,4"],
    "from-scratch": ["from-scratch", "no-study-here"],
    "pages": ["pages", "--list"],
}
ARGS = {"train": TrainArgs, "evaluate": EvaluateArgs, "compare-algorithms": CompareArgs, "collect": CollectArgs,
        "pretrain-dt": PretrainArgs, "finetune-dt": FinetuneArgs, "reproduce": ReproduceArgs, "demo": DemoArgs,
        "plan": PlanArgs, "benchmark": BenchmarkArgs, "plot": PlotArgs, "sweep": SweepArgs, "claims": ClaimsArgs,
        "from-scratch": FromScratchArgs, "pages": PagesArgs, "export": ExportArgs}
BAD_INT = ["-1", "abc", "1.5"]
BAD_FLOAT = ["nan", "inf", "-inf", "abc"]
# Float fields for which a negative value is meaningful (so only nan/inf/text are wrong).
SIGNED = {"noise_dbm", "target_return", "reference_gain_db"}
# Integers for which 0 is a valid count or seed; every other integer flag must be >= 1.
ZERO_OK = {"seed", "eval_seed", "collect_seed", "learning_starts", "warmup_steps", "total_steps", "layout_seed",
           "top_k", "count_other_layouts"}  # top_k 0: the learned value alone; count_other_layouts 0: none


def _numeric_flags(cls: type, prefix: str = "") -> list[tuple[str, str, type]]:
    """(flag, field name, int or float) for every numeric field, nested configs included."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        flat = typing.get_origin(hint) is typing.Annotated and any(
            getattr(m, "name", None) == "" for m in hint.__metadata__)
        base = typing.get_args(hint)[0] if typing.get_origin(hint) is typing.Annotated else hint
        args = [a for a in typing.get_args(base) if a is not type(None)] or [base]
        inner = args[0]
        if dataclasses.is_dataclass(inner) and len(args) == 1 and f.default is not None:
            out += _numeric_flags(inner, prefix if flat else f"{prefix}{f.name}.")
        elif inner in (int, float) and len(args) == 1:
            out.append((f"--{prefix}{f.name.replace('_', '-')}", f.name, inner))
    return out


def _cases() -> list[tuple[str, str, str]]:
    cases = []
    for cmd, cls in ARGS.items():
        for flag, name, kind in _numeric_flags(cls):
            values = BAD_INT if kind is int else BAD_FLOAT
            cases += [(cmd, flag, v) for v in values]
            if kind is float and name not in SIGNED:
                cases.append((cmd, flag, "-1"))
            if kind is int and name not in ZERO_OK:
                cases.append((cmd, flag, "0"))
    return cases


CASES = _cases()


@pytest.fixture(scope="module")
def existing_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory that looks like a finished run; the fuzz must leave its files untouched."""
    run = tmp_path_factory.mktemp("cli") / "run"
    run.mkdir()
    (run / "config.yaml").write_text("algo: ddpg\n")
    (run / "done.json").write_text("{}\n")
    (run / "evals.csv").write_text("env_steps,episodes,mean,ci_low,ci_high,iqm\n")
    return run


def _snapshot(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _with_paths(cmd: str, args: list[str], run: Path) -> list[str]:
    """Make the command's required paths exist so that parsing reaches the fuzzed flag."""
    extra = {"collect": ["--experts", str(run), "--out", str(run)], "pretrain-dt": ["--dataset", str(run)],
             "finetune-dt": ["--model", str(run)]}.get(cmd, [])
    if cmd in ("train", "pretrain-dt", "finetune-dt", "evaluate", "compare-algorithms", "reproduce") \
            and "--out" not in extra:
        extra += ["--out", str(run)]
    return args[:1] + extra + args[1:]


def _check_one_line(capsys: pytest.CaptureFixture[str], code: int, what: str) -> str:
    out, err = capsys.readouterr()
    assert code == 2, f"{what}: exit {code}, stderr {err!r}"
    assert "Traceback" not in err + out, what
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("uavris: error: "), f"{what}: {err!r}"
    return lines[0]


def _args_class(command: str) -> type:
    """The dataclass a command parses, found from the CLI's own command table (its module, and
    the class the command's function parses: ``<first word>Args`` by the CLI's convention)."""
    module = {"training": cli_training, "evaluation": cli_evaluation, "claims": cli_claims,
              "tools": cli_tools}[COMMANDS[command][0]]
    first, whole = command.split("-")[0].capitalize(), "".join(w.capitalize() for w in command.split("-"))
    return getattr(module, first + "Args", None) or getattr(module, whole + "Args")


def test_fuzz_surface_is_wide() -> None:
    """The fuzz reaches every command of the CLI's table that has numeric flags (the expected
    set is built from the table, not from the fuzz's own list), nested config fields included."""
    assert set(ARGS) == set(COMMANDS) and all(ARGS[c] is _args_class(c) for c in COMMANDS)
    numeric = {c for c in COMMANDS if _numeric_flags(_args_class(c))}
    flags = {(c, f) for c, f, _ in CASES}
    assert {c for c, _ in flags} == numeric and {"plan", "benchmark"} <= numeric
    assert ("train", "--hyperparams.learning-rate") in flags and ("train", "--system.v-max") in flags
    assert ("pretrain-dt", "--steps") in flags and ("finetune-dt", "--noise-sigma") in flags
    assert ("plan", "--grid-step") in flags
    assert len(flags) > 80


# train and reproduce parse the full system config (~0.3 s per command line, hundreds of cases).
@pytest.mark.parametrize("cmd", [pytest.param(c, marks=pytest.mark.slow) if c in ("train", "reproduce") else c
                                 for c in sorted({c for c, _, _ in CASES})])
def test_bad_numbers_fail_in_one_line(cmd: str, existing_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = _snapshot(existing_run)
    for c, flag, value in CASES:
        if c != cmd:
            continue
        args = _with_paths(cmd, BASE[cmd], existing_run) + [flag, value]
        line = _check_one_line(capsys, main(args), " ".join(args))
        assert len(line) < 400
    assert _snapshot(existing_run) == before


@pytest.mark.parametrize("args", [
    ["evaluate", "/no/such/run"],
    ["evaluate", "zero-action", "--scenario", "fig2", "--out", "FILE"],
    ["collect", "--experts", "/no/such/run"],
    ["collect", "--experts", "FILE"],
    ["pretrain-dt", "--dataset", "/no/such/dataset"],
    ["pretrain-dt", "--dataset", "FILE"],
    ["finetune-dt", "--model", "/no/such/model", "--scenario", "unseen1"],
    ["finetune-dt", "--model", "FILE", "--scenario", "unseen1"],
    ["train", "--preset", "smoke", "--out", "FILE"],
    ["train", "--config", "/no/such.yaml"],
    ["train", "--config", "FILE"],
    ["plot", "/no/such/run"],
    ["plot", "FILE"],
    ["reproduce", "--out", "FILE"],
    ["evaluate"],
    ["train", "--algo"],
    ["train", "--no-such-flag"],
    ["nonsense"],
    ["evaluate", "zero-action", "--scenario", "mars"],
    ["train", "--preset", "huge"],
    ["reproduce", "--track", "fast"],
])
def test_bad_paths_and_names_fail_in_one_line(args: list[str], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    file = tmp_path / "file.bin"
    file.write_bytes(b"\x00\xff not yaml, not a directory")
    args = [str(file) if a == "FILE" else a for a in args]
    _check_one_line(capsys, main(args), " ".join(args))


def test_every_command_has_help(capsys: pytest.CaptureFixture[str]) -> None:
    """`--help` exits 0 and names what the command writes and its positional arguments."""
    for name in COMMANDS:
        assert main([name, "--help"]) == 0, name
        out = capsys.readouterr().out
        assert f"usage: uavris {name}" in out
        assert "Writes" in out or name == "demo", name
    assert main(["evaluate", "--help"]) == 0
    assert "RUN|MODEL|REFERENCE" in capsys.readouterr().out
    assert main([]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)


def test_help_reads_cleanly(capsys: pytest.CaptureFixture[str]) -> None:
    """No artefacts of how the help is made: the usage line is a usage line, a progress bar is
    --progress / --no-progress, an optional flag whose help states its default shows neither
    "{None}|" nor a second "(default: None)", and demo takes the --system.* flags evaluate takes."""
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "usage: uavris COMMAND [FLAGS]\n" in out and "``" not in out and "Command-line interface" not in out
    for name in COMMANDS:
        assert main([name, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.replace("\u2502", " ").split())
        assert "--no-no-" not in text, name
        if name in ("train", "evaluate", "benchmark", "collect", "pretrain-dt", "finetune-dt", "reproduce", "plan",
                    "compare-algorithms", "sweep"):
            assert "--progress, --no-progress show a progress bar" in text, name
        for flag in ("--layout", "--out", "--scenario", "--config", "--phase-control", "--ray-address", "--labels"):
            assert not re.search(rf"{flag} \{{None\}}\|", text), (name, flag)
        assert not re.search(r"\(default[^()]*\) \(default: None\)", text), name
    assert main(["demo", "--help"]) == 0
    assert "--system.tx-power-w FLOAT" in capsys.readouterr().out


def _bare_flags(help_text: str) -> list[str]:
    """The flags of a command's ``--help`` (rendered 80 columns wide) whose help is nothing but
    their default. Below the description, a flag's row starts with the flag (its metavar may
    wrap onto rows as little indented); its help follows two spaces or more after it on that row
    and on the rows below that are indented further, up to the next flag or section."""
    lines = help_text.splitlines()
    first = next(i for i, r in enumerate(lines) if re.match(r"\s*(\u256d|-{10,})", r))  # the first section
    rows = [r.replace("\u2502", " ").rstrip() for r in lines[first:]]
    flags = [i for i, r in enumerate(rows) if re.match(r"--?[A-Za-z]", r.lstrip())]
    indent = min(len(rows[i]) - len(rows[i].lstrip()) for i in flags)  # a help's own rows are indented further
    bare = []
    for i in flags:
        if len(rows[i]) - len(rows[i].lstrip()) != indent:
            continue
        flag, _, text = rows[i].strip().partition("  ")
        words = [text]
        for below in rows[i + 1:]:
            if not below.strip() or re.match(r"--?[A-Za-z]|\u2570|-{10,}", below.lstrip()):
                break
            if len(below) - len(below.lstrip()) > indent:
                words.append(below.strip())
        if not re.sub(r"\((default|required|fixed to)[^()]*\)", "", " ".join(words)).strip():
            bare.append(flag)
    return bare


def test_every_flag_says_what_it_is_beyond_its_default(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """No flag's help is its default alone (tyro prints "(default: X)" under a flag whose field
    has neither a docstring nor a comment)."""
    monkeypatch.setenv("COLUMNS", "80")  # one column of flags (tyro lays a wide terminal out in several)
    bare = []
    for name in COMMANDS:
        assert main([name, "--help"]) == 0
        bare += [(name, flag) for flag in _bare_flags(capsys.readouterr().out)]
    assert not bare, bare
    assert _bare_flags(" options\n ----------\n  --jobs INT  (default: 1)\n  --seed INT\n      (default: 0)\n"
                       "  --out {a,\n  b}\n      where it writes (default: a)\n  --no-help\n") == [
        "--jobs INT", "--seed INT", "--no-help"]


def test_every_commands_help_is_tyros_own_to_the_byte() -> None:
    """Reading each field's help once (cli.field_help.with_help) changes no command's ``--help``:
    every command's, printed by a process where tyro reads the help itself at each parse and by
    one where it is read once."""
    import os
    import subprocess
    import sys

    script = ("import sys; from uavris.cli import COMMANDS, main, parsing\n"
              "if sys.argv[1] == 'tyro': parsing.with_help = lambda cls: None\n"
              "for name in COMMANDS: main([name, '--help']); print('=' * 20, name)\n")
    env = {**os.environ, "COLUMNS": "100"}
    tyro_alone, read_once = (subprocess.run([sys.executable, "-c", script, side], capture_output=True, text=True,
                                            env=env, timeout=120, check=True).stdout for side in ("tyro", "once"))
    assert tyro_alone.count("usage: uavris ") == len(COMMANDS)
    assert read_once == tyro_alone


def test_a_command_line_reads_no_source_after_the_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Each field's help is read from its class's source once per process (cli.field_help.with_help),
    not at every parse (tyro empties its caches after each): a second parse reads no source."""
    import inspect

    lines = (["train", "--preset", "smoke", "--out", str(tmp_path / "run"), "--system.v-max", "-1"],
             ["plan", "paper", "--grid-step", "-1"])
    assert [main(line) for line in lines] == [2, 2]
    read: list[object] = []
    real = inspect.getsource
    monkeypatch.setattr(inspect, "getsource", lambda obj: read.append(obj) or real(obj))
    assert [main(line) for line in lines] == [2, 2]
    assert "v_max" in capsys.readouterr().err
    assert not read, read


_SCENARIOS = ("fig2", "train1", "train2", "train3", "train4", "train5", "train6", "train7", "train8", "unseen1",
              "unseen2")
_PRESETS, _DEVICES, _PHASES = ("smoke", "quick", "paper"), ("cpu", "cuda", "auto"), ("agent", "optimizer")
FIXED_SET_OPTIONS = {
    "train": {"--algo": ("ddpg", "ppo", "sac", "td3"), "--scenario": _SCENARIOS, "--preset": _PRESETS,
              "--phase-control": _PHASES, "--device": _DEVICES},
    "evaluate": {"--scenario": _SCENARIOS, "--phase-control": _PHASES, "--device": _DEVICES},
    "benchmark": {"--preset": _PRESETS, "--cells": ("all", "scenarios", "layouts"), "--phase-control": _PHASES,
                  "--device": _DEVICES},
    "compare-algorithms": {"--algos": ("ddpg", "ppo", "sac", "td3"), "--preset": _PRESETS, "--scenario": _SCENARIOS,
                           "--backend": ("local", "ray"), "--device": _DEVICES},
    "pretrain-dt": {"--preset": _PRESETS, "--model.attention": ("window", "banded"), "--device": _DEVICES},
    "finetune-dt": {"--scenario": _SCENARIOS, "--preset": _PRESETS, "--selection": ("return", "paired"),
                    "--device": _DEVICES},
    "reproduce": {"--preset": _PRESETS, "--track": ("all", "both", "paper", "strong", "deployment"),
                  "--expert-algo": ("auto", "ddpg", "ppo", "sac", "td3"), "--backend": ("local", "ray"),
                  "--device": _DEVICES},
    "demo": {"--scenario": _SCENARIOS},
}


@pytest.mark.parametrize("name", sorted(FIXED_SET_OPTIONS))
def test_help_lists_the_choices_of_fixed_set_options(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    """tyro shows (and checks) the values of every option typed as a fixed set; no option
    reads `(default: NAME)` for a required value."""
    assert main([name, "--help"]) == 0
    text = capsys.readouterr().out.replace("\u2502", " ")
    for option, choices in FIXED_SET_OPTIONS[name].items():
        m = re.search(rf"{re.escape(option)} \[?\{{([^}}]*)\}}", text)
        assert m, f"uavris {name} --help does not list the choices of {option}"
        got = tuple(re.sub(r"\s+", "", m.group(1)).split(","))
        assert got in (choices, ("None", *choices)), (name, option, got)
    assert not re.search(r"\(default: [A-Z]+\)", " ".join(text.split())), name


def test_resume_and_force_say_what_they_do(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "never-trained"
    line = _check_one_line(capsys, main(["train", "--preset", "smoke", "--out", str(missing), "--resume"]), "resume")
    assert "no run to resume" in line and not missing.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    line = _check_one_line(capsys, main(["pretrain-dt", "--dataset", str(tmp_path), "--out", str(empty),
                                         "--resume"]), "resume empty")
    assert "holds no run" in line
    line = _check_one_line(capsys, main(["train", "--preset", "smoke", "--out", str(empty), "--resume", "--force"]),
                           "resume+force")
    assert "contradict" in line


def test_config_file_unknown_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("algo: ppo\nhyperparams:\n  learning_rat: 0.1\n")
    line = _check_one_line(capsys, main(["train", "--config", str(cfg)]), "unknown field")
    assert "learning_rat" in line


def test_config_file_then_flags(tmp_path: Path) -> None:
    """A partial YAML fills from the preset; flags override the file; the result is validated."""
    from uavris.cli.training import parse_train
    from uavris.experiments.training.train_expert import TrainConfig

    cfg = tmp_path / "c.yaml"
    cfg.write_text("algo: ppo\npreset: smoke\ntotal_steps: 320\nhyperparams:\n  learning_rate: 0.001\n"
                   "system:\n  noise_dbm: -90\n")
    args = ["--config", str(cfg), "--seed", "3"]
    got = parse_train(args).run
    want = TrainConfig(algo="ppo", scenario="fig2", seed=3, preset="smoke")
    assert got.total_steps == 320 and got.seed == 3 and got.hyperparams.learning_rate == 0.001
    assert got.system.noise_dbm == -90 and got.system.v_max == want.system.v_max
    assert got.hyperparams.n_steps == want.hyperparams.n_steps


def test_a_flag_written_at_the_parses_default_value_is_still_given(tmp_path: Path) -> None:
    """Each command parses its line once, with its own defaults (the quick preset's), then builds
    its config from the choices (a file's smoke preset, --preset smoke): a flag written with the
    value the parse would have defaulted to is the user's, not the default, and wins."""
    from uavris.cli.training import parse_pretrain, parse_reproduce, parse_train
    from uavris.presets import STUDY, TRAIN

    quick, smoke = TRAIN["quick"]["total_steps"], TRAIN["smoke"]["total_steps"]
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"preset: smoke\ntotal_steps: {smoke}\n")
    assert parse_train(["--config", str(cfg), "--total-steps", str(quick)]).run.total_steps == quick
    assert parse_train(["--config", str(cfg)]).run.total_steps == smoke
    assert parse_train(["--preset", "smoke", "--eval-every", "10000"]).run.eval_every == 10000
    assert parse_train(["--preset", "smoke"]).run.eval_every == TRAIN["smoke"]["eval_every"]
    assert parse_train(["--algo", "ppo"]).run.hyperparams.n_steps > 0  # PPO's, not the parse's DDPG
    episodes = STUDY["quick"]["eval_episodes"]
    assert parse_reproduce(["--preset", "smoke", "--eval-episodes", str(episodes)]).study.eval_episodes == episodes
    assert parse_reproduce(["--preset", "smoke"]).study.eval_episodes == STUDY["smoke"]["eval_episodes"]
    steps = parse_pretrain(["--dataset", "d", "--preset", "smoke"]).run.steps
    assert steps != parse_pretrain(["--dataset", "d"]).run.steps
    assert parse_pretrain(["--dataset", "d", "--preset", "smoke", "--steps", "1500"]).run.steps == 1500


def test_the_one_parse_checks_nothing_against_its_own_defaults(tmp_path: Path, monkeypatch) -> None:
    """The parse takes the line's values as they are (a config's flags, which check nothing); the config
    built from the line's choices (another preset's budgets, a hall, a file) is what is checked: lines
    valid for their preset, hall or file build, and an invalid one is still refused."""
    import yaml

    from uavris.agents.experts.imitation import ImitationConfig
    from uavris.cli.training import parse_finetune, parse_reproduce, parse_train
    from uavris.errors import ConfigError
    from uavris.experiments.training.train_expert import TrainConfig

    assert parse_reproduce(["--preset", "smoke", "--train-layouts", "3"]).study.train_layouts == 3
    hall = tmp_path / "hall.yaml"  # no room of its own: the flag's, narrower than the paper's
    hall.write_text("devices:\n  - [5, 5, 1]\n  - [20, 8, 1]\n  - [25, 12, 0.5]\n  - [10, 14, 1]\nstart: [15, 8, 4]\n")
    run = parse_train(["--layout", str(hall), "--system.room", "30", "16", "8", "--preset", "smoke"]).run
    assert run.system.room == (30.0, 16.0, 8.0) and run.start == (15.0, 8.0, 4.0)
    imitation = tmp_path / "imitation.yaml"
    imitation.write_text(yaml.safe_dump(TrainConfig(algo="ppo", phase_control="optimizer", preset="smoke",
                                                    imitation=ImitationConfig(rounds=3)).to_dict()))
    assert parse_train(["--config", str(imitation), "--imitation.rounds", "2"]).run.imitation.rounds == 2
    assert parse_train(["--config", str(imitation), "--total-steps", "0"]).run.total_steps == 0  # imitation alone
    with pytest.raises(ConfigError, match="total_steps"):
        parse_train(["--preset", "smoke", "--total-steps", "0"])
    # nested configs too: the smoke preset's batch of 32 under a buffer of 64; a file's 12 m ceiling
    assert parse_train(["--preset", "smoke", "--hyperparams.buffer-size", "64"]).run.hyperparams.buffer_size == 64
    with pytest.raises(ConfigError, match="buffer_size"):
        parse_train(["--preset", "smoke", "--hyperparams.buffer-size", "16"])
    high = tmp_path / "high.yaml"
    high.write_text("system:\n  room: [40, 40, 12]\n")
    assert parse_train(["--config", str(high), "--system.z-max", "11"]).run.system.z_max == 11.0
    high.write_text(hall.read_text() + "room: [40, 40, 12]\n")  # a layout's hall: its room, its devices
    assert parse_train(["--layout", str(high), "--system.z-max", "11", "--preset", "smoke"]).run.system.z_max == 11.0
    pairs = parse_train(["--layout", "layout-train-0-k8", "--system.max-active-pairs", "3", "--preset", "smoke"])
    assert pairs.run.system.max_active_pairs == 3 and pairs.run.system.num_users == 8
    monkeypatch.setattr(cli_training, "dt_system", lambda model: TrainConfig().system)  # a model of the paper's hall
    ft = parse_finetune(["--model", "m", "--scenario", "unseen1", "--preset", "smoke", "--candidates", "4"]).run
    assert (ft.candidates, ft.elites) == (4, 2)  # the smoke preset's elites, not the parse's (quick's 50)
    with pytest.raises(ConfigError, match="elites"):
        parse_finetune(["--model", "m", "--scenario", "unseen1", "--candidates", "4"])


def test_help_shows_the_defaults_the_lines_choices_make(capsys: pytest.CaptureFixture[str]) -> None:
    """``--help`` builds the line without it first: the paper preset's budgets under --preset
    paper, a required flag the line leaves out still "required"."""
    from uavris.presets import TRAIN

    assert main(["train", "--preset", "paper", "--help"]) == 0
    out = capsys.readouterr().out
    assert f"(default: {TRAIN['paper']['total_steps']})" in out
    assert main(["pretrain-dt", "--preset", "smoke", "--help"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"--dataset STR[^-]*\(required\)", out)
    assert re.search(r"--steps INT\s+gradient steps \(default: 20\)", out)  # the smoke preset's
    assert main(["train", "--help"]) == 0
    assert f"(default: {TRAIN['quick']['total_steps']})" in capsys.readouterr().out
    assert main(["finetune-dt", "--help"]) == 0  # neither a scenario nor a layout to adapt to: both asked for
    out = capsys.readouterr().out
    flat = re.sub(r"[\u2502\s]+", " ", out)  # the help's lines joined, its box drawn away
    assert "run or model directory (required)" in flat and "(or a layout's name, with start) (required)" in flat


def test_device_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import torch

    from uavris.agents.torch_device import resolve_device

    assert resolve_device("cpu") == "cpu"
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        for cmd in (["train", "--preset", "smoke", "--out", str(tmp_path / "r")],
                    ["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "1"],
                    ["reproduce", "--preset", "smoke", "--out", str(tmp_path / "s")]):
            line = _check_one_line(capsys, main(cmd + ["--device", "cuda"]), "cuda")
            assert "CUDA" in line
        assert not (tmp_path / "r").exists() and not (tmp_path / "s").exists()
    line = _check_one_line(capsys, main(["evaluate", "zero-action", "--scenario", "fig2", "--device", "tpu"]), "tpu")
    assert "invalid choice 'tpu'" in line and "'cpu', 'cuda', 'auto'" in line


def test_evaluate_writes_what_it_prints(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The printed mean is the JSON's, which is the mean of the per-episode CSV."""
    import json

    from uavris.io import read_csv

    assert main(["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "3", "--out", str(tmp_path),
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    (path,) = tmp_path.glob("zero-action-fig2-seed1000000-n3-*.json")  # -KEY: the system evaluated
    summary = json.loads(path.read_text())
    rows = read_csv(path.with_suffix(".csv"))
    assert len(rows) == 3
    assert summary["mean"] == pytest.approx(sum(float(r["avg_sum_rate"]) for r in rows) / 3)
    assert f"{summary['mean']:.2f} bps/Hz" in printed


def test_demo_prints_every_policy(capsys: pytest.CaptureFixture[str]) -> None:
    from uavris.agents.references import REFERENCES
    from uavris.experiments.tools.demo import DEMO_POLICIES

    assert main(["demo", "--episodes", "2"]) == 0
    out = capsys.readouterr().out
    assert all(REFERENCES[name].label in out for name in DEMO_POLICIES)


def test_plot_overlays_runs_of_every_kind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`uavris plot` reads the logs each kind of run writes and draws one panel per kind (PNG and PDF)."""
    import matplotlib.image as mpimg

    from uavris.experiments.training.finetune import ROUND_HEADER
    from uavris.experiments.training.pretrain import LOG_HEADER
    from uavris.experiments.training.train_expert import EPISODE_HEADER, EVAL_HEADER
    from uavris.io import write_csv

    runs = []
    for name, seed in (("a", 0), ("b", 1)):
        d = tmp_path / name
        d.mkdir()
        write_csv(d / "episodes.csv", EPISODE_HEADER, [[i, 100 * (i + 1), 10 + seed + 0.1 * i, 1000, 100]
                                                       for i in range(20)])
        write_csv(d / "evals.csv", EVAL_HEADER, [[s, 8, 10 + seed + s / 1000, 9 + seed, 11 + seed, 10 + seed]
                                                 for s in (0, 1000, 2000)])
        runs.append(d)
    pre = tmp_path / "pre"
    pre.mkdir()
    write_csv(pre / "train_log.csv", LOG_HEADER, [[s, 1 / s, 1e-4, 100.0] for s in range(1, 50)])
    ft = tmp_path / "ft"
    ft.mkdir()
    write_csv(ft / "finetune.csv", ROUND_HEADER, [[r, 8000 * r, 100 * r] + [1.0] * 5 + [40 + r, 39 + r, 41 + r]
                                                  for r in range(4)])
    stem = tmp_path / "out" / "curves"
    assert main(["plot", *map(str, runs + [pre, ft]), "--out", str(stem)]) == 0
    assert "curves.png" in capsys.readouterr().out
    image = mpimg.imread(stem.with_suffix(".png"))
    assert image.ndim == 3 and image.shape[1] > 2.5 * image.shape[0]  # three panels side by side
    assert image[..., :3].std() > 0.05  # something is drawn
    assert stem.with_suffix(".pdf").read_bytes().startswith(b"%PDF")
    line = _check_one_line(capsys, main(["plot", str(runs[0]), "--labels", "one", "two"]), "labels")
    assert "--labels" in line


def test_resume_uses_the_runs_own_configuration(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`train --out RUN --resume` continues a run made with non-default flags from its config.yaml
    (the preset's defaults would differ from it and be refused)."""
    run = tmp_path / "r"
    assert main(["train", "--preset", "smoke", "--algo", "td3", "--scenario", "train2", "--out", str(run),
                 "--no-progress"]) == 0
    done = (run / "done.json").read_text()
    (run / "done.json").unlink()  # as if killed after its last checkpoint
    (run / "model.zip").unlink()
    assert main(["train", "--out", str(run), "--resume", "--no-progress"]) == 0
    assert json.loads((run / "done.json").read_text())["final_eval"] == json.loads(done)["final_eval"]
    line = _check_one_line(capsys, main(["train", "--out", str(run), "--resume", "--algo", "ddpg"]), "differs")
    assert "ddpg" in line or "config" in line


@pytest.mark.parametrize("cmd", sorted(COMMANDS))
def test_ctrl_c_names_only_a_flag_the_command_has(cmd, monkeypatch, capsys):
    """Ctrl-C is one line, exit 130; it says "--resume" only for a command whose --help offers it."""
    import uavris.cli as cli

    def interrupted(args: list[str]) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "command", lambda name: interrupted)
    assert main([cmd]) == 130
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.startswith("uavris: interrupted")
    monkeypatch.undo()
    assert main([cmd, "--help"]) == 0
    offers = "--resume" in capsys.readouterr().out
    assert ("--resume" in line) == offers, (cmd, line)


def test_the_first_use_of_the_optimiser_says_it_compiles(monkeypatch, tmp_path, capsys):
    """Where the compiled kernel is in no cache, the first command that optimises phases says so in
    one line first; where it is cached (after make's install step), a fresh process finds it."""
    import subprocess
    import sys
    import warnings

    from uavris.physics import phase_opt

    monkeypatch.setattr(phase_opt, "kernel_ready", lambda: False)
    assert main(["evaluate", "hover-optimizer", "--scenario", "fig2", "--episodes", "1", "--no-progress",
                 "--out", str(tmp_path)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("uavris: compiling the phase optimiser, once: ") and len(err) == 1, err
    with warnings.catch_warnings(record=True) as said:  # make's install step prints its own one line
        warnings.simplefilter("always")
        phase_opt.compile_optimiser()  # in this process: compiled, so in numba's cache
    assert not [w for w in said if w.category is phase_opt.CompileNotice]
    fresh = subprocess.run([sys.executable, "-c", "from uavris.physics.phase_opt import kernel_ready; "
                            "print(kernel_ready())"], capture_output=True, text=True, check=True, timeout=120)
    assert fresh.stdout.strip() == "True"


def test_the_compile_notice_is_one_line_in_a_command_and_a_warning_in_the_library(monkeypatch, capsys):
    """A command shows uavris's own notice as one plain line on stderr (no file, no source line) and
    hands any other warning on as it was; outside a command the notice is an ordinary warning of its
    own category, which a library user may filter. Nothing is compiled: the kernel is said to be
    missing and the command only announces it."""
    import warnings

    from uavris import cli
    from uavris.physics import phase_opt

    monkeypatch.setattr(phase_opt, "kernel_ready", lambda: False)

    def announcing(args: list[str]) -> None:
        phase_opt.announce_compile()
        warnings.warn("not uavris's", UserWarning, stacklevel=1)

    monkeypatch.setattr(cli, "command", lambda name: announcing)
    others: list[type[Warning]] = []
    monkeypatch.setattr(warnings, "showwarning", lambda message, category, *rest: others.append(category))
    hook = warnings.showwarning
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["demo"]) == 0
    assert capsys.readouterr().err == (f"uavris: compiling the phase optimiser, once: {phase_opt.COMPILE_S} s "
                                       "(later runs load it from numba's cache)\n")
    assert others == [UserWarning] and warnings.showwarning is hook  # the other warning as it was; the hook undone
    with pytest.warns(phase_opt.CompileNotice, match="compiling the phase optimiser, once"):
        phase_opt.announce_compile()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=phase_opt.CompileNotice)
        phase_opt.announce_compile()  # filtered like any warning
