# isort: off
import uavris  # noqa: F401 - first: it pins the float path before numpy loads, as in every worker (float_paths)
# isort: on
import contextlib
import os
import shutil
import tempfile
from typing import Iterator

import numpy as np
import pytest
from hypothesis import settings

# CI runs a fixed set of examples (reproducible verdicts); locally hypothesis explores anew.
settings.register_profile("ci", derandomize=True, max_examples=200)
if os.environ.get("CI"):
    settings.load_profile("ci")

from uavris.agents.oracle.planner import PlanSettings  # noqa: E402
from uavris.agents.oracle.store import STORE_ENV  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402 - after the hypothesis profile is registered
from uavris.experiments.engine.process import configure_threads  # noqa: E402

configure_threads()  # one thread per test process, as in every worker and the command line (engine.process)
# The seal of uavris's own pickles (uavris.runs.seal): one key for the tests and every process they start,
# none written to the user's home (test_seal_key_is_made_once_and_kept_private tests the key file).
os.environ.setdefault("UAVRIS_SEAL_KEY", "5eed" * 16)
# One plan store for the run (uavris.agents.oracle.store), made by the first process (xdist's controller,
# before it starts its workers) and inherited by every process the tests start: a hall that several
# files' studies and tests plan is planned once. Fresh each run, so every plan is made by this code.
_RUN_STORE = None
if "PYTEST_XDIST_WORKER" not in os.environ and STORE_ENV not in os.environ:
    os.environ[STORE_ENV] = _RUN_STORE = tempfile.mkdtemp(prefix="uavris-test-plans-")

# Decision Transformer tests: short episodes keep rollouts cheap; the layout does not depend on T.
SHORT = SystemConfig(horizon=16)
# The smoke studies' system (tests/test_reproduce.py, tests/test_deployment_track.py): their stages,
# rows and report are the same at any horizon, and an evaluation's time is per slot. The energy
# budget is scaled with the horizon (hovering costs about 84 J a slot), so that episodes still end on
# it before the horizon, as at 100 slots and 8,000 J.
SMOKE_SYSTEM = SystemConfig(horizon=25, energy_budget_j=2000.0)
# A planner that looks little (one screened candidate, no refinement, two checking batches): for tests of
# how plans are shared and stored, which are the same for any plan.
GLANCE = PlanSettings(global_step=0.0, candidates=1, refine_from=1, max_refinements=0, check_batches=2, nlos_draws=1,
                      front_margin_deg=None)


# The files that run whole smoke studies take most of the suite's time: under `make test`
# (`-n 2 --dist loadfile --no-loadscope-reorder`) they start first, one on each worker, and the
# other files fill in around them (by default xdist starts the files with the most tests first).
STUDIES_FIRST = ("test_reproduce.py", "test_deployment_track.py")


def pytest_unconfigure(config: pytest.Config) -> None:
    if _RUN_STORE is not None:  # the process that made it
        shutil.rmtree(_RUN_STORE, ignore_errors=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: item.path.name not in STUDIES_FIRST)  # stable: each file's own order kept


@pytest.fixture
def config() -> SystemConfig:
    return SystemConfig()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def random_cn(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2.0)


@pytest.fixture(scope="module")
def expert_trajectories():
    """Two cheap "experts" (baselines) in two scenarios, 3 episodes each (DT tests)."""
    from uavris.agents.dt.trajectories import record_episodes
    from uavris.agents.references import reference_policy

    a = record_episodes(reference_policy("hover-aligned", SHORT), SHORT, "train1", [10, 11, 12], expert="hover",
                        expert_algo="b")
    b = record_episodes(reference_policy("hover-random-phases", SHORT), SHORT, "train2", [20, 21, 22], expert="rand",
                        expert_algo="b")
    return a + b


@pytest.fixture(scope="module")
def dataset_dir(expert_trajectories, tmp_path_factory):
    from uavris.agents.dt.dataset import write_dataset

    return write_dataset(tmp_path_factory.mktemp("ds") / "experts-v0", expert_trajectories, SHORT)


def keep_figures(monkeypatch: pytest.MonkeyPatch, *modules: object) -> list:
    """Figures that ``modules`` would save (their ``save_figure``), drawn and kept instead of
    written: a test reads their artists."""
    kept: list = []

    def keep(fig, stem):
        fig.canvas.draw()
        kept.append(fig)
        return []

    for module in modules:
        monkeypatch.setattr(module, "save_figure", keep, raising=False)
    return kept


@contextlib.contextmanager
def killed_after_round(monkeypatch: pytest.MonkeyPatch, last: int) -> Iterator[None]:
    """Fine-tuning (:func:`uavris.experiments.training.finetune.finetune`) stopped by a
    KeyboardInterrupt as soon as round ``last``'s checkpoint is written, as a kill then would."""
    from uavris.experiments.training import finetune as module

    real = module.write_checkpoint

    def write_then_stop(run_dir, index, *args, **kwargs):
        path = real(run_dir, index, *args, **kwargs)
        if index >= last:
            raise KeyboardInterrupt(f"killed after round {index}")
        return path

    with monkeypatch.context() as m:
        m.setattr(module, "write_checkpoint", write_then_stop)
        yield
