"""Deployments (layouts): where the D2D devices are and where the UAV starts.

The paper's study varies only the UAV's start, and every start of it has the same best
pose, so nothing there needs generalising. A layout moves the devices, and with them the
best pose: the setting in which a policy that memorised one deployment fails and one that
generalises pays (docs/study.md, section 2).

Lives here: :class:`Layout` (devices, start and optionally the room, with what it makes of
a base system), :class:`Site` (a resolved layout or a scenario: a system and a start under a
name, where a policy flies), the paper's layout (:data:`PAPER_LAYOUT`), the seeded generator
(:class:`LayoutGenerator`: training and unseen sets disjoint by construction), the layout
distance (:func:`layout_distance`, :func:`nearest_layout`), layout files (:func:`read_layout`,
:func:`write_layout`) and :func:`resolve_layout`, which turns what a user types (``paper``,
a generated name such as ``layout-unseen-3``, or a YAML file) into a layout. Not here: the
checks every layout passes (:class:`uavris.config.SystemConfig` and
:meth:`uavris.config.Scenario.validate_for`, the same for every source), the observation
of the device positions (``SystemConfig.observe_devices``).

A layout file (YAML)::

    name: my-hall            # optional; default: the file's name without .yaml
    room: [40, 40, 8]        # optional; default: the system's (x, y, z in m; a lower
                             # ceiling than the system's z_max caps the flight region,
                             # unless the command line writes --system.z-max)
    devices:                 # required: one [x, y, z] per D2D device, m
      - [15, 5, 1.0]
      - [20, 8, 1.5]
    start: [15, 20, 4.5]     # optional; default: the room's centre at 4.5 m
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from uavris.config import (
    PAPER_USERS,
    SCENARIOS,
    ConfigError,
    DictConfig,
    Scenario,
    SystemConfig,
    Vec3,
    float_tuple,
    scenario_at,
)
from uavris.io import read_yaml, write_yaml

START_HEIGHT = 4.5  # m: the paper's starting altitude (every scenario of its Sec. V)
SPLITS: tuple[str, ...] = ("train", "unseen", "other")
# The "other" split: unseen halls of another generator, so that a result tuned to the study's
# generator shows (docs/study.md, section 2): devices further from the walls and from each other, higher, and
# a start anywhere over the floor instead of its middle half.
OTHER_SPLIT = dict(wall_margin=5.0, spacing=9.0, heights=(0.6, 1.9), start_span=(0.1, 0.9))
# A generated hall's name: its split and index, and its number of devices where that is not
# the default (layout-unseen-3-k6: unseen hall 3 of the generator with 6 devices).
_GENERATED = re.compile(r"layout-(train|unseen|other)-(\d+)(?:-k(\d+))?")
# A hall's name names the files of its results: one plain file-name part, no folder, nothing hidden.
MAX_NAME = 100
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
DEFAULT_DEVICES = 4  # the paper's device count, the generator's default
_FILE_KEYS = {"name", "room", "devices", "users", "start"}


@dataclass(frozen=True)
class Layout:
    """A deployment: the devices (``users``), the UAV's start and, for a hall of its own, the
    room; a generated hall also carries its generator's ``split`` (:data:`SPLITS`)."""

    name: str
    users: tuple[Vec3, ...]
    start: Vec3
    room: Vec3 | None = None  # None: the base system's room
    # set by LayoutGenerator (None: the paper's hall, a user's); where a hall came from, not what it is, so a
    # generated hall written to a file and read back is the same hall
    split: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ConfigError(f"layout name {self.name!r}: letters, digits, '.', '_' and '-' only, starting with a "
                              "letter or digit (it names the files of the hall's results)")
        if len(self.name) > MAX_NAME:  # with a target's name and a key it must fit a file name (255 bytes)
            raise ConfigError(f"layout name {self.name[:40]}... has {len(self.name)} characters; at most {MAX_NAME} "
                              "(it names the files of the hall's results)")
        # Lists from YAML or the CLI become tuples of floats, so a layout is hashable and exact.
        object.__setattr__(self, "users", tuple(float_tuple(u, "Layout", f"users[{k}] (device D{k + 1})",
                                                            "a point [x, y, z] (m)")
                                                for k, u in enumerate(self.users)))
        object.__setattr__(self, "start", float_tuple(self.start, "Layout", "start", "a point [x, y, z] (m)"))
        if self.room is not None:
            object.__setattr__(self, "room", float_tuple(self.room, "Layout", "room", "three lengths [x, y, z] (m)"))

    def system(self, base: SystemConfig) -> SystemConfig:
        """``base`` with this layout's devices (and room), checked whole (:meth:`SystemConfig.check`)."""
        changes: dict[str, Any] = {"users": self.users}
        if self.room is not None:  # a lower hall caps the flight region at its ceiling
            changes.update(room=self.room, z_max=min(base.z_max, self.room[2]))
        return base.replace(**changes)

    @property
    def scenario(self) -> Scenario:
        return Scenario(self.name, self.start)

    def resolve(self, base: SystemConfig) -> tuple[SystemConfig, Scenario]:
        """The system and scenario of this layout on ``base``, both checked (devices inside the
        room, below the UAV's floor and apart; the start in the flight region, outside every
        safety ball); a bad layout raises :class:`ConfigError` naming the layout and the problem."""
        try:
            system = self.system(base)
            scenario = self.scenario
            scenario.validate_for(system)
        except ConfigError as e:
            raise ConfigError(f"layout {self.name!r}: {e}") from None
        return system, scenario

    @property
    def devices(self) -> int:
        """The number of D2D devices."""
        return len(self.users)

    def to_dict(self) -> dict[str, Any]:
        """The layout file's fields (module docstring): what a user's hall is; the split is the generator's."""
        out: dict[str, Any] = {"name": self.name, "devices": [list(u) for u in self.users], "start": list(self.start)}
        if self.room is not None:
            out["room"] = list(self.room)
        return out


PAPER_LAYOUT = Layout("paper", PAPER_USERS, SCENARIOS["fig2"].start)


@dataclass(frozen=True)
class Site(DictConfig):
    """Where a policy flies: a system (the hall and its devices) and the UAV's start, under a
    name: a scenario of the paper's hall (``unseen1``: a start), a generated hall
    (``layout-unseen-3``: devices and start, and the generator's ``split``) or a user's (a
    resolved :class:`Layout`). What a site is (its device count, its split) is read from these
    fields, never from its name."""

    name: str
    system: SystemConfig
    start: Vec3 | None = None  # None: the named scenario's start (uavris.config.SCENARIOS)
    split: str | None = None  # a generated hall's split (SPLITS); None: a scenario, the paper's hall, a user's

    @property
    def scenario(self) -> Scenario:
        return scenario_at(self.name, self.start)

    @property
    def devices(self) -> int:
        """The number of D2D devices in the hall."""
        return self.system.num_users

    @classmethod
    def of(cls, layout: Layout, base: SystemConfig) -> Site:
        """The site of ``layout`` on ``base`` (checked as :meth:`Layout.resolve` checks it)."""
        system, where = layout.resolve(base)
        return cls(layout.name, system, where.start, layout.split)


def default_start(system: SystemConfig, room: Sequence[float] | None = None) -> Vec3:
    """Where a layout without a start begins: above the middle of the floor at :data:`START_HEIGHT`."""
    r = room if room is not None else system.room
    return (float(r[0]) / 2, float(r[1]) / 2, START_HEIGHT)


@dataclass(frozen=True)
class LayoutGenerator:
    """Random halls of ``devices`` D2D devices (docs/study.md, section 2).

    Layout ``j`` of split ``s`` ("train" or "unseen") is drawn from its own random stream,
    keyed by ``(seed, s, j)``: the same layout from the same seed, whatever else is drawn,
    and the two splits never share a stream, so they are disjoint by construction. Devices:
    uniform over the floor at least ``wall_margin`` from the walls, heights uniform in
    ``heights`` (the paper's devices stand 0.1-1.5 m high), each at least the system's
    ``min_device_spacing`` horizontally from the others (rejection sampling). Start: uniform
    over the middle half of the floor (the paper's starts lie in [10, 30]^2 of its 40 m hall)
    at :data:`START_HEIGHT`, redrawn until it keeps the safety distance.
    """

    devices: int = DEFAULT_DEVICES
    heights: tuple[float, float] = (0.0, 1.5)
    wall_margin: float = 2.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.devices, int) or self.devices < 2:
            raise ConfigError(f"LayoutGenerator.devices must be an integer >= 2, got {self.devices!r}")
        lo, hi = (float(h) for h in self.heights)
        if not (np.isfinite([lo, hi]).all() and 0 <= lo <= hi):
            raise ConfigError(f"LayoutGenerator.heights must be 0 <= low <= high, got {self.heights!r}")
        if not (np.isfinite(self.wall_margin) and self.wall_margin >= 0):
            raise ConfigError(f"LayoutGenerator.wall_margin must be a finite distance >= 0, got {self.wall_margin!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"LayoutGenerator.seed must be an integer >= 0, got {self.seed!r}")

    def layout(self, split: str, index: int, base: SystemConfig | None = None) -> Layout:
        """Layout ``index`` of ``split`` in ``base``'s room (default: the paper's system)."""
        if split not in SPLITS:
            raise ConfigError(f"unknown layout split {split!r}; choose one of {', '.join(SPLITS)}")
        if index < 0:
            raise ConfigError(f"layout index must be >= 0, got {index}")
        base = base or SystemConfig()
        rng = np.random.default_rng([self.seed, SPLITS.index(split), index])
        room = np.asarray(base.room)
        other = split == "other"
        margin = OTHER_SPLIT["wall_margin"] if other else self.wall_margin
        heights = OTHER_SPLIT["heights"] if other else self.heights
        spacing = max(base.min_device_spacing, OTHER_SPLIT["spacing"]) if other else base.min_device_spacing
        span = OTHER_SPLIT["start_span"] if other else (0.25, 0.75)
        lo_xy, hi_xy = np.full(2, margin), room[:2] - margin
        top = min(heights[1], np.nextafter(base.z_min, -np.inf))  # devices stay below the UAV's floor
        if np.any(hi_xy <= lo_xy) or top < heights[0]:
            raise ConfigError(f"the room {base.room} leaves no floor for devices with wall_margin {margin} "
                              f"and heights {heights}")
        users = self._devices(rng, lo_xy, hi_xy, (heights[0], top), spacing)
        name = f"layout-{split}-{index}" + (f"-k{self.devices}" if self.devices != DEFAULT_DEVICES else "")
        z = float(np.clip(START_HEIGHT, base.z_min, base.z_max))
        for _ in range(1000):
            start = (*(float(v) for v in rng.uniform(span[0] * room[:2], span[1] * room[:2])), z)
            if min(np.linalg.norm(np.asarray(users) - start, axis=1)) >= base.safety_distance:
                return Layout(name, users, start, split=split)
        raise ConfigError(f"could not place a start outside the safety balls of {name}")

    def _devices(self, rng: np.random.Generator, lo_xy: np.ndarray, hi_xy: np.ndarray, heights: tuple[float, float],
                 spacing: float) -> tuple[Vec3, ...]:
        for _ in range(1000):
            placed: list[np.ndarray] = []
            for _ in range(100 * self.devices):
                xy = rng.uniform(lo_xy, hi_xy)
                if all(np.linalg.norm(xy - p[:2]) >= spacing for p in placed):
                    placed.append(np.array([*xy, rng.uniform(*heights)]))
                    if len(placed) == self.devices:
                        return tuple(tuple(float(c) for c in p) for p in placed)
        raise ConfigError(f"cannot place {self.devices} devices {spacing:g} m apart in this room")

    def layouts(self, split: str, count: int, base: SystemConfig | None = None) -> list[Layout]:
        """Layouts ``0 .. count-1`` of ``split``."""
        return [self.layout(split, j, base) for j in range(count)]


def layout_distance(a: Layout | Sequence[Vec3], b: Layout | Sequence[Vec3]) -> float:
    """Mean distance (m) between the devices of two layouts, matched one to one so that it is
    smallest (Hungarian assignment; the order of the devices means nothing to the physics,
    the pairing being uniform over them). The start is not part of it: it changes the route,
    not where the system is best. Layouts with different device counts are infinitely apart."""
    ua = np.asarray(a.users if isinstance(a, Layout) else a, dtype=np.float64)
    ub = np.asarray(b.users if isinstance(b, Layout) else b, dtype=np.float64)
    if ua.shape != ub.shape:
        return float("inf")
    cost = np.linalg.norm(ua[:, None] - ub[None], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].mean())


def nearest_layout(target: Layout, candidates: Sequence[Layout]) -> Layout:
    """The candidate at the smallest :func:`layout_distance` from ``target`` (ties: the first)."""
    if not candidates:
        raise ConfigError("no layouts to choose the nearest from")
    return min(candidates, key=lambda c: layout_distance(target, c))


# ------------------------------------------------------------------------------------- files
def layout_from_dict(data: Any, where: str, base: SystemConfig | None = None) -> Layout:
    """A layout from a mapping in the file format (module docstring), checked; ``where`` names it in errors."""
    base = base or SystemConfig()
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: a layout is a mapping with devices (and optionally name, room, start), "
                          f"got {type(data).__name__}")
    unknown = sorted(set(data) - _FILE_KEYS)
    if unknown:
        raise ConfigError(f"{where}: unknown layout field(s) {unknown}; known: devices, name, room, start")
    if ("devices" in data) == ("users" in data):
        raise ConfigError(f"{where}: give the device positions as 'devices' (a list of [x, y, z], m)")
    devices = data.get("devices", data.get("users"))
    if not isinstance(devices, list) or not devices:
        raise ConfigError(f"{where}: devices must be a non-empty list of [x, y, z] positions (m), got {devices!r}")
    for k, device in enumerate(devices, 1):  # before any check of where it is: a point has three coordinates
        if not isinstance(device, (list, tuple)) or len(device) != 3:
            raise ConfigError(f"device D{k} of {where}: expected [x, y, z], got {device!r}")
    name = data.get("name") or (re.sub(r"[^A-Za-z0-9._-]+", "_", Path(where).stem).lstrip("._-") or "hall")
    room = data.get("room")
    start = data.get("start")
    if start is None:
        start = default_start(base, room if isinstance(room, (list, tuple)) and len(room) == 3 else None)
    try:
        layout = Layout(name, devices, start, room)
        layout.resolve(base)
    except (ConfigError, TypeError) as e:
        raise ConfigError(f"{where}: {e}") from None
    return layout


def read_layout(path: str | Path, base: SystemConfig | None = None) -> Layout:
    """A layout file (module docstring); any problem is one :class:`ConfigError` line naming the file."""
    return layout_from_dict(read_yaml(Path(path)), str(path), base)


def write_layout(path: str | Path, layout: Layout) -> Path:
    """Write ``layout`` as a layout file (atomically)."""
    write_yaml(Path(path), layout.to_dict())
    return Path(path)


def sets_room(ref: str | Layout) -> bool:
    """Whether the layout ``ref`` names gives a room of its own (a layout file with ``room``), read
    without judging its devices in any room."""
    if isinstance(ref, Layout):
        return ref.room is not None
    if ref == "paper" or _GENERATED.fullmatch(ref):
        return False
    data = read_yaml(Path(ref))
    return isinstance(data, dict) and data.get("room") is not None


def resolve_layout(ref: str | Layout, base: SystemConfig | None = None,
                   generator: LayoutGenerator | None = None) -> Layout:
    """What a user names a layout by: ``paper``, a generated name ``layout-train-N`` /
    ``layout-unseen-N`` (of ``generator``; default the study's generator with as many devices
    as ``base`` has, so that a model of K devices is put in halls of K devices), the same with
    its device count, ``layout-unseen-N-kK`` (K devices whatever ``base`` has), or a YAML
    layout file."""
    if isinstance(ref, Layout):
        ref.resolve(base or SystemConfig())
        return ref
    if ref == "paper":
        return PAPER_LAYOUT
    m = _GENERATED.fullmatch(ref)
    if m:
        count = int(m.group(3)) if m.group(3) else None
        if count is not None and (count < 2 or count == DEFAULT_DEVICES):
            raise ConfigError(f"layout {ref!r}: -kK takes a device count >= 2 other than {DEFAULT_DEVICES} "
                              f"(layout-{m.group(1)}-{m.group(2)} has {DEFAULT_DEVICES})")
        if generator is None:
            own = count or (base.num_users if base is not None else DEFAULT_DEVICES)
            generator = LayoutGenerator(devices=own)
        elif count is not None and count != generator.devices:
            raise ConfigError(f"layout {ref!r} has {count} devices; this generator makes {generator.devices}")
        return generator.layout(m.group(1), int(m.group(2)), base)
    path = Path(ref)
    if path.suffix.lower() in (".yaml", ".yml") or path.exists():
        return read_layout(path, base)
    raise ConfigError(f"unknown layout {ref!r}; give paper, layout-train-N, layout-unseen-N (-kK: K devices) or a "
                      "YAML layout file")
