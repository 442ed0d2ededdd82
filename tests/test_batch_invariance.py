"""An episode scores the same alone or in a batch: for every reference, a Decision Transformer
and an SB3 expert (``uavris evaluate --episodes 1`` and a sweep's batch agree on a seed)."""

from __future__ import annotations

import pytest

from uavris.agents.evaluation import evaluate
from uavris.agents.references import REFERENCE_SEED, REFERENCES, reference_policy
from uavris.config import SystemConfig
from uavris.layouts import LayoutGenerator

SEED = 1_000_000
K = 3  # the episode compared: alone, and the fourth of a batch of 5 (another row than the first)


def _hall(devices: int = 5, horizon: int = 24) -> tuple[SystemConfig, object]:
    base = SystemConfig(horizon=horizon, observe_devices=True)
    return LayoutGenerator(devices=devices).layout("unseen", 3, base).resolve(base)


def _alone_and_in_batch(make, system, where) -> tuple[float, float]:
    alone = evaluate(make(), system, where, 1, SEED + K).avg_sum_rate[0]
    batch = evaluate(make(), system, where, 5, SEED).avg_sum_rate[K]
    return float(alone), float(batch)


@pytest.mark.parametrize("name", list(REFERENCES))
def test_every_reference_scores_an_episode_alone_as_in_a_batch(name: str) -> None:
    system, where = _hall()
    alone, batch = _alone_and_in_batch(lambda: reference_policy(name, system, REFERENCE_SEED), system, where)
    assert alone == batch  # bit for bit: the random references draw per episode


def test_a_decision_transformer_scores_an_episode_alone_as_in_a_batch() -> None:
    """A goal-conditioned DT of the deployment track's shape (device-set encoder, 2 blocks, a
    10-slot window), untrained: its actions differ by a float32 ulp between batch sizes under
    fused kernels, and the closed loop turns that into another episode."""
    import torch

    from uavris.agents.dt.config import DTConfig
    from uavris.agents.dt.goals import FixedGoals
    from uavris.agents.dt.model import DecisionTransformer
    from uavris.agents.dt.policy import DTBatchPolicy

    system, where = _hall()
    torch.manual_seed(0)
    cfg = DTConfig(system.observation_dim, system.action_dim, context=10, width=64, depth=2, heads=1,
                   max_timestep=system.horizon, state_encoder="devices", devices=system.num_users,
                   elements=system.num_elements, goal=True)
    model = DecisionTransformer(cfg, return_scale=40.0).eval()
    for p in model.parameters():  # larger weights than the initialisation's, so the actions vary
        p.data.normal_(0.0, 0.3)
    goal = FixedGoals((12.0, 18.0, 5.0))
    alone, batch = _alone_and_in_batch(lambda: DTBatchPolicy(model, 1000.0, goals=goal, system=system), system,
                                       where)
    assert alone == batch


@pytest.mark.parametrize("algo", ["td3", "ppo"])
def test_an_sb3_expert_scores_an_episode_alone_as_in_a_batch(algo: str) -> None:
    import torch

    from uavris.agents.experts.sb3 import SB3Policy, algorithm_class
    from uavris.agents.experts.vec_env import expert_spaces

    system, where = _hall()
    torch.manual_seed(0)
    obs_space, act_space = expert_spaces(system, "agent")
    net = algorithm_class(algo).policy_aliases["MlpPolicy"](obs_space, act_space, lambda _: 0.0, net_arch=[64, 64])
    net.set_training_mode(False)
    for p in net.parameters():
        p.data.normal_(0.0, 0.2)
    alone, batch = _alone_and_in_batch(lambda: SB3Policy(net), system, where)
    assert alone == batch
    assert all(type(m) is torch.nn.Linear for m in net.modules() if isinstance(m, torch.nn.Linear))  # as it was
