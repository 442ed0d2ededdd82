"""Counter-based random streams, vectorised over environments.

Each environment owns a 64-bit key; every random number of slot t of episode e is a
hash of (key, e, t, index). A batch of environments therefore draws its randomness in
one numpy call per quantity, and environment i of a batch sees exactly the numbers a
single environment with the same seed sees, whatever the batch size. The mixer is the
SplitMix64 finaliser (Steele, Lea, Flood 2014), which passes BigCrush as a hash of a
counter.

Lives here: :func:`seed_key`, :func:`slot_key`, :func:`mix64`, :func:`raw_bits`,
:func:`uniforms` and :func:`complex_normals`. Not here: what is drawn from them (the NLoS
and pairing draws: :class:`uavris.env.simulator.BatchedSimulator`; the optimiser's starts:
:mod:`.phase_opt`) and the seed bases of each kind of episode (:mod:`uavris.presets`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uavris.errors import ConfigError

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_STREAM = np.uint64(0xD1B54A32D192ED03)
_INV_2_32 = 1.0 / 4294967296.0


def mix64(x: ArrayLike) -> NDArray[np.uint64]:
    """SplitMix64 finaliser: a bijective avalanche hash of uint64 values."""
    z = np.asarray(x, dtype=np.uint64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def seed_key(seed: ArrayLike) -> NDArray[np.uint64]:
    """Key of an environment from a non-negative integer seed."""
    s = np.asarray(seed)
    if np.any(s < 0):
        raise ConfigError(f"seeds must be non-negative integers, got {seed!r}")
    with np.errstate(over="ignore"):
        return mix64(s.astype(np.uint64) + _GOLDEN)


def slot_key(key: ArrayLike, episode: ArrayLike, slot: ArrayLike) -> NDArray[np.uint64]:
    """Key of (environment key, episode index, slot index), shape of the broadcast inputs."""
    with np.errstate(over="ignore"):
        ek = mix64(np.asarray(key, dtype=np.uint64) ^ mix64(np.asarray(episode, dtype=np.uint64) * _STREAM + _GOLDEN))
        return mix64(ek + (np.asarray(slot, dtype=np.uint64) + np.uint64(1)) * _GOLDEN)


def raw_bits(keys: ArrayLike, count: int) -> NDArray[np.uint64]:
    """``count`` hashed 64-bit words per key: shape ``keys.shape + (count,)``."""
    k = np.asarray(keys, dtype=np.uint64)
    with np.errstate(over="ignore"):
        return mix64(k[..., None] + (np.arange(1, count + 1, dtype=np.uint64) * _STREAM))


def uniforms(bits: ArrayLike) -> NDArray[np.float64]:
    """Uniform (0, 1) doubles from the top 53 bits."""
    b = np.asarray(bits, dtype=np.uint64)
    return ((b >> np.uint64(11)).astype(np.float64) + 0.5) * (1.0 / 9007199254740992.0)


def complex_normals(bits: ArrayLike) -> NDArray[np.complex128]:
    """CN(0, 1) samples, one per 64-bit word (Box-Muller on its two 32-bit halves)."""
    b = np.asarray(bits, dtype=np.uint64)
    u1 = ((b >> _S32).astype(np.float64) + 0.5) * _INV_2_32
    # The angle in float32: its SIMD sin/cos are ~10x faster than float64's, and 24 bits
    # of angle are far finer than any statistic of the channel needs.
    angle = ((b & np.uint64(0xFFFFFFFF)).astype(np.float32) + np.float32(0.5)) * np.float32(2.0 * np.pi * _INV_2_32)
    # |w|^2 = -log(u1) is Exp(1), so E|w|^2 = 1: unit variance split over re and im.
    radius = np.sqrt(-np.log(u1))
    out = np.empty(b.shape, dtype=np.complex128)
    out.real = radius * np.cos(angle)
    out.imag = radius * np.sin(angle)
    return out
