import os

import numpy as np
import pytest
from hypothesis import settings

# CI runs a fixed set of examples (reproducible verdicts); locally hypothesis explores anew.
settings.register_profile("ci", derandomize=True, max_examples=200)
if os.environ.get("CI"):
    settings.load_profile("ci")

from uavris.config import SystemConfig


@pytest.fixture
def config() -> SystemConfig:
    return SystemConfig()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def random_cn(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2.0)
