"""Layouts: the generator, the layout distance, layout files, and what a bad layout says."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from uavris.config import ConfigError, SystemConfig
from uavris.errors import UavrisError
from uavris.layouts import (
    PAPER_LAYOUT,
    Layout,
    LayoutGenerator,
    layout_distance,
    nearest_layout,
    read_layout,
    resolve_layout,
    write_layout,
)

GEN = LayoutGenerator()


@pytest.mark.parametrize("split", ["train", "unseen"])
def test_generated_layouts_are_valid(split: str) -> None:
    base = SystemConfig()
    for layout in GEN.layouts(split, 40, base):
        system, scenario = layout.resolve(base)  # the checks every layout passes
        users = np.asarray(layout.users)
        assert users.shape == (4, 3)
        assert np.all(users[:, :2] >= GEN.wall_margin) and np.all(users[:, :2] <= 40 - GEN.wall_margin)
        assert np.all((users[:, 2] >= 0.0) & (users[:, 2] <= 1.5))
        for a, b in itertools.combinations(users, 2):
            assert math.dist(a[:2], b[:2]) >= base.min_device_spacing
        assert min(math.dist(scenario.start, u) for u in users) >= base.safety_distance
        assert 10 <= scenario.start[0] <= 30 and 10 <= scenario.start[1] <= 30 and scenario.start[2] == 4.5
        assert system.users == layout.users


def test_generated_layouts_are_reproducible_and_depend_on_the_seed() -> None:
    again = LayoutGenerator()
    assert GEN.layouts("train", 8) == again.layouts("train", 8)
    assert GEN.layout("unseen", 5) == again.layout("unseen", 5)  # layout j does not depend on the others drawn
    other = LayoutGenerator(seed=1)
    assert all(a.users != b.users for a, b in zip(GEN.layouts("train", 8), other.layouts("train", 8)))


def _matched_distance(a: Layout, b: Layout) -> float:
    """Mean device distance under the best one-to-one matching, by trying every matching
    (4! = 24; independent of layout_distance's Hungarian assignment)."""
    ua, ub = np.asarray(a.users), np.asarray(b.users)
    return min(float(np.mean(np.linalg.norm(ua - ub[list(p)], axis=1)))
               for p in itertools.permutations(range(len(ub))))


def test_training_and_unseen_sets_never_share_a_layout() -> None:
    """By the layouts' contents, not their names: no unseen hall has a training hall's devices
    (in any order, nor within half a metre of them on average) or start."""
    train, unseen = GEN.layouts("train", 64), GEN.layouts("unseen", 64)
    halls = {frozenset(t.users) for t in train}
    assert len(halls) == 64 and len({frozenset(u.users) for u in unseen}) == 64
    assert halls.isdisjoint(frozenset(u.users) for u in unseen)
    assert {t.start for t in train}.isdisjoint(u.start for u in unseen)
    assert min(_matched_distance(t, u) for t in train for u in unseen) > 0.5


def test_the_nearest_training_hall_worked_by_hand() -> None:
    """Which training hall's plan is flown in an unseen hall: the one whose devices are nearest
    once matched one to one (the order a hall lists its devices in means nothing; the start
    is not part of it). Unseen: devices at the corners of a 10 m square. Hall C: the same
    devices listed backwards, each 1 m along y (1.0 m); hall A: in order, each 2 m along x
    (2.0 m); hall B: three in place, the fourth 14 m along x and y (14 sqrt(2) / 4 = 4.95 m),
    starting where the unseen hall starts. Pairing devices by index would rank A first,
    the starts B."""
    base = SystemConfig(observe_devices=True)
    square = ((10.0, 10.0, 1.0), (20.0, 10.0, 1.0), (10.0, 20.0, 1.0), (20.0, 20.0, 1.0))
    unseen = Layout("hall-u", square, (15.0, 15.0, 4.5))
    halls = [Layout("hall-a", tuple((x + 2, y, z) for x, y, z in square), (30.0, 30.0, 4.5)),
             Layout("hall-b", (*square[:3], (34.0, 34.0, 1.0)), (15.0, 15.0, 4.5)),
             Layout("hall-c", tuple((x, y + 1, z) for x, y, z in reversed(square)), (25.0, 15.0, 4.5))]
    want = [("hall-c", 1.0), ("hall-a", 2.0), ("hall-b", 14 * math.sqrt(2) / 4)]
    assert nearest_layout(unseen, halls) is halls[2]
    assert [layout_distance(unseen, h) for h in halls] == pytest.approx([2.0, 14 * math.sqrt(2) / 4, 1.0])

    from uavris.experiments.study.tracks import TRACK_SPECS, transfer_sources
    from uavris.layouts import Site

    def deployment(layout: Layout) -> Site:
        return Site.of(layout, base)

    track = TRACK_SPECS["deployment"]  # demonstrations: the nearest training hall's plan only
    train = [deployment(h) for h in halls]
    [(name, dist)] = transfer_sources(track, deployment(unseen), train)
    assert (name, dist) == (want[0][0], pytest.approx(want[0][1]))
    every = transfer_sources(dataclasses.replace(track, demonstrations=False), deployment(unseen), train)
    assert [n for n, _ in every] == [n for n, _ in want]  # experts per layout: all of them, nearest first
    assert [d for _, d in every] == pytest.approx([d for _, d in want])


def test_layout_distance_is_a_matching_distance() -> None:
    a = GEN.layout("train", 0)
    shuffled = Layout("x", tuple(reversed(a.users)), a.start)
    assert layout_distance(a, shuffled) == 0.0  # device order means nothing
    moved = Layout("y", tuple((x + 3.0, y, z) for x, y, z in a.users), a.start)
    assert layout_distance(a, moved) == pytest.approx(3.0)
    b = GEN.layout("train", 1)
    assert layout_distance(a, b) == pytest.approx(layout_distance(b, a))
    assert nearest_layout(moved, [b, a]) is a
    assert layout_distance(a, Layout("k3", a.users[:3], a.start)) == math.inf


def test_layout_files_round_trip_and_names_resolve(tmp_path) -> None:
    layout = GEN.layout("unseen", 3)
    path = write_layout(tmp_path / "hall.yaml", layout)
    assert read_layout(path) == layout
    assert resolve_layout(str(path)) == layout
    assert resolve_layout("layout-unseen-3") == layout
    assert resolve_layout("paper") == PAPER_LAYOUT
    assert PAPER_LAYOUT.resolve(SystemConfig())[0] == SystemConfig()  # the paper's layout is the default system
    (tmp_path / "bare.yaml").write_text("devices: [[5, 5, 1], [30, 30, 1]]\n")
    bare = read_layout(tmp_path / "bare.yaml")
    assert bare.name == "bare" and bare.start == (20.0, 20.0, 4.5) and bare.room is None
    (tmp_path / "room.yaml").write_text("room: [20, 10, 6]\ndevices: [[3, 3, 1], [15, 7, 0.5]]\nstart: [10, 5, 3]\n")
    system, scenario = read_layout(tmp_path / "room.yaml").resolve(SystemConfig())
    assert system.room == (20.0, 10.0, 6.0) and system.z_max == 6.0 and scenario.start == (10.0, 5.0, 3.0)


BAD_LAYOUTS = [
    ("devices: [[50, 5, 1], [20, 20, 1]]", "users[0] (device D1) must be a point inside the room"),
    ("devices: [[10, 10, 1], [12, 10, 1]]", "users[1] (device D2) must be at least min_device_spacing = 5 m"),
    ("devices: [[10, 10, 6], [30, 30, 1]]", "users[0] (device D1) must be below the UAV's floor z_min = 2 m"),
    ("devices: [[20, 20, 1.5], [5, 5, 1]]\nstart: [20, 20, 4]", "start must be at least safety_distance = 3 m"),
    ("devices: [[10, 10, .nan], [30, 30, 1]]", "users[0] (device D1) must be a point inside the room"),
    ("devices: [[10, 10, .inf], [30, 30, 1]]", "users[0] (device D1) must be a point inside the room"),
    ("devices: [[10, 10], [30, 30, 1]]", "device D1 of"),
    ("devices: [[10, 10, 1], [30, 30, 1, 2]]", "device D2 of"),
    ("devices: [[10, 10, x], [30, 30, 1]]", "users[0] (device D1) must be a point [x, y, z]"),
    ("devices: [[true, 10, 1], [30, 30, 1]]", "users[0] (device D1) must be a point [x, y, z]"),  # not 1.0
    ("devices: [[10, 10, 1], [30, 30, 1]]\nstart: [15, \"20\", 4.5]", "start must be a point [x, y, z]"),
    ("devices: []", "devices must be a non-empty list"),
    ("devices: [[10, 10, 1]]", "users must be a list of at least 2 positions"),
    ("name: no devices", "give the device positions as 'devices'"),
    ("devices: [[10, 10, 1], [30, 30, 1]]\nstart: [10, 10]", "start must be three finite coordinates"),
    ("devices: [[10, 10, 1], [30, 30, 1]]\ncolour: red", "unknown layout field(s) ['colour']"),
    ("devices: [[10, 10, 1], [30, 30, 1]]\n  - oops: [", "hall.yaml"),
    ("- just\n- a list", "a layout is a mapping"),
]


@pytest.mark.parametrize("text, message", BAD_LAYOUTS)
def test_a_bad_layout_file_is_one_line_naming_the_problem(tmp_path, text: str, message: str) -> None:
    path = tmp_path / "hall.yaml"
    path.write_text(text)
    with pytest.raises(UavrisError) as e:  # ConfigError, or io's error for a file that does not parse
        read_layout(path)
    assert message in str(e.value) and "\n" not in str(e.value)
    assert str(path) in str(e.value)


def test_unknown_layout_names() -> None:
    with pytest.raises(ConfigError, match="unknown layout 'nowhere'"):
        resolve_layout("nowhere")
    with pytest.raises(UavrisError, match="missing.yaml does not exist"):
        resolve_layout("missing.yaml")


def test_a_generated_name_may_carry_its_device_count() -> None:
    """layout-unseen-N-kK is hall N of the generator with K devices, whatever the base system
    has; a base of K devices makes the plain name the same hall (named with its K); the
    default count keeps the plain name; a count that names nothing new is one line."""
    six = resolve_layout("layout-unseen-3-k6")
    assert six.name == "layout-unseen-3-k6" and len(six.users) == 6
    assert six == LayoutGenerator(devices=6).layout("unseen", 3)
    base6 = SystemConfig(users=six.users)
    assert resolve_layout("layout-unseen-3", base6) == six
    assert resolve_layout("layout-unseen-3-k6", SystemConfig()) == six  # the name's count wins over the base's
    four = resolve_layout("layout-unseen-3")
    assert four.name == "layout-unseen-3" and len(four.users) == 4
    system, _ = six.resolve(SystemConfig())
    assert system.num_users == 6
    for bad, says in (("layout-unseen-3-k4", "other than 4"), ("layout-unseen-3-k1", ">= 2")):
        with pytest.raises(ConfigError, match=says):
            resolve_layout(bad)
    with pytest.raises(ConfigError, match="has 6 devices; this generator makes 5"):
        resolve_layout("layout-unseen-3-k6", generator=LayoutGenerator(devices=5))


def test_the_oracle_plan_moves_with_the_layout() -> None:
    """Two hand-made halls, one mirrored into the other's opposite corner: in each, two devices
    stand 6 m apart and two far from them and from each other. The double path loss makes the
    best hovering place the one close to the near pair (3 m from each: the safety distance),
    so the plan must go there, and the two plans must be a hall apart."""
    from uavris.agents.oracle import plan_target

    near_pair = [(6.0, 8.0, 1.0), (12.0, 8.0, 1.0)]
    far = [(34.0, 36.0, 0.5), (34.0, 20.0, 0.5)]
    sw = Layout("sw", tuple(near_pair + far), (20.0, 20.0, 4.5))
    ne = Layout("ne", tuple((40 - x, 40 - y, z) for x, y, z in near_pair + far), (20.0, 20.0, 4.5))
    targets = []
    for layout in (sw, ne):
        system, scenario = layout.resolve(SystemConfig())
        plan = plan_target(system, scenario.start)
        mid = np.mean(np.asarray(layout.users[:2]), axis=0)
        assert np.linalg.norm(plan.target[:2] - mid[:2]) < 3.0, (layout.name, plan.target)
        targets.append(plan.target)
    assert np.linalg.norm(targets[0] - targets[1]) > 25.0


def test_a_generated_name_gives_a_hall_of_the_systems_own_number_of_devices():
    """A model of 6 devices evaluated in layout-unseen-0 gets a hall of 6 devices, the one the
    generator of 6 devices draws; the paper's system gets the study's 4-device hall."""
    from uavris.layouts import LayoutGenerator, resolve_layout

    six = SystemConfig(users=tuple((5.0 + 5.0 * k, 5.0 + 6.0 * k, 1.0) for k in range(6)))
    hall = resolve_layout("layout-unseen-0", six)
    assert len(hall.users) == 6 and hall.users == LayoutGenerator(devices=6).layout("unseen", 0, six).users
    assert resolve_layout("layout-unseen-0", SystemConfig()).users == LayoutGenerator().layout("unseen", 0).users
