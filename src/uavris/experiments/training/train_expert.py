"""Training one expert: run directory, checkpoints, resume, logs and evaluation.

Lives here: :class:`TrainConfig`, :func:`TrainConfig`, :func:`train`, :func:`train_job`,
:func:`save_checkpoint`, :func:`run_evaluation`, :func:`run_policy`, :func:`load_run_policy`,
:func:`final_policy_stem` and :func:`final_model_path`. Not here: the overwrite guard and the checkpoint pointer
(:mod:`uavris.runs`), the SB3 models (:mod:`uavris.agents.experts.sb3`) and the flags of
``uavris train`` (:mod:`uavris.cli.training`).

A run directory holds::

    config.yaml            the resolved TrainConfig (system, scenario, hyperparameters)
    episodes.csv           every finished training episode: env steps, average sum rate
    evals.csv              deterministic evaluations from env step 0 on (mean and 95% CI)
    checkpoints/           step_<N>.policy.safetensors/.json (the policy, what commands read),
                           step_<N>.zip models, step_<N>.state.pkl (environments and random
                           streams), replay_buffer.pkl (off-policy): the pickles each sealed
                           as uavris's own (.seal, uavris.runs.seal); latest.json
    timing.json            wall-clock seconds over all sessions, and the env steps they reached
    tb/                    TensorBoard logs
    policy.safetensors     the final policy's weights, and policy.json its architecture: what
                           every command loads (no pickle)
    model.zip, done.json   the final SB3 model (for SB3's users; sealed) and the completion record

Every file is written atomically. ``resume=True`` continues from ``checkpoints/latest.json``
with the step counter continuing; a finished run is never retrained unless forced.
Checkpoints are taken between a gradient update and the next env step (SB3's
``on_rollout_start``: every vector step for the off-policy algorithms, every rollout for
PPO) and hold the environments mid-episode and every random stream
(:mod:`uavris.agents.experts.resume_state`), so a killed and resumed run ends with the same
model and numbers as an uninterrupted one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from uavris import runs
from uavris.agents.evaluation import EpisodeResults, evaluate
from uavris.agents.experts import (
    OFF_POLICY,
    Algorithm,
    Hyperparams,
    check_algorithm,
    default_hyperparams,
    resume_state,
)
from uavris.agents.experts.imitation import ImitationConfig, imitate
from uavris.agents.experts.sb3 import SB3Policy, build_model, has_policy, load_model, load_policy, save_policy
from uavris.agents.experts.vec_env import UavRisVecEnv
from uavris.config import Scenario, ScenarioName, SystemConfig, float_tuple, scenario_at
from uavris.env.wrappers import PhaseControl, check_phase_control
from uavris.errors import CheckpointError, ConfigError, UavrisError
from uavris.experiments.display.progress import progress_bar
from uavris.io import atomic_save, atomic_write_bytes, read_csv, read_rows, refuse_links_out, write_csv
from uavris.presets import EVAL_SEED, PRESET, TRAIN, Preset, PresetConfig, check_preset, fill_from_preset
from uavris.runs.seal import TRUST_FLAG, check_sealed, seal

EPISODE_HEADER = ("episode", "env_steps", "avg_sum_rate", "return", "length")
EVAL_HEADER = ("env_steps", "episodes", "mean", "ci_low", "ci_high", "iqm")


@dataclass(frozen=True)
class TrainConfig(PresetConfig):
    """Everything that determines a training run (dumped as config.yaml). Fields left at
    ``PRESET`` take the preset's values (:data:`uavris.presets.TRAIN`; the hyperparameters:
    :func:`uavris.agents.experts.default_hyperparams` of the algorithm and preset)."""

    algo: Algorithm = "ddpg"  # the DRL algorithm (Stable-Baselines3)
    scenario: ScenarioName | str = "fig2"  # where it trains (or a layout's name, with start)
    start: tuple[float, float, float] | None = None  # the UAV's start; None: the named scenario's (a layout sets it)
    seed: int = 0  # seed of the model, the exploration and the training episodes
    preset: Preset = "quick"  # budgets and hyperparameters: smoke (seconds), quick (minutes), paper (hours)
    total_steps: int = PRESET  # environment steps of RL (after imitation, if any)
    eval_every: int = PRESET  # environment steps between periodic evaluations
    eval_episodes: int = PRESET  # episodes of each evaluation
    eval_seed: int = EVAL_SEED  # evaluation episodes never share seeds with training
    checkpoint_every: int = PRESET  # environment steps between checkpoints
    phase_control: PhaseControl = "agent"  # "optimizer": hybrid controller (uavris.env.wrappers)
    imitation: ImitationConfig | None = None  # start from the oracle's demonstrations (uavris.agents.experts.imitation)
    hyperparams: Hyperparams = PRESET  # the algorithm's, for the preset (uavris.agents.experts.hyperparams)
    system: SystemConfig = field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        check_algorithm(self.algo)
        check_preset(self.preset)
        fill_from_preset(self, {**TRAIN[self.preset], "hyperparams": default_hyperparams(self.algo, self.preset)})
        check_phase_control(self.phase_control)
        if self.start is not None:
            object.__setattr__(self, "start", float_tuple(self.start, "TrainConfig", "start", "[x, y, z] (m)"))
        self.resolved_scenario.validate_for(self.system)
        if self.imitation is not None and (self.algo != "ppo" or self.phase_control != "optimizer"):
            raise ConfigError("TrainConfig.imitation needs algo 'ppo' and phase_control 'optimizer' (the oracle's "
                              f"motion is what is imitated), got {self.algo!r} and {self.phase_control!r}")
        # RL steps may be 0 after imitation: the expert is then the imitation alone.
        least = 0 if self.imitation is not None else 1
        if self.total_steps < least:
            raise ConfigError(f"TrainConfig.total_steps must be >= {least}, got {self.total_steps}")
        for name in ("eval_every", "eval_episodes", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ConfigError(f"TrainConfig.{name} must be >= 1, got {getattr(self, name)}")
        for name in ("seed", "eval_seed"):
            if getattr(self, name) < 0:
                raise ConfigError(f"TrainConfig.{name} must be >= 0, got {getattr(self, name)}")

    @property
    def expert_kind(self) -> str:
        """What the run's policy is, for labels: the algorithm, or an imitation of the oracle
        (a PPO network with no RL after the DAgger rounds, the strong tracks' experts)."""
        if self.imitation is not None:
            return "oracle imitation" if self.total_steps == 0 else "oracle imitation + PPO"
        return self.algo.upper()

    @property
    def resolved_scenario(self) -> Scenario:
        """Where the run flies: the named scenario, or ``start`` under that name (a layout's)."""
        return scenario_at(self.scenario, self.start)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainConfig:
        try:
            return super().from_dict(d)
        except ConfigError as e:
            raise ConfigError(f"config.yaml does not describe a training run: {e}") from None


def default_run_dir(cfg: TrainConfig, root: str | Path = "runs/train") -> Path:
    hybrid = "-hybrid" if cfg.phase_control == "optimizer" else ""
    return Path(root) / f"{cfg.algo}{hybrid}-{cfg.scenario}-s{cfg.seed}-{cfg.preset}"


# ---------------------------------------------------------------------------- run state
def load_run_config(run_dir: str | Path) -> TrainConfig:
    run_dir = Path(run_dir)
    raw = runs.read_config(run_dir)
    if raw is None:
        raise UavrisError(f"{run_dir} is not a uavris run directory (no {runs.CONFIG_FILE})")
    if not isinstance(raw, dict) or "kind" in raw:
        raise UavrisError(f"{runs.config_path(run_dir)} does not describe an expert's training run")
    return TrainConfig.from_dict(raw)


# ---------------------------------------------------------------------------- training
class _Recorder:
    """Collects finished episodes, evaluations and checkpoints during ``learn``."""

    def __init__(self, cfg: TrainConfig, run_dir: Path, start_steps: int, episodes: list[dict[str, Any]],
                 evals: list[dict[str, Any]], progress: bool, interrupt_at: int | None, clock: runs.RunClock) -> None:
        self.cfg, self.run_dir, self.clock = cfg, run_dir, clock
        self.episodes, self.evals = episodes, evals
        self.next_eval = (start_steps // cfg.eval_every + 1) * cfg.eval_every
        self.next_ckpt = (start_steps // cfg.checkpoint_every + 1) * cfg.checkpoint_every
        self.interrupt_at = interrupt_at
        self.checkpoint_due = self.eval_due = False
        self.bar = progress_bar(cfg.total_steps, f"{cfg.algo} {cfg.scenario} s{cfg.seed}", "step", progress,
                                start_steps)

    def callback(self):
        rec = self

        class Callback(BaseCallback):
            def _on_step(self) -> bool:
                return rec.on_step(self.model, self.locals.get("infos", []), self.logger)

            def _on_rollout_start(self) -> None:
                rec.on_rollout_start(self.model)

        return Callback()

    def on_step(self, model: Any, infos: list[dict[str, Any]], logger: Any) -> bool:
        steps = model.num_timesteps
        for info in infos:
            ep = info.get("episode")
            if ep is not None:
                self.episodes.append({"episode": len(self.episodes), "env_steps": steps,
                                      "avg_sum_rate": ep["avg_sum_rate"], "return": ep["r"], "length": ep["l"]})
                logger.record_mean("rollout/avg_sum_rate", ep["avg_sum_rate"])
        self.bar.update(steps - self.bar.n)
        if self.episodes:
            recent = [row["avg_sum_rate"] for row in self.episodes[-20:]]
            self.bar.set_postfix(avg_sum_rate=f"{np.mean(recent):.2f}", refresh=False)
        if steps >= self.next_eval and steps < self.cfg.total_steps:  # the final evaluation follows training
            # evaluated at the next rollout start, once this step's transitions are trained on: SB3
            # calls on_step before the update, and a policy evaluated here would be one update short
            # of a run of this many steps (PPO a whole rollout's), which a budget is read as
            self.eval_due = True
            self.next_eval = (steps // self.cfg.eval_every + 1) * self.cfg.eval_every
        if steps >= self.next_ckpt:
            # saved at the next rollout start, once this step's transition is stored and trained on
            self.checkpoint_due = True
            self.next_ckpt = (steps // self.cfg.checkpoint_every + 1) * self.cfg.checkpoint_every
        if self.interrupt_at is not None and steps >= self.interrupt_at:
            raise KeyboardInterrupt(f"interrupted at step {steps} (test hook)")
        return True

    def on_rollout_start(self, model: Any) -> None:
        if self.eval_due:  # before the checkpoint, which keeps the row
            res = run_evaluation(model, self.cfg, self.cfg.eval_episodes).summary()
            self.evals.append(_eval_row(model.num_timesteps, res))
            model.logger.record("eval/avg_sum_rate", res["mean"])
            self.eval_due = False
        if self.checkpoint_due:
            save_checkpoint(model, self.cfg, self.run_dir, self.episodes, self.evals, self.clock)
            self.checkpoint_due = False

    def close(self) -> None:
        self.bar.close()


def _eval_row(steps: int, summary: dict[str, Any]) -> dict[str, Any]:
    """A row of evals.csv: the evaluation after ``steps`` env steps."""
    return {"env_steps": steps, **{h: summary[h] for h in EVAL_HEADER[1:]}}


def run_policy(model: Any, cfg: TrainConfig) -> SB3Policy:
    """The deterministic policy of a trained run (a hybrid run's acts on the motion, with
    the optimiser's phases)."""
    return SB3Policy(model, cfg.phase_control)


def load_run_policy(run_dir: str | Path, device: str = "cpu", trust_pickle: bool = False
                    ) -> tuple[TrainConfig, SB3Policy]:
    """A run's configuration and its deterministic policy (the final one, or the latest
    checkpoint's), from its policy files (safetensors + JSON: nothing in them runs). A run with
    SB3's archive only (uavris 0.3's, another tool's) is loaded from it with ``trust_pickle``
    only: unpickling it could run any code."""
    run_dir = Path(run_dir)
    refuse_links_out(run_dir, "an expert's run")  # before its configuration is read
    cfg = load_run_config(run_dir)
    stem = final_policy_stem(run_dir)
    if stem is not None:
        return cfg, run_policy(load_policy(stem, cfg.system, cfg.phase_control, device), cfg)
    archive = final_model_path(run_dir)
    if not trust_pickle:
        raise CheckpointError(f"{run_dir} holds only SB3's pickled archive ({archive.name}; a run of uavris 0.3 or of "
                              f"another tool): loading it could run any code; pass {TRUST_FLAG} if you trust it")
    return cfg, run_policy(load_model(archive, cfg.algo, device=device, trust_pickle=True), cfg)


def final_policy_stem(run_dir: Path) -> Path | None:
    """Where a run's final policy files are (``policy.*``), or its latest checkpoint's; None without either."""
    if has_policy(run_dir / "policy"):
        return run_dir / "policy"
    latest = runs.read_pointer(run_dir, "model")
    stem = run_dir / "checkpoints" / str(latest["model"]).replace(".zip", ".policy") if latest else None
    return stem if stem is not None and has_policy(stem) else None


def run_evaluation(model: Any, cfg: TrainConfig, episodes: int) -> EpisodeResults:
    """The run's deterministic evaluation on its own scenario and evaluation episodes."""
    return evaluate(run_policy(model, cfg), cfg.system, cfg.resolved_scenario, episodes, cfg.eval_seed)


def save_checkpoint(model: Any, cfg: TrainConfig, run_dir: Path, episodes: list, evals: list,
                    clock: runs.RunClock | None = None) -> Path:
    """Model, resume state (and replay buffer), then logs, then the ``latest.json`` pointer,
    each atomic. Call it only between a gradient update and the next env step.

    The pointer moves last, so a kill at any moment leaves the previous checkpoint intact.
    """
    ck = run_dir / "checkpoints"
    ck.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    model_path = ck / f"step_{steps}.zip"
    atomic_save(model_path, model.save)
    seal(model_path)  # SB3's archive and the pickles beside it: resumed only where uavris wrote them
    save_policy(model, cfg.algo, ck / f"step_{steps}.policy")
    state_path = ck / f"step_{steps}.state.pkl"
    atomic_write_bytes(state_path, resume_state.capture(model))
    seal(state_path)
    if cfg.algo in OFF_POLICY:
        atomic_save(ck / "replay_buffer.pkl", model.save_replay_buffer)
        seal(ck / "replay_buffer.pkl")
    write_csv(run_dir / "episodes.csv", EPISODE_HEADER, episodes)
    write_csv(run_dir / "evals.csv", EVAL_HEADER, evals)
    if clock is not None:
        clock.save(env_steps=steps)
    runs.write_pointer(run_dir, {"env_steps": steps, "model": model_path.name, "state": state_path.name,
                                 "episodes": len(episodes), "evals": len(evals)})
    return model_path


INT_COLUMNS = {"episode", "env_steps", "length", "episodes"}


def train(cfg: TrainConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
          progress: bool = True, interrupt_at: int | None = None, device: str = "cpu",
          trust_pickle: bool = False) -> Path:
    """Train ``cfg`` into ``run_dir`` on the torch ``device``; returns the final model path.
    Resuming unpickles the checkpoint: only files sealed as this uavris's own
    (:mod:`uavris.runs.seal`), or any with ``trust_pickle``.

    Raises :class:`UavrisError` for a finished run (unless ``force``), an existing
    unfinished run without ``resume``/``force``, a resume whose config differs, or a
    corrupt checkpoint. ``interrupt_at`` is a test hook that stops training at that step.
    """
    cfg.check()  # before anything is written
    run_dir = Path(run_dir)
    resuming = runs.prepare(run_dir, cfg.to_dict(), resume=resume, force=force,
                            same=lambda stored: isinstance(stored, dict) and TrainConfig.from_dict(stored) == cfg)
    clock = runs.RunClock(run_dir, resuming)
    env = UavRisVecEnv(cfg.hyperparams.n_envs, cfg.system, cfg.resolved_scenario, cfg.hyperparams.reward_scale,
                       cfg.phase_control)
    env.seed(cfg.seed * 10_000)
    episodes: list[dict[str, Any]] = []
    evals: list[dict[str, Any]] = []
    start = 0
    latest = runs.read_pointer(run_dir, "model", "state", "env_steps", "episodes", "evals") if resuming else None
    if resuming:
        if latest is not None:
            try:
                model_path = run_dir / "checkpoints" / latest["model"]
                state_path = run_dir / "checkpoints" / str(latest["state"])
                start, n_ep, n_ev = int(latest["env_steps"]), int(latest["episodes"]), int(latest["evals"])
            except (TypeError, ValueError):
                raise UavrisError(f"{run_dir / runs.POINTER} is corrupt") from None
            model = load_model(model_path, cfg.algo, env, device, trust_pickle)
            check_sealed(state_path, trust_pickle)
            if cfg.algo in OFF_POLICY:
                buf = run_dir / "checkpoints" / "replay_buffer.pkl"
                if not buf.exists():
                    raise UavrisError(f"replay buffer {buf} is missing; pass --force to start over")
                check_sealed(buf, trust_pickle)
                try:
                    model.load_replay_buffer(buf)
                except Exception as e:  # noqa: BLE001
                    raise CheckpointError(f"replay buffer {buf} is corrupt ({type(e).__name__})") from None
            try:
                resume_state.restore(model, state_path.read_bytes())
            except (OSError, ValueError) as e:
                raise CheckpointError(f"resume state {state_path} is missing or corrupt ({e})") from None
            episodes = read_rows(run_dir / "episodes.csv", EPISODE_HEADER, n_ep, INT_COLUMNS)
            evals = read_rows(run_dir / "evals.csv", EVAL_HEADER, n_ev, INT_COLUMNS)
    if latest is None:
        model = _fresh_model(cfg, env, run_dir, evals, progress, device)

    rec = _Recorder(cfg, run_dir, start, episodes, evals, progress, interrupt_at, clock)
    try:
        remaining = cfg.total_steps - start
        if remaining > 0:
            model.learn(remaining, callback=rec.callback(), reset_num_timesteps=start == 0,
                        tb_log_name="run", progress_bar=False)
    finally:
        rec.close()
    final = run_evaluation(model, cfg, cfg.eval_episodes).summary()
    evals.append(_eval_row(model.num_timesteps, final))
    save_checkpoint(model, cfg, run_dir, episodes, evals, clock)
    atomic_save(run_dir / "model.zip", model.save)  # for SB3's users; uavris reads the policy files
    seal(run_dir / "model.zip")
    save_policy(model, cfg.algo, run_dir / "policy")
    imitation = read_csv(run_dir / "imitation.csv") if (run_dir / "imitation.csv").exists() else []
    clock.save(env_steps=int(model.num_timesteps))
    runs.write_done(run_dir, {"env_steps": int(model.num_timesteps), "episodes": len(episodes),
                              "imitation_interactions": int(imitation[-1]["samples"]) if imitation else 0,
                              "final_eval": final})
    return run_dir / "model.zip"


IMITATION_HEADER = ("round", "samples", "loss", "student_gap", "eval_mean", "eval_ci_low", "eval_ci_high")


def _fresh_model(cfg: TrainConfig, env: Any, run_dir: Path, evals: list[dict[str, Any]], progress: bool,
                 device: str = "cpu") -> Any:
    """A new model, evaluated at env step 0 when RL follows (with ``cfg.imitation``, after it is
    fitted to the teacher: imitation.csv), so that its learning curve starts where a fine-tuning
    curve does: "fewer interactions" charges each side from its first useful point (the claims
    page, docs/results/claims.md). The evaluation's environment is its own; the model's random numbers are
    untouched (a deterministic policy draws none)."""
    model = build_model(cfg.algo, env, cfg.hyperparams, cfg.seed, str(run_dir / "tb"), device)
    if cfg.imitation is not None:
        _imitate(model, cfg, run_dir, progress)
    if cfg.total_steps > 0:  # otherwise the final evaluation is this one
        res = run_evaluation(model, cfg, cfg.eval_episodes).summary()
        evals.append(_eval_row(0, res))
    return model


def _imitate(model: Any, cfg: TrainConfig, run_dir: Path, progress: bool) -> None:
    """Fit ``model`` to the oracle's motion (``cfg.imitation``'s rounds), recorded in imitation.csv;
    with ``evaluate_rounds``, each round's student evaluated on the run's evaluation episodes
    (its own environment; the student is deterministic, so the fit is the same to the bit)."""
    assert cfg.imitation is not None
    rows: list[dict[str, Any]] = []
    bar = progress_bar(cfg.imitation.rounds, f"imitation {cfg.scenario}", "round", progress)
    nan = float("nan")

    def on_round(row: dict[str, float]) -> None:
        ev = run_evaluation(model, cfg, cfg.eval_episodes).summary() if cfg.imitation.evaluate_rounds else {}
        rows.append({**row, "eval_mean": ev.get("mean", nan), "eval_ci_low": ev.get("ci_low", nan),
                     "eval_ci_high": ev.get("ci_high", nan)})
        bar.update(1)
        bar.set_postfix(loss=f"{row['loss']:.4f}", refresh=False)

    with bar:
        imitate(model, cfg.system, cfg.resolved_scenario, cfg.imitation, cfg.seed, on_round)
    write_csv(run_dir / "imitation.csv", IMITATION_HEADER, rows)


def train_job(cfg_dict: dict[str, Any], run_dir: str, device: str = "cpu") -> dict[str, Any]:
    """Worker entry point (:mod:`uavris.experiments.engine.jobs`): train, or resume, one run; its done.json."""
    cfg = TrainConfig.from_dict(cfg_dict)
    path = Path(run_dir)
    if not runs.is_finished(path):
        train(cfg, path, resume=runs.config_path(path) is not None, progress=False, device=device)
    return runs.read_done(path)


def final_model_path(run_dir: str | Path) -> Path:
    """The final model, or the latest checkpoint of an unfinished run."""
    run_dir = Path(run_dir)
    if (run_dir / "model.zip").exists():
        return run_dir / "model.zip"
    latest = runs.read_pointer(run_dir, "model")
    if latest is not None:
        return run_dir / "checkpoints" / str(latest["model"])
    raise UavrisError(f"{run_dir} has no model yet (no model.zip and no checkpoint)")


__all__ = ["TrainConfig", "default_run_dir", "final_model_path", "load_model", "load_run_config", "train"]
