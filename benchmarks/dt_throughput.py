"""Single-core throughput of the uavris Decision Transformer: training and rollouts.

Measurements, in this one process pinned to a single CPU, one torch thread:

1. **Training samples/s** of two models, same batch (64 windows), same seed, same windows
   (``TrainingWindows`` over 32 synthetic 100-slot trajectories, left-padded near episode
   starts as in real training; every step samples its windows from a generator of the same
   seed, so every trainer reads the same windows), each beside a named alternative:

   - the **deployment** track's model: state of ``SystemConfig(observe_devices=True)``
     (170), the 6 motion entries, context 10, width 64, 2 layers, 1 head, the device-set
     encoder (4 devices, 16 elements), AdamW lr 3e-4 (``make_optimizer``), beside the same
     model with the DT paper's flat encoder (one linear map of the observation): what
     reading a hall as a set of devices costs;
   - the **paper-size** model (the DT paper's: context 20, width 128, 3 layers, 1 head,
     MLP 512 with ReLU, dropout 0.1; flat encoder, state 158, action 22), AdamW lr 1e-4,
     beside Hugging Face ``transformers.DecisionTransformerModel`` of the same size with
     the same step (foreach AdamW and clipping, as ours). Hugging Face's model comes from
     the benchmark-only extra ``pip install -e '.[bench]'``; without it that row is skipped.

   The step is :func:`uavris.agents.dt.training.train_steps`: forward, masked action MSE
   over the real slots, backward, gradient clipping at 0.25, AdamW (weight decay 1e-4 on the
   weight matrices), linear warm-up. A *sample* is one context window.
2. **Where the time goes**: torch.profiler over 20 steps of the deployment model's step,
   the 8 operators with the most self CPU time.
3. **Rollout** of 80 episodes (``unseen1``, seeds 0..79, the default system) by a DT of
   the paper's size: all 80 in one batched simulator with one forward pass per slot
   (``DTBatchPolicy`` + ``record_episodes``), against rolling the same 80 episodes out one
   by one (batch of 1). Same seeds, same model, same code path. Measured for both
   attention layouts: ``window`` (the DT paper's; every slot re-reads 59 tokens) and
   ``banded`` (every slot adds 3 tokens to a key/value cache; see
   ``uavris.agents.dt.model``).

Each case is warmed up, then timed ``--repeats`` times (the training cases interleaved, so
that a busy moment of the machine does not fall on one of them only); the best timing is
kept. The script prints the machine, the command, Markdown tables and PASS/FAIL lines
against the targets (the device-set encoder at least half the flat encoder's samples/s;
ours >= Hugging Face's samples/s; batched rollout >= 20x one-by-one). It always exits 0: it
is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/dt_throughput.py            # ~6 minutes
    .venv/bin/python benchmarks/dt_throughput.py --quick    # ~1.5 minutes (16 episodes, fewer steps)
"""

from __future__ import annotations

import os

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
for _variable in THREAD_VARIABLES:  # before numpy and torch load their thread pools
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import gc  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any, Callable  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402  (benchmarks/_machine.py)

from uavris.agents.dt.config import ATTENTION_LAYOUTS, DTConfig  # noqa: E402
from uavris.agents.dt.model import DecisionTransformer  # noqa: E402
from uavris.agents.dt.policy import DTBatchPolicy  # noqa: E402
from uavris.agents.dt.training import TrainingWindows, make_optimizer, masked_action_loss, train_steps  # noqa: E402
from uavris.agents.dt.trajectories import Trajectory, record_episodes  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.env.simulator import observation_slices  # noqa: E402

BATCH = 64
CONTEXT, WIDTH, DEPTH, HEADS, DROPOUT = 20, 128, 3, 1, 0.1  # the paper-size model (and the rollouts')
EPISODES = 80
SCENARIO = "unseen1"
TARGET_RETURN = 2000.0
RETURN_SCALE = 3000.0
ROLLOUT_RATIO_TARGET = 20.0
SEED = 0
WEIGHT_DECAY, GRAD_CLIP, WARMUP = 1e-4, 0.25, 30
FLAT_SHARE_TARGET = 0.5  # the device-set encoder's samples/s at least half the flat encoder's
PROFILE_STEPS, PROFILE_TOP = 20, 8


@dataclass(frozen=True)
class TrainedModel:
    """A model of the training measurement: its system, size, learning rate and target."""

    name: str
    system: SystemConfig
    act_dim: int
    lr: float
    model: dict[str, Any]  # DTConfig's fields besides state_dim and act_dim

    def config(self) -> DTConfig:
        return DTConfig(self.system.observation_dim, self.act_dim, max_timestep=self.system.horizon, **self.model)

    def describe(self) -> str:
        c = self.config()
        encoder = f"device encoder ({c.devices} devices, {c.elements} elements)" if c.state_encoder == "devices" \
            else "flat encoder"
        return (f"context {c.context}, width {c.width}, {c.depth} layers, {c.heads} head, dropout {c.dropout}, "
                f"{encoder}, state {c.state_dim}, action {c.act_dim}, lr {self.lr:g}")


MODELS = (
    TrainedModel("deployment", SystemConfig(observe_devices=True), 6, 3e-4,
                 dict(context=10, width=64, depth=2, heads=1, state_encoder="devices", devices=4, elements=16)),
    TrainedModel("paper-size", SystemConfig(), SystemConfig().action_dim, 1e-4,
                 dict(context=CONTEXT, width=WIDTH, depth=DEPTH, heads=HEADS, dropout=DROPOUT)),
)
# the deployment model with the DT paper's flat encoder: the alternative the device-set encoder is timed beside
FLAT = TrainedModel("deployment, flat encoder", MODELS[0].system, 6, 3e-4,
                    dict(context=10, width=64, depth=2, heads=1))


def best_of(fn: Callable[[], Any], repeats: int) -> float:
    timings = []
    for _ in range(repeats):
        gc.collect()
        start = time.perf_counter()
        fn()
        timings.append(time.perf_counter() - start)
    return min(timings)


# ------------------------------------------------------------------------------ training
def synthetic_windows(spec: TrainedModel, seed: int) -> TrainingWindows:
    """Windows over 32 random 100-slot trajectories, sampled exactly as training samples them.
    Observations are standard normal except the pairing, a valid 0/1 draw (one or two pairs
    among the devices), which the device encoder reads raw."""
    system, rng = spec.system, np.random.default_rng(seed)
    k, slots = system.num_users, system.horizon + 1
    pairing = observation_slices(k, system.num_elements, system.observe_devices)["pairing"]
    trajs = []
    for i in range(32):
        obs = rng.standard_normal((slots, system.observation_dim)).astype(np.float32)
        p = np.zeros((slots, k, k), dtype=np.float32)
        for t in range(slots):
            order = rng.permutation(k)
            p[t, order[0], order[1]] = 1.0
            if rng.random() < 0.5:
                p[t, order[2], order[3]] = 1.0
        obs[:, pairing] = p.reshape(slots, -1)
        trajs.append(Trajectory(obs, rng.uniform(-1, 1, (system.horizon, spec.act_dim)).astype(np.float32),
                                rng.uniform(0, 30, system.horizon), False, True, SCENARIO, i))
    return TrainingWindows.for_model(trajs, spec.config())


class Trainer:
    """One model and its optimiser, trained by uavris's step; every call of :meth:`run`
    samples its windows from a generator seeded ``SEED`` (the same windows)."""

    def __init__(self, spec: TrainedModel, windows: TrainingWindows) -> None:
        torch.manual_seed(SEED)
        self.spec, self.windows = spec, windows
        self.model = DecisionTransformer(spec.config(), return_scale=RETURN_SCALE)
        self.opt = make_optimizer(self.model, spec.lr, WEIGHT_DECAY)
        self.params = sum(p.numel() for p in self.model.parameters())

    def run(self, count: int) -> list[float]:
        return train_steps(self.model, self.opt, self.windows, np.random.default_rng(SEED), 0, count, BATCH,
                           self.spec.lr, WARMUP, GRAD_CLIP)


class HFTrainer:
    """Hugging Face's ``DecisionTransformerModel`` at the paper size with the same step as
    ours (foreach AdamW and clipping; no warm-up, which costs nothing), the same windows."""

    def __init__(self, spec: TrainedModel, windows: TrainingWindows) -> None:
        import transformers
        from transformers import DecisionTransformerConfig, DecisionTransformerModel

        transformers.logging.set_verbosity_error()
        torch.manual_seed(SEED)
        c = spec.config()
        cfg = DecisionTransformerConfig(state_dim=c.state_dim, act_dim=c.act_dim, hidden_size=c.width,
                                        n_layer=c.depth, n_head=c.heads, n_inner=4 * c.width,
                                        activation_function="relu", resid_pdrop=c.dropout, embd_pdrop=c.dropout,
                                        attn_pdrop=c.dropout, max_ep_len=c.max_timestep, action_tanh=True)
        self.model = DecisionTransformerModel(cfg)
        self.opt = torch.optim.AdamW(self.model.parameters(), lr=spec.lr, weight_decay=WEIGHT_DECAY, foreach=True)
        self.windows = windows
        self.params = sum(p.numel() for p in self.model.parameters())
        impl = getattr(self.model.config, "_attn_implementation", None) or "default"
        self.label = f"transformers {transformers.__version__}, attention {impl}"

    def run(self, count: int) -> list[float]:
        rng = np.random.default_rng(SEED)
        self.model.train()
        losses = []
        for _ in range(count):
            b = self.windows.sample(BATCH, rng)
            # HF scales nothing itself; the same return scale as ours is applied here.
            out = self.model(states=b["states"], actions=b["actions"],
                             returns_to_go=b["returns_to_go"][..., None] / RETURN_SCALE, timesteps=b["timesteps"],
                             attention_mask=b["valid"].long(), return_dict=True)
            loss = masked_action_loss(out.action_preds, b["actions"], b["valid"])
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.model.parameters(), GRAD_CLIP, foreach=True)
            self.opt.step()
            losses.append(float(loss.detach()))
        return losses


def hf_trainer(spec: TrainedModel, windows: TrainingWindows) -> HFTrainer | None:
    try:
        return HFTrainer(spec, windows)
    except ImportError:
        return None


def measure_training(trainers: dict[str, Any], steps: int, repeats: int) -> dict[str, float]:
    """Samples/s of each trainer: warmed up, then ``repeats`` timings of ``steps`` steps,
    interleaved across the trainers, the best kept."""
    for tr in trainers.values():
        tr.run(3)
    best = dict.fromkeys(trainers, float("inf"))
    for _ in range(repeats):
        for name, tr in trainers.items():
            gc.collect()
            start = time.perf_counter()
            tr.run(steps)
            best[name] = min(best[name], time.perf_counter() - start)
    return {name: steps * BATCH / t for name, t in best.items()}


def profile_step(spec: TrainedModel, windows: TrainingWindows) -> tuple[list[tuple[str, ...]], float, float]:
    """torch.profiler over ``PROFILE_STEPS`` steps: the top operators by self CPU time as table
    rows, the profiled wall time per step (ms) and the total self CPU (ms)."""
    from torch.profiler import ProfilerActivity, profile

    trainer = Trainer(spec, windows)
    trainer.run(3)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        start = time.perf_counter()
        trainer.run(PROFILE_STEPS)
        wall = time.perf_counter() - start
    events = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)
    total = sum(e.self_cpu_time_total for e in events)
    rows = [("operator", "calls per step", "self CPU per step (ms)", "share of self CPU")]
    for e in events[:PROFILE_TOP]:
        rows.append((e.key, f"{e.count / PROFILE_STEPS:.0f}", f"{e.self_cpu_time_total / 1e3 / PROFILE_STEPS:.2f}",
                     f"{e.self_cpu_time_total / total:.1%}"))
    return rows, 1e3 * wall / PROFILE_STEPS, total / 1e3 / PROFILE_STEPS


# ------------------------------------------------------------------------------ rollouts
def measure_rollouts(system: SystemConfig, episodes: int, repeats: int, attention: str = "window"
                     ) -> tuple[float, float, int]:
    """(batched s, one-by-one s, slots) for ``episodes`` episodes."""
    torch.manual_seed(0)
    model = DecisionTransformer(DTConfig(system.observation_dim, system.action_dim, CONTEXT, WIDTH, DEPTH, HEADS,
                                         DROPOUT, max_timestep=system.horizon, attention=attention),
                                return_scale=3000.0).eval()
    seeds = np.arange(episodes)
    record_episodes(DTBatchPolicy(model, TARGET_RETURN), system, SCENARIO, seeds[:2])  # warm-up
    slots = sum(t.length for t in record_episodes(DTBatchPolicy(model, TARGET_RETURN), system, SCENARIO, seeds))
    batched = best_of(lambda: record_episodes(DTBatchPolicy(model, TARGET_RETURN), system, SCENARIO, seeds), repeats)

    def one_by_one() -> None:
        for s in seeds:
            record_episodes(DTBatchPolicy(model, TARGET_RETURN), system, SCENARIO, [s])

    return batched, best_of(one_by_one, repeats), slots


# ------------------------------------------------------------------------------ report
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="16 episodes, fewer training steps, fewer timings")
    p.add_argument("--repeats", type=int, default=None, help="timings per case, best kept (default 3, quick 2)")
    args = p.parse_args(argv)
    args.repeats = args.repeats or (2 if args.quick else 3)
    return args


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    pinning = pin_to_one_core()
    torch.set_num_threads(1)
    system = SystemConfig()
    steps = 10 if args.quick else 30
    episodes = 16 if args.quick else EPISODES
    print("# uavris Decision Transformer throughput (one core)\n")
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()}; {pinning}; torch threads {torch.get_num_threads()}")
    print(f"- platform: {platform.platform()}; python {platform.python_version()}, torch {torch.__version__}")
    for spec in MODELS:
        print(f"- {spec.name} model: {spec.describe()}; batch {BATCH}")
    print(f"- training step: AdamW (weight decay {WEIGHT_DECAY:g}), clipping at {GRAD_CLIP}, warm-up {WARMUP} steps; "
          "uavris.agents.dt.training (train_steps, make_optimizer)")
    print(f"- mode: {'quick' if args.quick else 'full'}, {steps} timed training steps, best of {args.repeats}; "
          f"{episodes} rollout episodes\n", flush=True)

    rates: dict[str, dict[str, float]] = {}
    params: dict[str, dict[str, int]] = {}
    hf_label = None
    for spec in MODELS:
        windows = synthetic_windows(spec, SEED)
        trainers: dict[str, Any] = {"uavris": Trainer(spec, windows)}
        if spec.name == "deployment":
            trainers["flat"] = Trainer(FLAT, windows)
        hf = hf_trainer(spec, windows) if spec.name == "paper-size" else None
        if hf is not None:
            trainers["hf"] = hf
            hf_label = hf.label
        print(f"measuring training, {spec.name} model ({', '.join(trainers)}) ...", file=sys.stderr, flush=True)
        rates[spec.name] = measure_training(trainers, steps, args.repeats)
        params[spec.name] = {name: tr.params for name, tr in trainers.items()}
    print("profiling the deployment model's step ...", file=sys.stderr, flush=True)
    profile_rows, profile_ms, profile_self_ms = profile_step(MODELS[0], synthetic_windows(MODELS[0], SEED))
    rollouts = {}
    for attention in ATTENTION_LAYOUTS:
        print(f"measuring rollouts of {episodes} episodes ({attention} attention) ...", file=sys.stderr, flush=True)
        rollouts[attention] = measure_rollouts(system, episodes, args.repeats, attention)

    print("## Training\n")
    rows = [("model", "trainer", "parameters", "throughput", "relative to uavris")]
    for spec in MODELS:
        r, n = rates[spec.name], params[spec.name]
        rows.append((spec.name, "uavris (train_steps)", f"{n['uavris']:,}", f"{r['uavris']:,.0f} samples/s", "1.00x"))
        if "flat" in r:
            rows.append((spec.name, "the same with the flat encoder", f"{n['flat']:,}", f"{r['flat']:,.0f} samples/s",
                         f"{r['flat'] / r['uavris']:.2f}x"))
        if "hf" in r:
            rows.append((spec.name, f"HF DecisionTransformerModel ({hf_label})", f"{n['hf']:,}",
                         f"{r['hf']:,.0f} samples/s", f"{r['hf'] / r['uavris']:.2f}x"))
        elif spec.name == "paper-size":
            rows.append((spec.name, "HF DecisionTransformerModel", "n/a", "skipped (pip install -e '.[bench]')", "n/a"))
    print(table(rows))
    print()
    print(f"## Where the time goes: the deployment model's step (torch.profiler, {PROFILE_STEPS} steps, top "
          f"{PROFILE_TOP} operators by self CPU time)\n")
    print(table(profile_rows))
    print()
    print(f"profiled: {profile_ms:.1f} ms per step of wall time ({BATCH * 1e3 / profile_ms:,.0f} samples/s under the "
          f"profiler), {profile_self_ms:.1f} ms of self CPU time in all operators\n")
    print("## Rollouts\n")
    rows = [("case", "throughput", "relative")]
    for attention, (batched, sequential, slots) in rollouts.items():
        rows.append((f"rollout ({attention}), {episodes} episodes one by one",
                     f"{slots / sequential:,.0f} slots/s ({sequential:.2f} s)", "1.00x"))
        rows.append((f"rollout ({attention}), {episodes} episodes batched",
                     f"{slots / batched:,.0f} slots/s ({batched:.2f} s)", f"{sequential / batched:.2f}x"))
    print(table(rows))
    print()
    deploy = rates["deployment"]
    share = deploy["uavris"] / deploy["flat"]
    print(f"training, deployment model: device-set encoder / flat encoder = {share:.2f}x (target >= "
          f"{FLAT_SHARE_TARGET:g}x) {verdict(share >= FLAT_SHARE_TARGET)}")
    paper = rates["paper-size"]
    if "hf" in paper:
        print(f"training, paper-size model: uavris / Hugging Face = {paper['uavris'] / paper['hf']:.2f}x (target >= "
              f"1x) {verdict(paper['uavris'] >= paper['hf'])}")
    for attention, (batched, sequential, _) in rollouts.items():
        ratio = sequential / batched
        print(f"rollout ({attention}): batched / one by one = {ratio:.2f}x (target >= {ROLLOUT_RATIO_TARGET:.0f}x) "
              f"{verdict(ratio >= ROLLOUT_RATIO_TARGET)}")
    window_one, banded_batched = rollouts["window"][1], rollouts["banded"][0]
    print(f"rollout: banded batched / window one by one = {window_one / banded_batched:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
