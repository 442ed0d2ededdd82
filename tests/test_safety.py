"""Safety separation: the UAV keeps at least ``safety_distance`` from every device."""

import numpy as np
import pytest

from uavris import physics as ph
from uavris.config import ConfigError, SystemConfig, get_scenario
from uavris.env import UavRisD2DEnv, UavRisD2DVectorEnv
from uavris.env.simulator import BatchedSimulator

TOL = 1e-9  # m: the projection lands on the ball's surface up to rounding


def fly(config, scenario, n, steps, policy, seed=0):
    """Step ``n`` environments with ``policy(sim) -> actions``; per step, the least UAV-device
    distance and the largest speed over the batch."""
    sim = BatchedSimulator(config, scenario, n)
    sim.seed(seed + np.arange(n))
    sim.reset()
    closest, fastest = [], []
    for _ in range(steps):
        sim.step(policy(sim))
        closest.append(ph.separation(sim.pos, config.users).min())
        fastest.append(np.linalg.norm(sim.vel, axis=1).max())
    return np.array(closest), np.array(fastest), sim


def test_random_actions_never_come_closer_than_the_bound():
    cfg = SystemConfig()
    rng = np.random.default_rng(0)

    def policy(sim):
        a = rng.uniform(-1, 1, (sim.num_envs, cfg.action_dim))
        a[:, :3] = np.sign(a[:, :3])  # hard accelerations: walls, the speed bound and balls are all hit
        return a

    for scenario in ("fig2", "train7", "unseen2"):
        closest, fastest, _ = fly(cfg, scenario, 64, 300, policy, seed=1)
        assert closest.min() >= cfg.safety_distance - TOL
        assert fastest.max() <= cfg.v_max + 1e-9


@pytest.mark.parametrize("device", range(4))
def test_flying_straight_at_a_device_stops_on_its_ball(device):
    """Full acceleration towards one device from three training starts: the UAV reaches the
    ball's surface (it is pressed against it or slides over it), never enters it, and keeps
    |v| <= v_max."""
    cfg = SystemConfig()
    target = np.asarray(cfg.users[device])

    def policy(sim):
        a = np.zeros((sim.num_envs, cfg.action_dim))
        d = target - sim.pos
        a[:, :3] = d / np.linalg.norm(d, axis=1, keepdims=True)
        return a

    for scenario in ("train1", "train4", "train8"):
        closest, fastest, _ = fly(cfg, scenario, 2, 60, policy)
        assert closest.min() >= cfg.safety_distance - TOL
        assert closest.min() <= cfg.safety_distance + 1e-6  # the ball was reached
        assert fastest.max() <= cfg.v_max + 1e-9


def test_projection_onto_the_ball_removes_only_the_inward_velocity():
    centre = np.array([[20.0, 20.0, 1.0]])
    q = np.array([20.0, 20.0, 4.5])  # 3.5 m above the device
    v = np.array([1.0, 0.0, -4.0])  # sideways and down: crosses into the 3 m ball this slot
    q1, v1 = ph.kinematic_step(q, v, np.zeros(3), 0.5, [0, 0, 2], [40, 40, 8], centre, 3.0)
    free = q + v * 0.5
    normal = (free - centre[0]) / np.linalg.norm(free - centre[0])
    np.testing.assert_allclose(q1, centre[0] + 3.0 * normal, atol=1e-12)
    np.testing.assert_allclose(np.dot(v1, normal), 0.0, atol=1e-12)  # inward part removed
    np.testing.assert_allclose(v1, v - np.dot(v, normal) * normal, atol=1e-12)  # tangential part kept
    assert np.linalg.norm(v1) <= np.linalg.norm(v)
    # Moving away from a ball it touches: nothing is changed.
    q1, v1 = ph.kinematic_step([20, 20, 4.0], [0, 0, 1.0], [0, 0, 0], 0.5, [0, 0, 2], [40, 40, 8], centre, 3.0)
    np.testing.assert_allclose(q1, [20, 20, 4.5])
    np.testing.assert_allclose(v1, [0, 0, 1.0])


def test_ball_pressed_against_a_wall_keeps_the_uav_where_it_was():
    """A device 1 m from the wall x = 0: pushing out of its ball radially would leave the room;
    the UAV then stays at its feasible position and stops."""
    centre = np.array([[1.0, 20.0, 1.0]])
    q, v = np.array([0.2, 20.0, 4.0]), np.array([0.0, 0.0, -2.0])
    assert ph.separation(q, centre)[0] >= 3.0
    q1, v1 = ph.kinematic_step(q, v, np.zeros(3), 0.5, [0, 0, 2], [40, 40, 8], centre, 3.0)
    np.testing.assert_array_equal(q1, q)
    np.testing.assert_array_equal(v1, 0.0)


def test_energy_and_motion_unchanged_where_no_ball_is_touched():
    """With and without the separation the same actions give identical trajectories and
    energy while every UAV stays clear of the balls (gentle random actions from fig2)."""
    rng = np.random.default_rng(3)
    actions = rng.uniform(-0.3, 0.3, (40, 8, 22))
    runs = []
    for d in (0.0, 3.0):
        sim = BatchedSimulator(SystemConfig(safety_distance=d), "fig2", 8)
        sim.seed(np.arange(8))
        sim.reset()
        trace = []
        for a in actions:
            _, _, _, info = sim.step(a)
            trace.append((sim.pos.copy(), sim.vel.copy(), sim.energy.copy(), info.slot_energy.copy()))
        runs.append(trace)
    assert min(ph.separation(t[0], SystemConfig().users).min() for t in runs[1]) > 3.0
    for a, b in zip(*runs):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


def test_batched_equals_single_when_balls_are_touched():
    cfg = SystemConfig()
    n, steps = 3, 90  # within one episode
    target = np.asarray(cfg.users[1])
    rng = np.random.default_rng(9)
    noise = rng.uniform(-0.2, 0.2, (steps, n, 22))
    venv = UavRisD2DVectorEnv(n, cfg, "train1")
    envs = [UavRisD2DEnv(cfg, "train1") for _ in range(n)]
    venv.reset(seed=50)
    for i, env in enumerate(envs):
        env.reset(seed=50 + i)
    touched = False
    for t in range(steps):
        a = noise[t].copy()
        d = target - venv.unwrapped.sim.pos
        a[:, :3] += d / np.linalg.norm(d, axis=1, keepdims=True)
        obs, r, *_ = venv.step(a.astype(np.float32))
        for i, env in enumerate(envs):
            o, ri, *_ = env.step(a[i].astype(np.float32))
            np.testing.assert_array_equal(o, obs[i])
            assert ri == r[i]
        touched |= bool(np.any(np.abs(venv.unwrapped.sim.dist[:, 1] - cfg.safety_distance) < 1e-6))
    assert touched


def test_start_inside_a_ball_is_one_clear_error():
    with pytest.raises(ConfigError) as e:
        UavRisD2DEnv(scenario=[20.0, 8.0, 3.0])  # 1.5 m above device 1
    msg = str(e.value)
    assert "safety_distance = 3 m" in msg and "users[1]" in msg and "\n" not in msg
    get_scenario([20.0, 8.0, 4.6]).validate_for(SystemConfig())  # 3.1 m: allowed
    UavRisD2DEnv(SystemConfig(safety_distance=0.0), scenario=[20.0, 8.0, 3.0])  # separation off


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_safety_distance_names_the_field(bad):
    with pytest.raises(ConfigError, match="SystemConfig.safety_distance must be"):
        SystemConfig(safety_distance=bad)


def test_a_partial_config_takes_todays_defaults():
    partial = {k: v for k, v in SystemConfig().to_dict().items() if k != "safety_distance"}
    assert SystemConfig.from_dict(partial).safety_distance == 3.0
    assert SystemConfig.from_dict(SystemConfig().to_dict()) == SystemConfig()


def test_simulator_asserts_the_separation_in_debug_mode(monkeypatch):
    """With kinematics that ignore the balls (a simulated bug), the step's debug check fires."""
    original = ph.kinematic_step
    monkeypatch.setattr(ph, "kinematic_step", lambda q, v, a, dt, lo, hi, *_: original(q, v, a, dt, lo, hi))
    cfg = SystemConfig()
    target = np.asarray(cfg.users[1])

    def policy(sim):
        a = np.zeros((sim.num_envs, cfg.action_dim))
        a[:, :3] = (target - sim.pos) / np.linalg.norm(target - sim.pos, axis=1, keepdims=True)
        return a

    with pytest.raises(AssertionError, match="of a device"):
        fly(cfg, "train4", 1, 60, policy)


# ------------------------------------------------------------------ the attitude safety layer
STEP = np.radians(10.0)  # one slot's largest attitude change per angle


def _one_device_1_degree_in_front():
    """A level RIS at 3 m and one device 20 m away, 1 degree below the RIS plane: with pitch p
    (yaw = roll = 0) the normal is (sin p, 0, cos p), and the device's elevation above the plane
    is 1 degree - p, worked by hand."""
    q = np.array([0.0, 0.0, 3.0])
    device = np.array([[20.0, 0.0, 3.0 - 20.0 * np.tan(np.radians(1.0))]])
    return q, device


def test_the_layer_keeps_the_margin_against_an_increment_that_would_block():
    q, device = _one_device_1_degree_in_front()
    assert ph.worst_elevation(np.zeros(3), q, device) == pytest.approx(np.sin(np.radians(1.0)), abs=1e-12)
    # pitch +2 degrees would put the device 1 degree behind the plane; a 0.5-degree margin allows 0.5
    executed = ph.clear_attitude(np.zeros(3), np.radians([0.0, 2.0, 0.0]), q, device, np.radians(0.5), STEP)
    assert np.degrees(executed) == pytest.approx([0.0, 0.5, 0.0], abs=1e-6)
    assert ph.worst_elevation(executed, q, device) >= np.sin(np.radians(0.5)) - 1e-12


def test_the_layer_passes_an_increment_away_from_every_device_unchanged():
    q, device = _one_device_1_degree_in_front()
    away = np.radians([5.0, -2.0, 3.0])  # pitch away from the device; yaw and roll keep it in front
    assert np.array_equal(ph.clear_attitude(np.zeros(3), away, q, device, np.radians(0.5), STEP), away)
    # the margin out of reach (2 degrees, the device at 1 even level): any move that does not lower it passes
    assert np.array_equal(ph.clear_attitude(np.zeros(3), away, q, device, np.radians(2.0), STEP), away)
    toward = np.radians([0.0, 0.4, 0.0])
    assert np.degrees(ph.clear_attitude(np.zeros(3), toward, q, device, np.radians(2.0), STEP))[1] == pytest.approx(
        0.0, abs=1e-6)


def test_no_device_goes_behind_the_plane_under_the_layer_whatever_the_policy_does():
    """Random tilts in the paper's hall put devices behind the RIS without the layer, never with it."""
    from uavris.env.simulator import BatchedSimulator

    rng = np.random.default_rng(0)
    behind = {}
    for margin in (None, 1.0):
        c = SystemConfig(front_margin_deg=margin)
        sim = BatchedSimulator(c, "fig2", 16)
        sim.seed(np.arange(16))
        sim.reset()
        worst = np.inf
        for _ in range(40):
            action = rng.uniform(-1, 1, (16, c.action_dim)).astype(np.float32)
            sim.step(action)
            worst = min(worst, float(ph.worst_elevation(sim.att, sim.pos, np.asarray(c.users)).min()))
        behind[margin] = worst
    assert behind[None] < 0.0  # the policy alone blocks devices
    assert behind[1.0] >= np.sin(np.radians(1.0)) - 1e-9


def test_a_tilted_ris_whose_device_drops_behind_turns_back_towards_level():
    """Tilted 15 degrees, the device 5 degrees behind the plane: the layer turns the RIS towards
    level by up to one step, however the policy wanted to turn (here: further away)."""
    q, device = _one_device_1_degree_in_front()
    att = np.radians([0.0, 6.0, 0.0])  # the device at 1 - 6 = -5 degrees: behind
    executed = ph.clear_attitude(att, np.radians([0.0, 10.0, 0.0]), q, device, np.radians(0.5), STEP)
    assert np.degrees(executed)[1] == pytest.approx(-5.5, abs=1e-5)  # back to 0.5 degrees: the margin


def test_level_attitude_holds_the_attitude_and_keeps_the_policys_own_actions_in_its_memory():
    from uavris.agents.policy import LevelAttitude
    from uavris.env.rollout import rollout

    class Tilter:
        """Turns every angle by a full step every slot, and remembers what it was told it did."""

        phase_control = "optimizer"

        def begin(self, n):
            self.seen = []

        def __call__(self, obs):
            return np.tile(np.array([0.1, 0.0, 0.0, 1.0, -1.0, 1.0], dtype=np.float32), (obs.shape[0], 1))

        def record(self, actions, rewards):
            self.seen.append(actions.copy())

    inner = Tilter()
    atts = []
    rollout(LevelAttitude(inner), SystemConfig(horizon=5), "fig2", [0, 1],
            on_slot=lambda sim, obs, executed, alive: atts.append(sim.att.copy()))
    assert np.all(np.stack(atts) == 0.0)  # never turned
    assert all(np.array_equal(a[:, 3:], np.tile([1.0, -1.0, 1.0], (2, 1))) for a in inner.seen)  # its own choice
