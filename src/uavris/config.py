"""System configuration and named scenarios.

Every parameter of the paper's simulation section is a field of :class:`SystemConfig`;
the parameters the paper leaves open (slot length, horizon, speed and acceleration bounds,
attitude step, noise power, energy budget, flight region) carry documented defaults, see
``docs/model.md``. Configs are frozen data: a bad value of a field raises
:class:`~uavris.errors.ConfigError` naming the field and the allowed range when the config is
made; what several fields decide together (a system's hall: its devices in its room) is judged
by :meth:`SystemConfig.check`, once the config is whole.

Lives here: :class:`SystemConfig`, :class:`PropulsionParams`, :class:`Scenario`, the
named scenarios and :class:`DictConfig`, the one ``to_dict`` / ``from_dict`` convention of
every config dataclass of uavris. Not here: the configurations of learning (each with its algorithm) and
the presets (:mod:`uavris.presets`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import sys
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping, Sequence, TypeVar, get_args

from uavris.errors import ConfigError
from uavris.io import INTERNAL, OMIT_DEFAULT, to_plain

C = TypeVar("C", bound="DictConfig")


class DictConfig:
    """The one dict convention of uavris's frozen config dataclasses (a mixin).

    :meth:`to_dict` gives plain JSON / YAML values (tuples as lists, nested configs as
    dicts): what run directories, stage keys and job arguments store. :meth:`from_dict`
    is its inverse: a partial dict takes the defaults for what it leaves out, an unknown
    field is one :class:`~uavris.errors.ConfigError` line naming it, a nested config field
    is rebuilt from its dict (one the class names in ``partial_fields`` is left a mapping, of
    the fields that differ from its preset's), the class's own validation runs as on any
    construction, and the whole config is checked (:meth:`check`).
    """

    def to_dict(self) -> dict[str, Any]:
        return to_plain(self)

    @classmethod
    def from_dict(cls: type[C], d: Mapping[str, Any]) -> C:
        if not isinstance(d, Mapping):
            raise ConfigError(f"{cls.__name__} must be given as a mapping of its fields, got {type(d).__name__}")
        known = {f.name for f in dataclasses.fields(cls) if not f.metadata.get(INTERNAL)}  # type: ignore[arg-type]
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"{cls.__name__} has no field(s) {unknown}; known fields: {sorted(known)}")
        hints = typing.get_type_hints(cls, vars(sys.modules[cls.__module__]))
        values = {}
        for name, value in d.items():
            nested = nested_config(hints.get(name))
            if nested is not None and isinstance(value, Mapping) and name not in getattr(cls, "partial_fields", ()):
                value = nested.from_dict(value)
            elif isinstance(value, list) and _holds_tuple(hints.get(name)):
                value = tuple(value)  # JSON and YAML have lists only; the configs hold tuples (hashable)
            values[name] = value
        try:
            built = cls(**values)
        except TypeError as e:
            raise ConfigError(f"bad {cls.__name__}: {e}") from None
        return built.check()

    def check(self: C) -> C:
        """What no single field decides, judged once the config is whole (a system's hall), in every
        nested config; ``self``. A field's own range is judged when the config is made."""
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if isinstance(value, DictConfig):
                value.check()
        return self


def union_members(hint: Any) -> tuple[Any, ...]:
    """The types a field's annotation allows (``X | Y`` -> X, Y)."""
    union = isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union
    return get_args(hint) if union else (hint,)


def nested_config(hint: Any) -> type[DictConfig] | None:
    """The config class a field's annotation holds (``X`` or ``X | None``), else None."""
    for opt in union_members(hint):
        if isinstance(opt, type) and issubclass(opt, DictConfig):
            return opt
    return None


def _holds_tuple(hint: Any) -> bool:
    return any(opt is tuple or typing.get_origin(opt) is tuple for opt in union_members(hint))

Vec3 = tuple[float, float, float]

PAPER_USERS: tuple[Vec3, ...] = (
    (15.0, 5.0, 1.0),
    (20.0, 8.0, 1.5),
    (30.0, 20.0, 0.1),
    (15.0, 35.0, 0.6),
)


def _check(ok: bool, owner: str, name: str, allowed: str, value: Any) -> None:
    if not ok:
        raise ConfigError(f"{owner}.{name} must be {allowed}, got {value!r}")


def _device(k: int) -> str:
    """Device ``k`` of ``users`` as errors name it: its index and D1, D2, ... as layout files and plots count."""
    return f"users[{k}] (device D{k + 1})"


def _finite(x: Any) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def float_tuple(value: Any, owner: str, name: str, allowed: str) -> tuple[float, ...]:
    """``value`` as a tuple of floats, or a one-line :class:`ConfigError` naming the field: its
    entries are numbers (YAML's ``true`` or a quoted ``"3"`` is not a coordinate)."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__") or any(
            isinstance(v, bool) or not isinstance(v, numbers.Real) for v in value):
        raise ConfigError(f"{owner}.{name} must be {allowed}, got {value!r}")
    return tuple(float(v) for v in value)


def check_positive(owner: str, cfg: Any, names: Sequence[str]) -> None:
    """Each field ``names`` of the dataclass ``cfg`` must be a finite number > 0."""
    for name in names:
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 and math.isfinite(v)):
            raise ConfigError(f"{owner}.{name} must be > 0, got {v!r}")


def check_non_negative(owner: str, cfg: Any, names: Sequence[str]) -> None:
    """Each field ``names`` of the dataclass ``cfg`` must be a finite number >= 0 (NaN is not)."""
    for name in names:
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0 and math.isfinite(v)):
            raise ConfigError(f"{owner}.{name} must be >= 0, got {v!r}")


@dataclass(frozen=True)
class PropulsionParams(DictConfig):
    """Rotary-wing propulsion power model of Zeng, Xu and Zhang (IEEE TWC 2019).

    Defaults are that paper's values; hovering costs ``blade_profile_w + induced_w``
    = 168.49 W.
    """

    blade_profile_w: float = 79.86  # P0
    induced_w: float = 88.63  # Pi
    tip_speed: float = 120.0  # U_tip, m/s
    hover_induced_velocity: float = 4.03  # v0, m/s
    fuselage_drag_ratio: float = 0.6  # d0
    air_density: float = 1.225  # rho, kg/m^3
    rotor_solidity: float = 0.05  # s
    rotor_disc_area: float = 0.503  # A, m^2

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            _check(_finite(v) and v > 0, "PropulsionParams", f.name, "a finite number > 0", v)


def unkeyed(default: Any) -> Any:
    """A field added after a release: written by ``to_dict`` only when set (:data:`uavris.io.OMIT_DEFAULT`),
    so the stage keys of studies made before it hold."""
    return dataclasses.field(default=default, metadata={OMIT_DEFAULT: True})


@dataclass(frozen=True)
class SystemConfig(DictConfig):
    """The UAV-mounted RIS D2D system (paper Sec. II and V, docs/model.md).

    Units: metres, seconds, watts, joules, dBm for the noise power.
    """

    room: Vec3 = (40.0, 40.0, 8.0)  # the hall: x, y, z extent in m (the paper's 40 x 40 x 8)
    users: tuple[Vec3, ...] = PAPER_USERS  # the D2D devices: x y z (m) of each, in turn (the paper's four)
    nx: int = 4  # RIS elements along x (the paper's 4 x 4 UPA)
    ny: int = 4  # RIS elements along y
    element_spacing: float = 0.5  # element spacing over wavelength, d / lambda
    rician_factor: float = 8.0  # Rician factor kappa of the device-RIS channels
    pathloss_exponent: float = 2.4  # path-loss exponent alpha
    tx_power_w: float = 1.0  # transmit power P of each device, W
    noise_dbm: float = -80.0  # noise power sigma^2 at each receiver, dBm
    reference_gain_db: float = unkeyed(0.0)  # per-hop path gain at 1 m, dB (0: none, the paper's; free space -40)
    slot_s: float = 0.5  # slot length Delta t, s
    horizon: int = 100  # slots per episode, T
    v_max: float = 5.0  # the UAV's largest speed, m/s
    a_max: float = 2.0  # the UAV's largest acceleration, m/s^2
    attitude_step_deg: float = 10.0  # largest attitude change per slot and axis (yaw, pitch, roll), degrees
    z_min: float = 2.0  # the UAV's lowest altitude, m (every device stands below it)
    z_max: float = 8.0  # the UAV's highest altitude, m (at most the room's height)
    safety_distance: float = 3.0  # least UAV-device distance, m (docs/model.md, defaults table)
    front_margin_deg: float | None = None  # attitude safety layer: every device kept this far (deg) in front of the RIS
    min_device_spacing: float = 5.0  # least horizontal distance between two devices, m (docs/study.md, section 2)
    energy_budget_j: float = 8000.0  # propulsion energy budget E_max of an episode, J
    max_active_pairs: int | None = None  # most D2D pairs active in a slot; None: floor(K/2)
    angle_dependent_reflection: bool = True  # False: r = r_pre (ideal RIS)
    learn_amplitudes: bool = False  # True: N extra action entries set |r_pre| in [0, 1]
    channel_ref_distance: float = 10.0  # observation scale for channels, m
    observe_devices: bool = False  # True: the observation ends with the device positions (docs/study.md, section 2)
    propulsion: PropulsionParams = field(default_factory=PropulsionParams)

    def __post_init__(self) -> None:
        o = "SystemConfig"
        # Normalise list inputs (from YAML or the CLI) to tuples so the config stays hashable.
        object.__setattr__(self, "room", float_tuple(self.room, o, "room", "three finite lengths > 0 (x, y, z in m)"))
        _check(isinstance(self.users, (list, tuple)), o, "users", "a list of [x, y, z] device positions (m)",
               self.users)
        object.__setattr__(self, "users", tuple(float_tuple(u, o, _device(k), "a point [x, y, z] (m)")
                                                for k, u in enumerate(self.users)))
        if isinstance(self.propulsion, dict):
            object.__setattr__(self, "propulsion", PropulsionParams(**self.propulsion))
        _check(len(self.room) == 3 and all(_finite(v) and v > 0 for v in self.room), o, "room",
               "three finite lengths > 0 (x, y, z in m)", self.room)
        _check(len(self.users) >= 2, o, "users", "a list of at least 2 positions (K >= 2)", len(self.users))
        _check(isinstance(self.observe_devices, bool), o, "observe_devices", "true or false", self.observe_devices)
        for name in ("nx", "ny", "horizon"):
            v = getattr(self, name)
            _check(isinstance(v, int) and not isinstance(v, bool) and v >= 1, o, name, "an integer >= 1", v)
        positive = ("element_spacing", "tx_power_w", "slot_s", "v_max", "a_max", "energy_budget_j",
                    "channel_ref_distance", "pathloss_exponent")
        for name in positive:
            v = getattr(self, name)
            _check(_finite(v) and v > 0, o, name, "a finite number > 0", v)
        _check(_finite(self.rician_factor) and self.rician_factor >= 0, o, "rician_factor",
               "a finite number >= 0", self.rician_factor)
        _check(_finite(self.noise_dbm), o, "noise_dbm", "a finite number (dBm)", self.noise_dbm)
        _check(_finite(self.reference_gain_db) and -200 <= self.reference_gain_db <= 0, o, "reference_gain_db",
               "a finite gain in [-200, 0] dB", self.reference_gain_db)
        _check(_finite(self.attitude_step_deg) and 0 <= self.attitude_step_deg <= 180, o,
               "attitude_step_deg", "in [0, 180]", self.attitude_step_deg)
        _check(_finite(self.safety_distance) and self.safety_distance >= 0, o, "safety_distance",
               "a finite distance >= 0 (m)", self.safety_distance)
        _check(self.front_margin_deg is None or (_finite(self.front_margin_deg) and 0 <= self.front_margin_deg < 90),
               o, "front_margin_deg", "None (no attitude safety layer) or an angle in [0, 90) degrees",
               self.front_margin_deg)
        _check(_finite(self.min_device_spacing) and self.min_device_spacing >= 0, o, "min_device_spacing",
               "a finite distance >= 0 (m)", self.min_device_spacing)

    def check(self) -> SystemConfig:
        """What the hall decides, judged once the system is whole (a command's build, a layout's
        system, a file read, every simulator made of it): the UAV's heights under the ceiling, every
        device inside the room, below the UAV's floor and apart from the others, the pairs its
        devices can make; ``self``. Made on its own, a system judges only each field's range, so
        that its room and its devices can come from different places (a flag, a layout)."""
        o = "SystemConfig"
        super().check()
        _check(_finite(self.z_min) and _finite(self.z_max) and 0 <= self.z_min < self.z_max <= self.room[2],
               o, "z_min/z_max", f"0 <= z_min < z_max <= room height {self.room[2]}", (self.z_min, self.z_max))
        for k, u in enumerate(self.users):
            _check(len(u) == 3, o, _device(k), "a point [x, y, z] (m)", list(u))
            inside = all(_finite(c) and 0.0 <= c <= r for c, r in zip(u, self.room))
            _check(inside, o, _device(k), f"a point inside the room [0, {self.room}]", list(u))
            # The model has every device below the RIS (docs/model.md, section 3): a device above
            # the UAV's floor would be cut off by back-side blocking whenever the UAV flies lower.
            _check(u[2] < self.z_min, o, _device(k), f"below the UAV's floor z_min = {self.z_min:g} m "
                   f"(a device height < {self.z_min:g})", list(u))
        for i in range(len(self.users)):
            for j in range(i + 1, len(self.users)):
                gap = math.dist(self.users[i][:2], self.users[j][:2])
                _check(gap >= self.min_device_spacing, o, _device(j),
                       f"at least min_device_spacing = {self.min_device_spacing:g} m (horizontally) from every other "
                       f"device, but it is {gap:.2f} m from device D{i + 1} = {list(self.users[i])}",
                       list(self.users[j]))
        kmax = self.num_users // 2
        if self.max_active_pairs is not None:
            v = self.max_active_pairs
            _check(isinstance(v, int) and 1 <= v <= kmax, o, "max_active_pairs", f"an integer in [1, {kmax}]", v)
        return self

    @property
    def num_users(self) -> int:
        return len(self.users)

    @property
    def num_elements(self) -> int:
        return self.nx * self.ny

    @property
    def pairs_upper(self) -> int:
        """Largest number of simultaneously active pairs."""
        return self.max_active_pairs or self.num_users // 2

    @property
    def noise_w(self) -> float:
        """The noise power every rate sees, W: sigma^2 over the two hops' reference gain beta0^2.
        The channels keep the paper's h = d^(-alpha/2) g (eq. 1); a reference path gain beta0 on
        each hop scales every cascaded gain by beta0^2, and SINR = P beta0^2 S / (P beta0^2 I +
        sigma^2) = P S / (P I + sigma^2 / beta0^2): the rates are exactly those of this noise,
        and the observed channels keep their scale (docs/model.md, "The regime")."""
        return 10.0 ** ((self.noise_dbm - 2.0 * self.reference_gain_db) / 10.0) / 1000.0

    @property
    def attitude_step_rad(self) -> float:
        return math.radians(self.attitude_step_deg)

    @property
    def action_dim(self) -> int:
        """3 accelerations + N phases (+ N amplitudes) + 3 attitude increments."""
        return 3 + self.num_elements * (2 if self.learn_amplitudes else 1) + 3

    @property
    def observation_dim(self) -> int:
        k, n = self.num_users, self.num_elements
        return 3 + 3 + 6 + 2 * k * n + k * k + 2 + (3 * k if self.observe_devices else 0)

    @property
    def region_low(self) -> Vec3:
        return (0.0, 0.0, self.z_min)

    @property
    def region_high(self) -> Vec3:
        return (self.room[0], self.room[1], self.z_max)

    def replace(self, **changes: Any) -> SystemConfig:
        """This system with ``changes``, checked whole (:meth:`check`)."""
        return dataclasses.replace(self, **changes).check()

    def nearest_device(self, position: Vec3) -> tuple[int, float]:
        """Index of the device closest to ``position`` and its distance, m."""
        dist = [math.dist(position, u) for u in self.users]
        k = min(range(len(dist)), key=dist.__getitem__)
        return k, dist[k]



@dataclass(frozen=True)
class Scenario:
    """A deployment: the UAV's initial position (it starts at rest and level)."""

    name: str
    start: Vec3

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", tuple(float(c) for c in self.start))
        _check(len(self.start) == 3 and all(_finite(c) for c in self.start), "Scenario", "start",
               "three finite coordinates", self.start)

    def to_dict(self) -> dict[str, Any]:
        """JSON-native form that :func:`get_scenario` reads back."""
        return {"name": self.name, "start": list(self.start)}

    def validate_for(self, config: SystemConfig) -> None:
        """The start must lie in the flight region and keep the safety distance from every device."""
        lo, hi = config.region_low, config.region_high
        inside = all(lo_i <= c <= hi_i for c, lo_i, hi_i in zip(self.start, lo, hi))
        _check(inside, f"Scenario({self.name!r})", "start", f"inside the flight region {lo}..{hi}", self.start)
        k, dist = config.nearest_device(self.start)
        _check(dist >= config.safety_distance, f"Scenario({self.name!r})", "start",
               f"at least safety_distance = {config.safety_distance:g} m from every device, but it is "
               f"{dist:.2f} m from users[{k}] = {list(config.users[k])}", list(self.start))


def _s(name: str, x: float, y: float) -> Scenario:
    return Scenario(name, (x, y, 4.5))


ScenarioName = Literal["fig2", "train1", "train2", "train3", "train4", "train5", "train6", "train7", "train8",
                       "unseen1", "unseen2"]  # the paper's scenarios (--scenario)
SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        _s("fig2", 15, 20),
        _s("train1", 10, 10),
        _s("train2", 10, 30),
        _s("train3", 15, 20),
        _s("train4", 20, 20),
        _s("train5", 20, 30),
        _s("train6", 25, 20),
        _s("train7", 30, 10),
        _s("train8", 30, 30),
        _s("unseen1", 15, 15),
        _s("unseen2", 25, 25),
    )
}
assert tuple(SCENARIOS) == get_args(ScenarioName)
TRAINING_SCENARIOS: tuple[str, ...] = tuple(f"train{i}" for i in range(1, 9))
UNSEEN_SCENARIOS: tuple[str, ...] = ("unseen1", "unseen2")


def get_scenario(scenario: str | Scenario | Mapping[str, Any] | Sequence[float]) -> Scenario:
    """Resolve a scenario name, a :class:`Scenario`, ``{"name": ..., "start": [x, y, z]}`` (as
    :meth:`Scenario.to_dict` writes it, e.g. in an environment spec) or a start ``[x, y, z]``."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, str):
        if scenario not in SCENARIOS:
            raise ConfigError(f"unknown scenario {scenario!r}; choose one of {sorted(SCENARIOS)}")
        return SCENARIOS[scenario]
    if isinstance(scenario, Mapping) and set(scenario) == {"name", "start"}:
        return Scenario(str(scenario["name"]), tuple(scenario["start"]))
    if isinstance(scenario, (tuple, list)) and len(scenario) == 3:
        return Scenario("custom", tuple(scenario))
    raise ConfigError(f"scenario must be a name, a Scenario or [x, y, z], got {scenario!r}")


def scenario_at(name: str, start: Sequence[float] | None) -> Scenario:
    """The scenario ``name`` starting at ``start``; a named scenario's own start when ``start`` is None.

    Configs that may run in a hall of their own (a layout, :mod:`uavris.layouts`) store the
    scenario's name and its start, so they hold everything the run needs.
    """
    return get_scenario(name) if start is None else Scenario(name, tuple(start))
