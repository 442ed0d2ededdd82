import numpy as np
import pytest

from uavris.config import SystemConfig


@pytest.fixture
def config() -> SystemConfig:
    return SystemConfig()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def random_cn(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2.0)
