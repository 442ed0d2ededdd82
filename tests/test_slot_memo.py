"""The slot memo (uavris.physics.slot_memo): a slot solved through it gets the bits it gets
without it, in any batch, whether solved there or served; each distinct slot is solved once."""

from __future__ import annotations

import numpy as np
import pytest

from uavris.physics.phase_opt import optimize_phases
from uavris.physics.slot_memo import SlotMemo

K, N, P, NOISE = 4, 16, 0.1, 1e-12


def _slots(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` slots of 4 devices and 16 elements, each with two active links (0 -> 1, 2 -> 3)."""
    rng = np.random.default_rng(seed)
    h = (rng.normal(size=(count, K, N)) + 1j * rng.normal(size=(count, K, N))) * 1e-4
    cos = rng.uniform(0.2, 1.0, size=(count, K))
    pairing = np.zeros((count, K, K))
    pairing[:, 0, 1] = pairing[:, 2, 3] = 1.0
    return h, cos, pairing


def _distinct(h: np.ndarray) -> int:
    return len({row.tobytes() for row in h})


def test_a_slot_gets_the_same_bits_through_the_memo_in_any_batch():
    h, cos, pairing = _slots(6, 0)
    order = np.array([0, 1, 2, 1, 3, 0, 4, 5, 5])  # repeats inside the batch
    plain = optimize_phases(h[order], cos[order], pairing[order], P, NOISE, memo=None)
    memo = SlotMemo()
    first = optimize_phases(h[order], cos[order], pairing[order], P, NOISE, memo=memo)
    assert np.array_equal(first.phases, plain.phases) and np.array_equal(first.sum_rate, plain.sum_rate)
    assert memo.solved == _distinct(h[order]) == 6 and memo.hits == len(order) - 6
    again = np.array([5, 3, 3, 0])  # another batch of slots it has seen: served, none solved
    served = optimize_phases(h[again], cos[again], pairing[again], P, NOISE, memo=memo)
    alone = optimize_phases(h[again], cos[again], pairing[again], P, NOISE, memo=None)
    assert np.array_equal(served.phases, alone.phases) and np.array_equal(served.sum_rate, alone.sum_rate)
    assert memo.solved == 6 and memo.hits == len(order) - 6 + len(again)


def test_the_solver_settings_and_warm_starts_are_part_of_a_slots_key():
    h, cos, pairing = _slots(3, 1)
    memo = SlotMemo()
    optimize_phases(h, cos, pairing, P, NOISE, memo=memo)
    fewer = optimize_phases(h, cos, pairing, P, NOISE, iterations=5, memo=memo)  # other settings: solved anew
    assert memo.solved == 6
    assert np.array_equal(fewer.sum_rate, optimize_phases(h, cos, pairing, P, NOISE, iterations=5, memo=None).sum_rate)
    warm = np.random.default_rng(2).uniform(0, 2 * np.pi, size=(3, N))
    warmed = optimize_phases(h, cos, pairing, P, NOISE, warm=warm, memo=memo)
    assert memo.solved == 9
    assert np.array_equal(warmed.phases, optimize_phases(h, cos, pairing, P, NOISE, warm=warm, memo=None).phases)


def test_a_full_memo_starts_afresh_and_still_gives_the_same_bits():
    h, cos, pairing = _slots(8, 3)
    memo = SlotMemo(max_slots=3)
    for part in (slice(0, 3), slice(3, 6), slice(6, 8), slice(0, 8)):
        got = optimize_phases(h[part], cos[part], pairing[part], P, NOISE, memo=memo)
        assert len(memo) <= 3
        assert np.array_equal(got.phases, optimize_phases(h[part], cos[part], pairing[part], P, NOISE).phases)
    with pytest.raises(ValueError, match="max_slots"):
        SlotMemo(max_slots=0)


def _at_offset(a: np.ndarray, offset: int) -> np.ndarray:
    """A copy of ``a`` whose data starts ``offset`` bytes past a 64-byte boundary."""
    buf = np.empty(a.nbytes + 128, dtype=np.uint8)
    start = (-buf.ctypes.data) % 64 + offset
    out = buf[start:start + a.nbytes].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


@pytest.mark.parametrize("offset", [8, 24, 40])
def test_a_slots_bits_do_not_depend_on_where_its_inputs_lie_in_memory(offset):
    """What the memo rests on, and the study's same numbers in any process: a slot's solution is
    a function of its inputs' values alone, not of their alignment (which differs between
    processes with their allocation history: an alignment-dependent SIMD or BLAS path would give
    other bits there)."""
    h, cos, pairing = _slots(8, 4)
    pairing[::2, 0, 1] = 0.0  # slots of one link and of two
    plain = optimize_phases(h, cos, pairing, P, NOISE, memo=None)
    moved = optimize_phases(*(_at_offset(x, offset) for x in (h, cos, pairing)), P, NOISE, memo=None)
    assert np.array_equal(moved.phases, plain.phases) and np.array_equal(moved.sum_rate, plain.sum_rate)
