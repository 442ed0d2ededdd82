"""What determines a study: :class:`ReproduceConfig`, dumped into every report.

Lives here: :class:`ReproduceConfig` (the preset, the tracks chosen, their sizes and seeds,
the system) and the choices ``--track`` and ``--expert-algo`` accept. Not here: the stages
it becomes (:mod:`.pipeline`), the tracks themselves (:mod:`.tracks`), the preset tables
(:data:`uavris.presets.STUDY`).
"""

from __future__ import annotations

import dataclasses
from typing import Literal, get_args

from uavris.agents.experts import ALGORITHMS
from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.study.tracks import TRACK_SPECS, TRACKS, Track, sites
from uavris.layouts import Site
from uavris.presets import PRESET, STUDY, Preset, PresetConfig, check_preset, fill_from_preset

# "all": the three tracks; "both": the paper and the strong track (the study before layouts).
TrackChoice = Literal["all", "both", "paper", "strong", "deployment"]
TRACK_CHOICES: tuple[str, ...] = get_args(TrackChoice)
AUTO = "auto"
ExpertAlgo = Literal["auto", "ddpg", "ppo", "sac", "td3"]
TRACK_SETS = {"all": TRACKS, "both": ("paper", "strong")}
MAX_DEVICES = 10  # the learned value is trained on halls of 3-8 devices (10: a count it never saw); the exact
# planner's cost grows fast with the devices (about 30 s a plan at 10 on one core)
SIZE_BOUNDS = {"compare_seeds": 100, "compare_steps": 100_000_000, "eval_episodes": 100_000, "trajectories": 100_000,
               "layout_trajectories": 100_000, "train_layouts": 100_000, "unseen_layouts": 10_000, "dt_seeds": 100,
               "mixed_layouts": 100_000}
assert set(TRACK_CHOICES) == set(TRACK_SETS) | set(TRACKS) and set(get_args(ExpertAlgo)) == {AUTO, *ALGORITHMS}


@dataclasses.dataclass(frozen=True)
class ReproduceConfig(PresetConfig):
    """Everything that determines the study (dumped into the report). Fields left at
    ``PRESET`` take the preset's values (:data:`uavris.presets.STUDY`)."""

    preset: Preset = "quick"  # smoke (seconds, for tests), quick (the time on 2 cores: docs/timings.md) or paper (days)
    seed: int = 0  # seed of every training run (experts, DT); evaluation episodes have their own
    compare_seeds: int = PRESET  # paper track: seeds per algorithm in the comparison
    compare_steps: int = PRESET  # paper track: environment steps per run of the comparison
    eval_episodes: int = PRESET  # evaluation episodes per policy and scenario
    trajectories: int = PRESET  # paper and strong tracks: expert trajectories per training scenario
    track: TrackChoice = "all"  # all, both (paper and strong), paper, strong or deployment
    expert_algo: ExpertAlgo = AUTO  # paper track: auto (the comparison's choice) or one of the four
    train_layouts: int = PRESET  # deployment track: training layouts
    unseen_layouts: int = PRESET  # deployment track: unseen layouts
    layout_trajectories: int = PRESET  # deployment track: the oracle's demonstrations per training layout
    layout_seed: int = 0  # deployment track: seed of the layout generator
    scaling: tuple[int, ...] = PRESET  # deployment track: smaller training sets of the data curve
    dt_seeds: int = PRESET  # deployment track: pre-training seeds of every learned row
    mixed_layouts: int = PRESET  # deployment track: halls of the mixed-quality dataset
    ablation: bool = False  # deployment track: also the ablation's rows (data curve, flat encoder, mixed-quality data)
    device_counts: tuple[int, ...] = ()  # deployment track: also every row zero-shot in unseen halls of these counts
    count_other_layouts: int = 0  # deployment track: also this many halls of another generator per device count
    system: SystemConfig = dataclasses.field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        check_preset(self.preset)
        fill_from_preset(self, STUDY[self.preset])
        if self.track not in TRACK_CHOICES:
            raise UavrisError(f"unknown track {self.track!r}; choose one of {', '.join(TRACK_CHOICES)}")
        if self.expert_algo not in (AUTO,) + ALGORITHMS:
            raise UavrisError(f"unknown expert algorithm {self.expert_algo!r}; choose {AUTO} (the comparison's "
                              f"winner) or one of {', '.join(ALGORITHMS)}")
        for name, top in SIZE_BOUNDS.items():  # a typo's bound: beyond it a run exhausts memory or days
            v = getattr(self, name)
            if not 1 <= v <= top:
                raise UavrisError(f"--{name.replace('_', '-')} must be in [1, {top:,}], got {v}")
        if self.unseen_layouts < 2:
            raise UavrisError(f"--unseen-layouts must be >= 2 (a CI over layouts needs two), got {self.unseen_layouts}")
        for name in ("seed", "layout_seed"):
            if getattr(self, name) < 0:
                raise UavrisError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(self, name)}")
        object.__setattr__(self, "scaling", tuple(int(n) for n in self.scaling))
        counts = tuple(self.device_counts)
        if any(isinstance(k, bool) or not isinstance(k, int) or not 2 <= k <= MAX_DEVICES for k in counts) \
                or len(set(counts)) != len(counts):
            raise UavrisError(f"--device-counts {list(counts)}: distinct device counts in [2, {MAX_DEVICES}]")
        object.__setattr__(self, "device_counts", tuple(sorted(counts)))
        if self.count_other_layouts and not (2 <= self.count_other_layouts <= SIZE_BOUNDS["unseen_layouts"]
                                             and self.device_counts):
            raise UavrisError(f"--count-other-layouts {self.count_other_layouts}: 0, or in [2, "
                              f"{SIZE_BOUNDS['unseen_layouts']:,}] with --device-counts (as --unseen-layouts; "
                              "fewer than 3 halls print no interval and no verdict)")
        bad = [n for n in self.scaling if not 1 <= n < self.train_layouts]
        if bad:
            raise UavrisError(f"--scaling {list(self.scaling)}: each must be >= 1 and below "
                              f"--train-layouts ({self.train_layouts}), got {bad}")

    def trajectories_for(self, track: Track) -> int:
        """Expert trajectories (or the oracle's demonstrations) per training deployment of
        ``track``: a generated hall gets few (many halls, few episodes each: docs/study.md
        section 2), a scenario of the paper's hall many."""
        return self.layout_trajectories if track.layouts else self.trajectories

    @property
    def tracks(self) -> tuple[Track, ...]:
        return tuple(TRACK_SPECS[t] for t in TRACK_SETS.get(self.track, (self.track,)))

    def sites(self, track: Track) -> tuple[list[Site], list[Site]]:
        """The training and unseen sites of ``track``; with the ablation, the unseen ones
        include as many halls of another generator, and as many of each of ``device_counts``
        with ``count_other_layouts`` of another generator at each of those counts (all zero-shot only)."""
        other = self.unseen_layouts if self.ablation and track.ablation and track.layouts else 0
        return sites(track, self.system, self.train_layouts, self.unseen_layouts, self.layout_seed, other,
                     self.device_counts if track.places else (), self.count_other_layouts)
