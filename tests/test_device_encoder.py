"""The DT's state encoders: the device-set encoder reads a hall as a set of devices (the order
in which a layout lists them changes no bit of an action), the flat one does not."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from uavris.agents.dt.checkpoint import load_dt, save_dt
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.encoders import pooled_over_devices
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.references import reference_policy
from uavris.config import SystemConfig
from uavris.env import observation_layout
from uavris.env.rollout import rollout
from uavris.env.simulator import observation_slices
from uavris.errors import ConfigError
from uavris.layouts import LayoutGenerator

torch.set_num_threads(1)
SEEN = SystemConfig(observe_devices=True, horizon=12)
HALL, WHERE = LayoutGenerator().layout("train", 5).resolve(SEEN)
K, N = SEEN.num_users, SEEN.num_elements
PERMUTATIONS = [(1, 0, 2, 3), (3, 2, 1, 0), (2, 0, 3, 1)]


def hall_states(episodes: int = 4) -> np.ndarray:
    """Observations ``(episodes, T + 1, S)`` of a moving UAV in a generated hall (several pairings)."""
    b = rollout(reference_policy("hover-random-phases", HALL), HALL, WHERE, np.arange(episodes) + 40, record=True)
    rng = np.random.default_rng(0)
    obs = b.observations.copy()
    # move the UAV's view of the devices too, so the windows are not one pose repeated
    obs[..., observation_layout(HALL)["devices"]] += rng.normal(0, 0.1, obs[..., -3 * K:].shape).astype(np.float32)
    return obs


def permute_devices(states: np.ndarray, perm: tuple[int, ...]) -> np.ndarray:
    """The same observations with the devices listed in the order ``perm`` (an independent
    rearrangement: each per-device slice by rows, the pairing by rows and columns)."""
    lay = observation_layout(HALL)
    out = states.copy()
    lead = states.shape[:-1]
    p = list(perm)
    for name, width in (("channel_real", N), ("channel_imag", N), ("devices", 3)):
        out[..., lay[name]] = states[..., lay[name]].reshape(*lead, K, width)[..., p, :].reshape(*lead, -1)
    pairing = states[..., lay["pairing"]].reshape(*lead, K, K)
    out[..., lay["pairing"]] = pairing[..., p, :][..., :, p].reshape(*lead, -1)
    return out


def model(encoder: str, seed: int = 0, attention: str = "window", ris_frame: bool = False) -> DecisionTransformer:
    torch.manual_seed(seed)
    sized = dict(devices=K, elements=N, ris_frame=ris_frame) if encoder == "devices" else {}
    cfg = DTConfig(SEEN.observation_dim, 6, context=4, width=32, depth=2, heads=2, dropout=0.0,
                   max_timestep=SEEN.horizon, attention=attention, state_encoder=encoder, **sized)
    rng = np.random.default_rng(seed)  # normalisation that differs per entry, pooled for the device encoder
    mean, std = rng.normal(0, 0.1, SEEN.observation_dim), rng.uniform(0.5, 2.0, SEEN.observation_dim)
    if encoder == "devices":
        mean, std = pooled_over_devices(mean, std, K, N)
    return DecisionTransformer(cfg, mean, std, return_scale=40.0).eval()


def actions(m: DecisionTransformer, states: np.ndarray) -> torch.Tensor:
    b, length = states.shape[:2]
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():
        return m(torch.rand(b, length, generator=g) * 100, torch.from_numpy(states),
                 torch.rand(b, length, 6, generator=g) * 2 - 1, torch.arange(length).repeat(b, 1))


@pytest.mark.parametrize("perm", PERMUTATIONS)
def test_permuting_a_halls_devices_leaves_the_device_encoders_actions_bit_identical(perm):
    states = hall_states()[:, :4]  # 4 episodes, windows of 4 slots
    m = model("devices")
    a, b = actions(m, states), actions(m, permute_devices(states, perm))
    assert torch.equal(a, b)
    assert a.abs().max() > 1e-3  # and the actions are not trivially zero


@pytest.mark.parametrize("perm", PERMUTATIONS)
def test_with_the_ris_frame_permuting_the_devices_changes_no_bit_either(perm):
    states = tilted(hall_states()[:, :4])
    m = model("devices", ris_frame=True)
    a, b = actions(m, states), actions(m, permute_devices(states, perm))
    assert torch.equal(a, b) and a.abs().max() > 1e-3
    # and the elevations are read: the same hall level gives other actions
    assert (a - actions(m, hall_states()[:, :4])).abs().max() > 1e-5


def tilted(states: np.ndarray) -> np.ndarray:
    """The same observations with the RIS tilted by up to 8 degrees in every angle."""
    lay = observation_layout(HALL)
    att = np.radians(np.random.default_rng(1).uniform(-8, 8, states.shape[:-1] + (3,)))
    out = states.copy()
    out[..., lay["attitude_sin"]], out[..., lay["attitude_cos"]] = np.sin(att), np.cos(att)
    return out


def test_the_ris_frame_elevations_worked_by_hand():
    """Pitch p tilts the normal to (sin p, 0, cos p) (yaw = roll = 0, eq. 10). A device 20 m ahead
    (+x) and 1 m below the UAV sits at elevation atan(1/20) = 2.86 degrees below a level RIS; with
    p = 5 degrees it is 2.14 degrees behind the plane: cos(theta) = sin(2.86 - 5 degrees). One 20 m
    behind (-x), 1 m below, is then 7.86 degrees in front; one 20 m to a side (+-y) keeps its
    angle to the tilt axis: cos(theta) = cos(p) sin(2.86 degrees)."""
    enc = model("devices", ris_frame=True).embed_state
    lay = observation_layout(HALL)
    raw = torch.zeros(SEEN.observation_dim)
    p = np.radians(5.0)
    raw[lay["attitude_sin"]] = torch.tensor([0.0, np.sin(p), 0.0], dtype=torch.float32)
    raw[lay["attitude_cos"]] = torch.tensor([1.0, np.cos(p), 1.0], dtype=torch.float32)
    offsets = np.array([[20.0, 0, -1.0], [-20.0, 0, -1.0], [0, 20.0, -1.0], [0, -20.0, -1.0]]) / 20.0
    raw[lay["devices"]] = torch.tensor(offsets.ravel(), dtype=torch.float32)
    elev = np.degrees(np.arctan(1 / 20))
    side = np.cos(p) * np.sin(np.radians(elev))
    want = [np.sin(np.radians(elev - 5.0)), np.sin(np.radians(elev + 5.0)), side, side]
    np.testing.assert_allclose(enc.elevations(raw).numpy(), want, atol=1e-6)


def test_the_flat_encoder_is_not_order_free():
    states = hall_states()[:, :4]
    m = model("flat")
    diff = (actions(m, states) - actions(m, permute_devices(states, PERMUTATIONS[0]))).abs().max()
    assert diff > 1e-4  # the flat model's action depends on the order the layout lists its devices in


def test_the_device_encoder_reads_the_devices_a_changed_device_changes_the_action():
    states = hall_states()[:, :4]
    m = model("devices")
    moved = states.copy()
    moved[..., observation_layout(HALL)["devices"].start] += 0.5  # device 0 moves 10 m along x
    assert (actions(m, states) - actions(m, moved)).abs().max() > 1e-5


def test_the_banded_cached_deployment_is_order_free_too():
    states = hall_states(2)[:, :6]
    m = model("devices", attention="banded")
    assert torch.equal(actions(m, states), actions(m, permute_devices(states, PERMUTATIONS[2])))


def test_pooled_statistics_equal_those_of_the_devices_pooled_data():
    # Independent calculation: stack every device's entries as extra samples and take numpy's
    # mean and std of the stacked column.
    rng = np.random.default_rng(1)
    lay = observation_layout(HALL)
    x = rng.normal(rng.normal(0, 1, SEEN.observation_dim), rng.uniform(0.1, 3, SEEN.observation_dim),
                   (500, SEEN.observation_dim))
    mean, std = pooled_over_devices(x.mean(0), x.std(0), K, N)
    for name, width in (("channel_real", N), ("channel_imag", N), ("devices", 3)):
        block = x[:, lay[name]].reshape(-1, K, width).reshape(-1, width)  # (samples * K, width)
        np.testing.assert_allclose(mean[lay[name]], np.tile(block.mean(0), K), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(std[lay[name]], np.tile(block.std(0), K), rtol=1e-10)
    whole = x[:, lay["pairing"]].ravel()
    np.testing.assert_allclose(mean[lay["pairing"]], whole.mean(), rtol=1e-12)
    np.testing.assert_allclose(std[lay["pairing"]], whole.std(), rtol=1e-10)
    uav = lay["position"]
    np.testing.assert_array_equal(mean[uav], x.mean(0)[uav])  # the UAV's own entries keep theirs


def test_a_device_encoder_needs_the_devices_in_the_observation():
    with pytest.raises(ConfigError, match="observe_devices"):
        DTConfig(SystemConfig().observation_dim, 6, state_encoder="devices", devices=K, elements=N)
    with pytest.raises(ConfigError, match="state_encoder"):
        DTConfig(SEEN.observation_dim, 6, state_encoder="graph")


def test_a_device_encoder_checkpoint_round_trips(tmp_path):
    m = model("devices", seed=4)
    save_dt(m, tmp_path, {"target_return": 1.0})
    back, _ = load_dt(tmp_path)
    states = hall_states(2)[:, :4]
    assert back.cfg == m.cfg and torch.equal(actions(back.eval(), states), actions(m, states))


def test_an_ensemble_acts_with_the_mean_of_its_models_actions():
    from uavris.agents.dt.policy import DTBatchPolicy, DTEnsemble

    members = [DTBatchPolicy(model("devices", seed=s), 50.0, phase_control="optimizer") for s in (1, 2, 3)]
    alone = [DTBatchPolicy(model("devices", seed=s), 50.0, phase_control="optimizer") for s in (1, 2, 3)]
    ensemble = DTEnsemble(members)
    states = hall_states(3)
    ensemble.begin(3)
    for m in alone:
        m.begin(3)
    for t in range(4):
        got = ensemble(states[:, t])
        own = [m(states[:, t]) for m in alone]
        np.testing.assert_allclose(got, np.mean(own, axis=0), rtol=1e-6, atol=1e-7)
        assert np.ptp(np.stack(own), axis=0).max() > 1e-4  # the members disagree: the mean is not trivial
        rewards = np.full(3, 30.0)
        ensemble.record(got, rewards)
        for m in alone:  # each member's history holds the executed (mean) action
            m.record(got, rewards)
    with pytest.raises(ValueError, match="at least one"):
        DTEnsemble([])


def doubled_hall(states: np.ndarray) -> np.ndarray:
    """The same slots in a hall of 2K devices: every device twice, every pair twice (device
    k + K is device k's twin and pairs with the twin of k's partner), the UAV's own entries
    unchanged. Built from the observation's layout for 2K devices, independently of the model."""
    lay, big = observation_layout(HALL), observation_slices(2 * K, N, True)
    lead = states.shape[:-1]
    out = np.zeros((*lead, big["devices"].stop), dtype=states.dtype)
    for name, sl in big.items():
        if name in ("channel_real", "channel_imag", "devices"):
            rows = states[..., lay[name]].reshape(*lead, K, -1)
            out[..., sl] = np.concatenate([rows, rows], axis=-2).reshape(*lead, -1)
        elif name == "pairing":
            p = states[..., lay[name]].reshape(*lead, K, K)
            block = np.zeros((*lead, 2 * K, 2 * K), dtype=states.dtype)
            block[..., :K, :K], block[..., K:, K:] = p, p
            out[..., sl] = block.reshape(*lead, -1)
        else:
            out[..., sl] = states[..., lay[name]]
    return out


@pytest.mark.parametrize("ris_frame", [False, True])
def test_a_model_reads_a_hall_of_another_device_count_with_the_same_weights(ris_frame):
    """Every device twice is the same set for the encoder's maximum and mean: a model made for
    2K devices (``for_devices``) gives, on the doubled hall, the actions it gives on the hall."""
    states = hall_states(3)[:, :4]
    m = model("devices", seed=5, ris_frame=ris_frame)
    big = m.for_devices(2 * K)
    assert big.cfg.devices == 2 * K and big.cfg.state_dim == observation_slices(2 * K, N, True)["devices"].stop
    torch.testing.assert_close(actions(big, doubled_hall(states)), actions(m, states), rtol=1e-5, atol=1e-6)
    assert m.for_devices(K) is m
    # a third device count runs too, and its actions differ from the hall's (it reads the devices)
    three = m.for_devices(3)
    lay3, lay = observation_slices(3, N, True), observation_layout(HALL)
    first3 = np.concatenate([states[..., lay[s]].reshape(*states.shape[:-1], K, -1)[..., :3, :]
                             .reshape(*states.shape[:-1], -1) if s in ("channel_real", "channel_imag", "devices")
                             else states[..., lay[s]].reshape(*states.shape[:-1], K, K)[..., :3, :3]
                             .reshape(*states.shape[:-1], -1) if s == "pairing" else states[..., lay[s]]
                             for s in lay3], axis=-1)
    a3 = actions(three, first3)
    assert torch.isfinite(a3).all() and not torch.allclose(a3, actions(m, states))


def test_a_flat_model_cannot_read_another_device_count():
    with pytest.raises(ConfigError, match="only a DT with the device-set encoder"):
        model("flat").for_devices(6)


def test_a_dt_policy_is_evaluated_in_a_hall_of_six_devices():
    """evaluate() fits a device-encoder DT to the hall it is given; a flat one is refused in one line."""
    from uavris.agents.dt.policy import DTBatchPolicy
    from uavris.agents.evaluation import evaluate

    hall6, where6 = LayoutGenerator(devices=6).layout("unseen", 1).resolve(SEEN)
    policy = DTBatchPolicy(model("devices", seed=6), 50.0, phase_control="optimizer")
    res = evaluate(policy, hall6, where6, 2, 0)
    assert res.avg_sum_rate.shape == (2,) and np.all(np.isfinite(res.avg_sum_rate)) and res.avg_sum_rate.min() > 0
    flat = DTBatchPolicy(model("flat"), 50.0, phase_control="optimizer")
    with pytest.raises(ConfigError, match="reads observations of"):
        evaluate(flat, hall6, where6, 2, 0)


def centroid_motion(obs: np.ndarray) -> np.ndarray:
    """A teacher any count can follow: fly towards the devices' centroid (the devices' offsets
    are the observation's last 3 K entries), attitude unchanged."""
    from uavris.agents.dt.encoders import devices_of_width

    k = devices_of_width(obs.shape[-1], N)
    centre = obs[:, -3 * k:].reshape(len(obs), k, 3).mean(axis=1)
    out = np.zeros((len(obs), 6), dtype=np.float32)
    out[:, :3] = np.clip(centre / 5.0, -1.0, 1.0)
    return out


def test_one_model_learns_halls_of_two_device_counts_together():
    """MixedWindows draws each batch from one count, each set in proportion to its slots, and
    one device-set model trained on both fits the teacher in both (the loss falls by more than
    half on fixed windows of each count)."""
    from uavris.agents.dt.training import MixedWindows, TrainingWindows, make_optimizer, masked_action_loss, train_steps
    from uavris.agents.dt.trajectories import record_episodes

    sets = []
    for k, hall in ((4, 2), (6, 3)):
        system, where = LayoutGenerator(devices=k).layout("train", hall).resolve(SEEN)
        sets.append(record_episodes(centroid_motion, system, where, np.arange(6) + 10 * k, phase_control="optimizer"))
    torch.manual_seed(0)
    cfg = DTConfig(SEEN.observation_dim, 6, context=4, width=32, depth=1, heads=1, dropout=0.0,
                   max_timestep=SEEN.horizon, state_encoder="devices", devices=K, elements=N)
    m = DecisionTransformer(cfg, return_scale=40.0)
    parts = [TrainingWindows.for_model(s, cfg) for s in sets]
    mixed = MixedWindows(parts)
    rng = np.random.default_rng(0)
    widths = [mixed.sample(2, rng)["states"].shape[-1] for _ in range(2000)]
    share = widths.count(SEEN.observation_dim) / len(widths)
    p = parts[0].num_slots / mixed.num_slots
    assert abs(share - p) < 4 * np.sqrt(p * (1 - p) / len(widths))
    fixed = [part.sample(64, np.random.default_rng(1)) for part in parts]

    def losses() -> list[float]:
        with torch.no_grad():
            return [float(masked_action_loss(m(b["returns_to_go"], b["states"], b["actions"], b["timesteps"],
                                                 b["valid"]), b["actions"], b["valid"])) for b in fixed]
    before = losses()
    train_steps(m, make_optimizer(m, 1e-3, 0.0), mixed, rng, 0, 200, 32, 1e-3, 10, 1.0)
    after = losses()
    assert all(a < 0.5 * b for a, b in zip(after, before)), (before, after)


def test_more_datasets_need_the_device_encoder_and_every_episode():
    from uavris.experiments.training.pretrain import PretrainConfig

    with pytest.raises(ConfigError, match="more_datasets needs the model's state_encoder 'devices'"):
        PretrainConfig(dataset="a", more_datasets=("b",))
    with pytest.raises(ConfigError, match="not with more_datasets"):
        PretrainConfig(dataset="a", more_datasets=("b",), model={"state_encoder": "devices"}, scenarios=("x",))
    assert PretrainConfig(dataset="a", more_datasets=["b"], model={"state_encoder": "devices"}).more_datasets == ("b",)
