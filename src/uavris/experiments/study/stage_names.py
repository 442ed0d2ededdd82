"""The names of a study's stages, each kind named once.

A stage's name is its kind (below) or a kind with a site or a seed in it (the functions below),
with its track's prefix in front (:meth:`.tracks.Track.stage`: ``strong-``, ``deploy-``; none for
the paper's track). The study's one stage outside the tracks is :data:`COMPARE` (paper Fig. 2).
What each stage does: :mod:`.pipeline` and :mod:`.places`; reading a finished one: :mod:`.finished`.
"""

from __future__ import annotations

COMPARE = "compare"  # Fig. 2: the four algorithms over seeds; the paper track's experts are its choice
EXPERTS_TRAIN = "experts-train"  # a track's experts in its training deployments, one run each under runs/SITE
EXPERTS_UNSEEN = "experts-unseen"  # a track's experts trained in its unseen deployments (the references of Fig. 3)
DATASET = "dataset"  # the experts' trajectories, or the planning oracle's demonstrations in the training halls
DATASET_BEST = "dataset-best"  # the best demonstrations by return (filtered behaviour cloning's data)
DATASET_MIXED = "dataset-mixed"  # the mixed-quality demonstrations (the ablation)
VALUE_LABELS = "value-labels"  # the learned value's labels: R at poses of training halls of several counts
PRETRAIN = "pretrain"  # the track's DT (seed 0's; :func:`.tracks.trained_models` names the other models)


def evaluation_stage(site: str) -> str:
    """The stage that evaluates every row of a track in ``site`` (a hall's or a scenario's name)."""
    return f"evaluate-{site}"


def finetune_stage(site: str) -> str:
    """The stage that fine-tunes the DT in ``site`` by the paper's Algorithm 1."""
    return f"finetune-{site}"


def value_stage(seed: int) -> str:
    """The stage that fits the learned value of a pose of pre-training seed ``seed`` (its fit's seed
    the study's plus ``seed``): the places that seed's goal-conditioned DT is told (docs/places.md)."""
    return "value" + (f"-s{seed}" if seed else "")


def places_stage(site: str, seed: int) -> str:
    """The stage that fine-tunes the goal-conditioned DT of pre-training seed ``seed`` in ``site`` by trying places."""
    return f"finetune-places-{site}" + (f"-s{seed}" if seed else "")
