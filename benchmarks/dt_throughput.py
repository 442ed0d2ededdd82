"""Single-core throughput of the uavris Decision Transformer: training and rollouts.

Two measurements, in this one process pinned to a single CPU, one torch thread:

1. **Training samples/s** of ``uavris.agents.dt.model.DecisionTransformer`` against Hugging
   Face ``transformers.DecisionTransformerModel`` at the same size (the DT paper's: context
   20, width 128, 3 layers, 1 head, MLP 512 with ReLU, dropout 0.1; state 158, action 22),
   the same batch (64 windows) and the same training step: forward, masked action MSE
   over the real slots, backward, gradient clipping at 0.25, AdamW. Both read the same
   pre-sampled windows, left-padded near episode starts as in real training. A *sample*
   is one context window. Hugging Face's model comes from the benchmark-only extra
   ``pip install -e '.[bench]'``; without it that row is skipped.
2. **Rollout** of 80 episodes (``unseen1``, seeds 0..79, the default system) by a DT of
   the same size: all 80 in one batched simulator with one forward pass per slot
   (``DTBatchPolicy`` + ``record_episodes``), against rolling the same 80 episodes out one
   by one (batch of 1). Same seeds, same model, same code path. Measured for both
   attention layouts: ``window`` (the DT paper's; every slot re-reads 59 tokens) and
   ``banded`` (every slot adds 3 tokens to a key/value cache; see
   ``uavris.agents.dt.model``).

Each case is warmed up, then timed ``--repeats`` times; the best timing is kept. The
script prints the machine, the command, a Markdown table and PASS/FAIL lines against the
targets (ours >= Hugging Face's samples/s; batched rollout >= 20x one-by-one). It always
exits 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/dt_throughput.py            # ~4 minutes
    .venv/bin/python benchmarks/dt_throughput.py --quick    # ~40 seconds (16 episodes, fewer steps)
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
from typing import Any, Callable  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)

from uavris.agents.dt.config import ATTENTION_LAYOUTS, DTConfig  # noqa: E402
from uavris.agents.dt.model import DecisionTransformer, masked_action_loss  # noqa: E402
from uavris.agents.dt.policy import DTBatchPolicy  # noqa: E402
from uavris.agents.dt.trajectories import TrainingWindows, Trajectory, record_episodes  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402

BATCH = 64
CONTEXT, WIDTH, DEPTH, HEADS, DROPOUT = 20, 128, 3, 1, 0.1
EPISODES = 80
SCENARIO = "unseen1"
TARGET_RETURN = 2000.0
ROLLOUT_RATIO_TARGET = 20.0


def best_of(fn: Callable[[], Any], repeats: int) -> float:
    timings = []
    for _ in range(repeats):
        gc.collect()
        start = time.perf_counter()
        fn()
        timings.append(time.perf_counter() - start)
    return min(timings)


# ------------------------------------------------------------------------------ training
def training_batches(system: SystemConfig, count: int, seed: int) -> list[dict[str, torch.Tensor]]:
    """Windows cut from random 100-slot trajectories, exactly as training samples them."""
    rng = np.random.default_rng(seed)
    trajs = [Trajectory(rng.standard_normal((system.horizon + 1, system.observation_dim)).astype(np.float32),
                        rng.uniform(-1, 1, (system.horizon, system.action_dim)).astype(np.float32),
                        rng.uniform(0, 30, system.horizon), False, True, SCENARIO, i) for i in range(32)]
    windows = TrainingWindows(trajs, CONTEXT)
    return [windows.sample(BATCH, rng) for _ in range(count)]


def ours_step_fn(system: SystemConfig) -> tuple[Callable[[dict], None], int]:
    torch.manual_seed(0)
    model = DecisionTransformer(DTConfig(system.observation_dim, system.action_dim, CONTEXT, WIDTH, DEPTH, HEADS,
                                         DROPOUT, max_timestep=system.horizon), return_scale=3000.0).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=1e-4)

    def step(b: dict) -> None:
        pred = model(b["returns_to_go"], b["states"], b["actions"], b["timesteps"], b["valid"])
        loss = masked_action_loss(pred, b["actions"], b["valid"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 0.25)
        opt.step()

    return step, sum(p.numel() for p in model.parameters())


def hf_step_fn(system: SystemConfig) -> tuple[Callable[[dict], None], int, str] | None:
    try:
        import transformers
        from transformers import DecisionTransformerConfig, DecisionTransformerModel
    except ImportError:
        return None
    transformers.logging.set_verbosity_error()
    torch.manual_seed(0)
    cfg = DecisionTransformerConfig(state_dim=system.observation_dim, act_dim=system.action_dim, hidden_size=WIDTH,
                                    n_layer=DEPTH, n_head=HEADS, n_inner=4 * WIDTH, activation_function="relu",
                                    resid_pdrop=DROPOUT, embd_pdrop=DROPOUT, attn_pdrop=DROPOUT,
                                    max_ep_len=system.horizon, action_tanh=True)
    model = DecisionTransformerModel(cfg).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=1e-4)

    def step(b: dict) -> None:
        # HF scales nothing itself; the same 1/3000 return scale as ours is applied here.
        out = model(states=b["states"], actions=b["actions"], returns_to_go=b["returns_to_go"][..., None] / 3000.0,
                    timesteps=b["timesteps"], attention_mask=b["valid"].long(), return_dict=True)
        loss = masked_action_loss(out.action_preds, b["actions"], b["valid"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 0.25)
        opt.step()

    impl = getattr(model.config, "_attn_implementation", None) or "default"
    params = sum(p.numel() for p in model.parameters())
    return step, params, f"transformers {transformers.__version__}, attention {impl}"


def measure_training(step: Callable[[dict], None], batches: list[dict], steps: int, repeats: int) -> float:
    for b in batches[:3]:
        step(b)

    def run() -> None:
        for i in range(steps):
            step(batches[i % len(batches)])

    return steps * BATCH / best_of(run, repeats)


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
def table(rows: list[tuple[str, ...]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(rows[0], widths)) + " |",
             "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in rows[1:]]
    return "\n".join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="16 episodes, fewer training steps, one timing")
    p.add_argument("--repeats", type=int, default=None, help="timings per case, best kept (default 3, quick 1)")
    args = p.parse_args(argv)
    args.repeats = args.repeats or (1 if args.quick else 3)
    return args


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
    print(f"- model: context {CONTEXT}, width {WIDTH}, depth {DEPTH}, heads {HEADS}, dropout {DROPOUT}, "
          f"state {system.observation_dim}, action {system.action_dim}; batch {BATCH}")
    print(f"- mode: {'quick' if args.quick else 'full'}, {steps} timed training steps, {episodes} episodes, "
          f"best of {args.repeats}\n", flush=True)

    batches = training_batches(system, 8, seed=0)
    print("measuring training (uavris) ...", file=sys.stderr, flush=True)
    ours_step, ours_params = ours_step_fn(system)
    ours = measure_training(ours_step, batches, steps, args.repeats)
    hf = hf_step_fn(system)
    hf_rate = None
    if hf is not None:
        print("measuring training (Hugging Face) ...", file=sys.stderr, flush=True)
        hf_rate = measure_training(hf[0], batches, steps, args.repeats)
    rollouts = {}
    for attention in ATTENTION_LAYOUTS:
        print(f"measuring rollouts of {episodes} episodes ({attention} attention) ...", file=sys.stderr, flush=True)
        rollouts[attention] = measure_rollouts(system, episodes, args.repeats, attention)

    rows = [("case", "throughput", "relative")]
    rows.append((f"training, uavris DT ({ours_params:,} parameters)", f"{ours:,.0f} samples/s", "1.00x"))
    if hf is not None and hf_rate is not None:
        rows.append((f"training, HF DecisionTransformerModel ({hf[1]:,} parameters; {hf[2]})",
                     f"{hf_rate:,.0f} samples/s", f"{hf_rate / ours:.2f}x"))
    else:
        rows.append(("training, HF DecisionTransformerModel", "skipped (pip install -e '.[bench]')", "n/a"))
    for attention, (batched, sequential, slots) in rollouts.items():
        rows.append((f"rollout ({attention}), {episodes} episodes one by one",
                     f"{slots / sequential:,.0f} slots/s ({sequential:.2f} s)", "1.00x"))
        rows.append((f"rollout ({attention}), {episodes} episodes batched",
                     f"{slots / batched:,.0f} slots/s ({batched:.2f} s)", f"{sequential / batched:.2f}x"))
    print(table(rows))
    print()
    if hf_rate is not None:
        print(f"training: uavris / Hugging Face = {ours / hf_rate:.2f}x (target >= 1x) "
              f"{'PASS' if ours >= hf_rate else 'FAIL'}")
    for attention, (batched, sequential, _) in rollouts.items():
        ratio = sequential / batched
        print(f"rollout ({attention}): batched / one by one = {ratio:.2f}x (target >= {ROLLOUT_RATIO_TARGET:.0f}x) "
              f"{'PASS' if ratio >= ROLLOUT_RATIO_TARGET else 'FAIL'}")
    window_one, banded_batched = rollouts["window"][1], rollouts["banded"][0]
    print(f"rollout: banded batched / window one by one = {window_one / banded_batched:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
