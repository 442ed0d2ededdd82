"""The oracle reference policies: the planning oracle and the greedy oracle it replaced.

Lives here: the two batch policies, the per-slot approach controller (:func:`fly_to`) and a
fixed plan flown anywhere (:class:`PlannedFlight`). Not here: the
plan (:mod:`.planner`) and the local lookahead (:mod:`.lookahead`).

Both are references for the learned policies, not deployable controllers. They read the
batch simulator's state, but only what the observation ``S_t`` holds: this slot's
channels ``H(t)`` and pairing ``P(t)`` and the UAV's pose (position, velocity, attitude;
``cos(theta)`` follows from it), plus the fixed device positions and system constants.
They never read the next slot's NLoS draw or pairing (drawn after the action, from
counters they do not use). Every slot, for every environment of the batch:

1. Phases: :func:`uavris.physics.phase_opt.optimize_slot_phases` on ``H(t)``,
   ``cos(theta(t))`` and ``P(t)`` (closed form for one active pair; multi-start L-BFGS with
   noise continuation and a nulling polish for several). They act on this slot's ``r(t)``.
2. Motion, for the move to slot ``t+1``:

   - **planning oracle** (:func:`oracle_policy`, the reference every report uses): the
     plan of :func:`.planner.plan_target` for the scenario's start, made once and cached,
     gives a target position and attitude. The UAV flies straight at it as fast as the
     bounds allow (:func:`approach_command`: the largest speed from which it can still stop
     at the target, reached at up to ``a_max``; lateral velocity is cancelled) and turns the
     RIS towards the target attitude by up to one attitude step per slot and axis. (Handing
     the last half metre to the local lookahead instead cost 0.1 bps/Hz on fig2 and unseen2,
     8 episodes each: its interference-free score pulls the UAV off the optimiser-refined
     target; docs/model.md, "The oracle".)
   - **greedy oracle** (:func:`greedy_oracle_policy`): the one-step lookahead from every
     state, the oracle of earlier releases. It climbs to the nearest local optimum of the
     expected rate: from ``unseen2`` it stops by device 3 although the region between
     devices 1 and 2 is worth more (docs/model.md, "The oracle").

Energy. Constraint (13g) is enforced by the environment, which ends the episode in the
slot where the propulsion energy reaches ``E_max``; the oracles are subject to it like
every other policy. Moving costs less than hovering, so an episode of an oracle that
hovers at its destination may end a few slots before the horizon (as ``hover``'s does);
the average sum rate is the mean over the slots flown.

Randomness: the optimiser's random starts and the plan's common random numbers are
hashes of ``seed`` (and of each slot's channels), so an evaluation is reproducible and an
episode gets the same optimiser starts whatever batch it is evaluated in.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.agents.oracle import store
from uavris.agents.oracle.lookahead import choose_moves
from uavris.agents.oracle.objective import approach_speed
from uavris.agents.oracle.planner import Plan, PlanSettings, holding, plan_target
from uavris.agents.policy import Privileged
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator, phases_to_action
from uavris.env.wrappers import motion_of
from uavris.physics.phase_opt import DEFAULT_ITERATIONS, DEFAULT_RESTARTS, optimize_slot_phases


def approach_command(config: SystemConfig, pos: NDArray, vel: NDArray, target: NDArray) -> NDArray[np.float64]:
    """Acceleration command ``(n, 3)`` that flies ``pos`` straight at ``target`` and stops there.

    The wanted end-of-slot velocity points at the target with :func:`.objective.approach_speed`
    (no velocity across the line); the simulator limits the command to ``a_max``. Steering
    the vertical leg first, so that the UAV travels at the target's low altitude, scored
    0.13 bps/Hz less on average over seven scenarios (16 episodes each) than the straight line.
    """
    d = target - pos
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    direction = d / np.maximum(dist, 1e-12)
    along = np.sum(vel * direction, axis=-1, keepdims=True)
    return (direction * approach_speed(config, dist, along) - vel) / config.slot_s


def turn_towards(config: SystemConfig, att: NDArray, target: NDArray) -> NDArray[np.float64]:
    """Attitude increments ``(n, 3)`` along the shorter way round, at most one step per axis."""
    diff = np.mod(target - att + np.pi, 2.0 * np.pi) - np.pi
    return np.clip(diff, -config.attitude_step_rad, config.attitude_step_rad)


def _action(config: SystemConfig, accel: NDArray, datt: NDArray, phases: NDArray) -> NDArray[np.float32]:
    c = config
    n_el = c.num_elements
    a = np.zeros((len(accel), c.action_dim), dtype=np.float64)
    a[:, 0:3] = ph.limit_norm(accel, c.a_max) / c.a_max
    a[:, 3:3 + n_el] = phases_to_action(phases)
    if c.learn_amplitudes:
        a[:, 3 + n_el:3 + 2 * n_el] = 1.0  # unit amplitude
    step = c.attitude_step_rad
    a[:, -3:] = datt / step if step > 0 else 0.0
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def _phases(sim: BatchedSimulator, restarts: int, iterations: int, seed: int) -> NDArray[np.float64]:
    return optimize_slot_phases(sim.config, sim.channels, sim.cos_theta, sim.pairing, restarts=restarts,
                                iterations=iterations, seed=seed).phases


def greedy_oracle_policy(*, restarts: int = DEFAULT_RESTARTS, iterations: int = DEFAULT_ITERATIONS,
                         braking_slots: int | None = None, seed: int = 0) -> Privileged:
    """The greedy oracle (privileged ``policy(obs, sim) -> actions``): optimised phases, one-step
    lookahead motion.

    Args:
        restarts, iterations: phase optimiser settings (random starts; L-BFGS iterations per level).
        braking_slots: length of the lookahead's braking continuation; ``None``: the slots
            needed to stop from ``v_max``.
        seed: non-negative seed of the optimiser's random starts.
    """
    if braking_slots is not None and braking_slots < 0:
        raise ValueError(f"braking_slots must be >= 0 or None, got {braking_slots}")

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        accel, datt, _ = choose_moves(sim.config, sim.pos, sim.vel, sim.att, braking_slots)
        return _action(sim.config, accel, datt, _phases(sim, restarts, iterations, seed))

    return Privileged(act)


def fly_to(sim: BatchedSimulator, plan: Plan) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The move towards ``plan``'s pose from the simulator's current state: acceleration command
    ``(n, 3)`` (m/s^2) and attitude increments ``(n, 3)`` (rad); the planning oracle's motion
    (module docstring), for any plan, also one made for another hall."""
    c = sim.config
    accel = approach_command(c, sim.pos, sim.vel, plan.target)
    # Level on the way, the planned attitude on arrival: a tilt that helps at the target
    # blocks distant devices (puts them behind the RIS) elsewhere. The turn starts when
    # the remaining distance is what v_max covers in the slots the turn takes.
    turn_slots = np.ceil(np.max(np.abs(np.mod(plan.attitude + np.pi, 2 * np.pi) - np.pi)) /
                         max(c.attitude_step_rad, 1e-12))
    arriving = np.linalg.norm(sim.pos - plan.target, axis=1) <= (turn_slots + 1) * c.v_max * c.slot_s
    datt = turn_towards(c, sim.att, np.where(arriving[:, None], plan.attitude, 0.0))
    if plan.front_margin_deg is not None:
        # A plan that keeps a margin is flown keeping it: the turn is cut as the attitude safety layer
        # cuts it, at the pose the slot's move reaches. Without the cut, a turn begun short of the
        # target, or the hover's drift, put a device behind the RIS for 1-12% of the slots of some
        # 3-device halls (docs/model.md section 19).
        accel_done = ph.feasible_acceleration(sim.vel, ph.limit_norm(accel, c.a_max), c.slot_s, c.v_max, c.a_max)
        moved, _ = ph.kinematic_step(sim.pos, sim.vel, accel_done, c.slot_s, sim.low, sim.high, sim.users,
                                     c.safety_distance)
        datt = ph.clear_attitude(sim.att, datt, moved, sim.users, np.radians(plan.front_margin_deg),
                                 c.attitude_step_rad)
    return accel, datt


def motion_entries(config: SystemConfig, accel: NDArray, datt: NDArray) -> NDArray[np.float32]:
    """A move as the 6 motion entries of an action in [-1, 1] (acceleration, attitude)."""
    return motion_of(_action(config, accel, datt, np.zeros((len(accel), config.num_elements))))


class PlannedFlight:
    """Flies to a fixed plan's pose (:func:`fly_to`) with the optimiser's phases: the motion of
    the planning oracle of the hall the plan was made for, carried to another hall (the
    deployment track's "nearest training hall" reference and a demonstration of mixed quality).
    Privileged like the oracle: it reads the simulator's pose and velocity."""

    privileged: ClassVar[bool] = True
    phase_control: ClassVar[str] = "optimizer"

    def __init__(self, plan: Plan) -> None:
        self.plan = plan

    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        return motion_entries(sim.config, *fly_to(sim, self.plan))


# Plans made by an oracle that had valued no pose of that system before, with the poses they
# valued: another oracle of the same settings that has not planned in that system either
# takes the plan and the poses instead of planning again. A study's evaluation of a hall
# flies the oracle's row and then plans the same hall again for the report's plan target and
# the learned value's accuracy; a worker evaluating several halls plans the same training
# hall for each one's transfer row (docs/timings.md). A few recent ones: a process plans one
# hall after another.
_FRESH_PLANS: OrderedDict[tuple[Any, ...], tuple[Plan, dict[bytes, float]]] = OrderedDict()
FRESH_PLANS_KEPT = 8


def forget_shared_plans() -> None:
    """Empty the plans oracles of this process share: a benchmark that times planning starts
    from nothing."""
    _FRESH_PLANS.clear()


class PlanningOracle:
    """The planning oracle as a privileged batch policy ``policy(obs, sim) -> actions`` (module docstring).

    Plans are cached per (system, start), so one instance evaluates many batches and
    scenarios at the cost of one plan each; :attr:`plans` holds them for reports. A plan is
    a function of the settings, the system and the start alone (its random numbers are the
    settings' seed), so a plan another instance of this process made from the same state
    (no pose of that system valued yet) is taken as it is, with the poses it valued
    (:meth:`valued_poses` is then what it would have been); so is one another process made,
    where the plan store is on (:mod:`.store`).
    """

    privileged: ClassVar[bool] = True  # reads the simulator's state (uavris.agents.policy)

    def __init__(self, *, restarts: int = DEFAULT_RESTARTS, iterations: int = DEFAULT_ITERATIONS, seed: int = 0,
                 settings: PlanSettings | None = None) -> None:
        if seed < 0:
            raise ValueError(f"seed must be >= 0, got {seed}")
        self.restarts, self.iterations, self.seed = restarts, iterations, seed
        self.settings = settings or PlanSettings(seed=seed)
        self.plans: dict[tuple[Any, ...], Plan] = {}
        self._memo: dict[SystemConfig, dict[bytes, float]] = {}

    def plan(self, config: SystemConfig, start: tuple[float, float, float]) -> Plan:
        key = (config, tuple(start))
        if key not in self.plans:
            planning = self._planning(config)
            memo = self._memo.setdefault(planning, {})
            shared = (self.settings, planning, tuple(float(x) for x in start))
            if memo:  # it valued poses of this system: it plans itself
                plan = plan_target(config, start, self.settings, memo)
            elif shared in _FRESH_PLANS:  # made from nothing by another oracle of this process
                plan, valued = _FRESH_PLANS[shared]
                _FRESH_PLANS.move_to_end(shared)
                memo.update(valued)
            else:  # made from nothing by another process (the store, where on), or here
                stored = store.key(*shared) if store.directory() else None
                kept = store.load(stored, shared[2], self.settings) if stored else None
                if kept is None:
                    plan = plan_target(config, start, self.settings, memo)
                    if stored:
                        store.save(stored, plan, memo)
                else:
                    plan, valued = kept
                    memo.update(valued)
                self._share(shared, plan, memo)
            self.plans[key] = plan
        return self.plans[key]

    @staticmethod
    def _share(shared: tuple[Any, ...], plan: Plan, memo: dict[bytes, float]) -> None:
        """Offer a plan made from nothing (and the poses it valued) to the other oracles of this process."""
        plan.target.flags.writeable = plan.attitude.flags.writeable = False  # shared from now on
        _FRESH_PLANS[shared] = (plan, dict(memo))
        while len(_FRESH_PLANS) > FRESH_PLANS_KEPT:
            _FRESH_PLANS.popitem(last=False)

    def _planning(self, config: SystemConfig) -> SystemConfig:
        """The system its plans of ``config`` are made in (:func:`.planner.holding`): a system under the
        safety layer with the plans' own margin shares the plans and valued poses of the one without it."""
        return holding(config, self.settings.front_margin_deg)

    def valued_poses(self, config: SystemConfig) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The poses ``(P, 6)`` (position, attitude) its plans of ``config`` valued with ``R``
        itself (not those valued with the cheap estimate), and ``R`` at each: what a learned
        value of a pose can be fitted to, at no cost beyond the plans."""
        memo = self._memo.get(self._planning(config), {})
        exact = [(np.frombuffer(key[1:], dtype=np.float64), value) for key, value in memo.items() if key[:1] == b"\x01"]
        if not exact:
            return np.zeros((0, 6)), np.zeros(0)
        return np.stack([pose for pose, _ in exact]), np.array([value for _, value in exact])

    def motion(self, sim: BatchedSimulator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The oracle's move for the simulator's current state: acceleration command ``(n, 3)``
        (m/s^2) and attitude increments ``(n, 3)`` (rad). A function of the pose and velocity
        alone, given the plan of the scenario's start."""
        return fly_to(sim, self.plan(sim.config, sim.scenario.start))

    def motion_action(self, sim: BatchedSimulator) -> NDArray[np.float32]:
        """:meth:`motion` as the 6 motion entries of an action in [-1, 1] (acceleration, attitude)."""
        return motion_entries(sim.config, *self.motion(sim))

    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        accel, datt = self.motion(sim)
        return _action(sim.config, accel, datt, _phases(sim, self.restarts, self.iterations, self.seed))


def oracle_policy(*, restarts: int = DEFAULT_RESTARTS, iterations: int = DEFAULT_ITERATIONS, seed: int = 0,
                  settings: PlanSettings | None = None) -> PlanningOracle:
    """The planning oracle (see :class:`PlanningOracle`), the reference of every report."""
    return PlanningOracle(restarts=restarts, iterations=iterations, seed=seed, settings=settings)
