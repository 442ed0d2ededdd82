"""Random D2D link activation (paper Sec. II, docs/model.md section 10).

Lives here: :func:`pairing_from_uniforms` (the simulator's, fed by :mod:`.streams`) and
:func:`sample_pairing`. Not here: the rates of the active pairs (:mod:`.rates`) and the
pairing's probabilities, which the oracles use
(:func:`uavris.agents.oracle.objective.pairing_distribution`,
:func:`uavris.agents.oracle.lookahead.link_activity`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def pairing_from_uniforms(u_count: ArrayLike, u_perm: ArrayLike, max_pairs: int) -> NDArray[np.float64]:
    """Pairing matrix P from uniform draws, batched. Shape ``(..., K, K)``.

    m ~ U{1..max_pairs} from ``u_count`` ``(...)``; a random permutation of the K users
    (argsort of ``u_perm`` ``(..., K)``) gives 2m distinct users, paired as
    (perm[0] -> perm[1]), (perm[2] -> perm[3]), ...; the permutation also randomises each
    pair's direction. P[k, i] = 1 when k transmits to i.
    """
    u_perm = np.asarray(u_perm, dtype=np.float64)
    k = u_perm.shape[-1]
    m = np.minimum((np.asarray(u_count, dtype=np.float64) * max_pairs).astype(np.int64), max_pairs - 1) + 1
    perm = np.argsort(u_perm, axis=-1)
    npairs = k // 2
    tx = perm[..., 0 : 2 * npairs : 2]  # (..., K//2)
    rx = perm[..., 1 : 2 * npairs : 2]
    on = np.arange(npairs) < m[..., None]
    P = np.zeros(u_perm.shape[:-1] + (k, k))
    batch = np.indices(u_perm.shape[:-1])
    idx = tuple(b[..., None] for b in batch)
    P[idx + (tx, rx)] = on
    return P


def sample_pairing(rng: np.random.Generator, num_users: int, max_pairs: int,
                   size: tuple[int, ...] = ()) -> NDArray[np.float64]:
    """Draw pairing matrices with a numpy Generator (convenience for users of the physics API)."""
    return pairing_from_uniforms(rng.random(size), rng.random(size + (num_users,)), max_pairs)
