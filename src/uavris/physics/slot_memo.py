"""A slot's phases solved once: the compiled multi-pair solver's results kept by their inputs.

Lives here: :class:`SlotMemo`, a mapping from a slot's exact inputs to the phases and sum rate
:func:`uavris.physics.phase_kernel.solve_slots` gave it, with the solver's own signature
(:meth:`SlotMemo.solve`). Not here: the method (:mod:`uavris.physics.phase_opt`, which takes
a memo as an option), who keeps one (:mod:`uavris.agents.oracle.objective`: physics holds
no state of its own).

Why: the value of a pose, ``R`` (docs/model.md, "The oracle"), solves every pairing on every
draw at that pose, and a planner values the same pose many times: its pattern search steps
back onto poses it has valued, its finalists are valued again, the rows of a study that fly
to one place are each assessed there, and the learned planner decides the same place for
every row told it. In a deployment evaluation a quarter of the solved slots were such
repeats. The solver solves each slot on its own, from starts drawn from that slot's own
inputs, so a slot's result does not depend on its batch: a repeat is served the very bits
it would have been given, and every number stays what it was.

The key is a 128-bit BLAKE2 digest of the slot's inputs (every per-slot array, its shape,
and the solver's settings): a collision is as likely as guessing a random 128-bit number.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from uavris.physics.phase_kernel import solve_slots

PER_SLOT = 6  # solve_slots' leading arguments with one row per slot: the links' channels, cosines, starts
OUTPUTS = 2  # its trailing arguments: the phases and sum rates it writes


class SlotMemo:
    """Solutions of :func:`~uavris.physics.phase_kernel.solve_slots` by the digest of their slot's
    inputs, at most ``max_slots`` of them (when full it starts afresh: what a planner repeats,
    it repeats soon). ``hits`` and ``solved`` count the slots served and the slots solved."""

    def __init__(self, max_slots: int = 1 << 17) -> None:
        if max_slots < 1:
            raise ValueError(f"SlotMemo.max_slots must be >= 1, got {max_slots!r}")
        self.max_slots = max_slots
        self.hits = self.solved = 0
        self._phases: dict[bytes, tuple[bytes, float]] = {}  # the phases' float64 bytes, the sum rate

    def __len__(self) -> int:
        return len(self._phases)

    def solve(self, *args: Any) -> None:
        """:func:`~uavris.physics.phase_kernel.solve_slots` with the same arguments: the slots whose
        inputs it has seen are copied from the memo, the others solved (each once) and kept."""
        per_slot, settings = args[:PER_SLOT], args[PER_SLOT:-OUTPUTS]
        out_phi, out_rate = args[-OUTPUTS:]
        m = len(out_rate)
        if m == 0:
            return
        rows = np.concatenate([np.ascontiguousarray(x).reshape(m, -1).view(np.uint8) for x in per_slot], axis=1)
        what = repr(([x.shape[1:] for x in per_slot],
                     [s.tolist() if isinstance(s, np.ndarray) else s for s in settings])).encode()
        keys = [hashlib.blake2b(what + row.tobytes(), digest_size=16).digest() for row in rows]
        known: dict[bytes, tuple[bytes, float]] = {}
        first: dict[bytes, int] = {}  # a slot to solve: where it first appears in this batch
        for i, key in enumerate(keys):
            hit = self._phases.get(key)
            if hit is not None:
                known[key] = hit
            else:
                first.setdefault(key, i)
        if first:
            new = np.fromiter(first.values(), dtype=np.int64, count=len(first))
            phi, rate = np.empty((new.size, out_phi.shape[1])), np.empty(new.size)
            solve_slots(*(np.ascontiguousarray(x[new]) for x in per_slot), *settings, phi, rate)
            if len(self._phases) + new.size > self.max_slots:
                self._phases.clear()
            for j, key in enumerate(first):
                known[key] = (phi[j].tobytes(), float(rate[j]))
                if len(self._phases) < self.max_slots:
                    self._phases[key] = known[key]
            self.solved += new.size
        for i, key in enumerate(keys):
            phases, out_rate[i] = known[key]
            out_phi[i] = np.frombuffer(phases, dtype=np.float64)
        self.hits += m - len(first)
