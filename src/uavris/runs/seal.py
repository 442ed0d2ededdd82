"""Which pickled files uavris may unpickle: the ones it wrote itself, sealed with a secret of this user.

Lives here: :func:`seal` (write ``FILE.seal``, an HMAC-SHA256 of the file under the key), :func:`mac`,
:func:`is_sealed` and :func:`check_sealed` (the one-line refusal). Not here: what is pickled
(SB3's archives and replay buffer, the resume state: :mod:`uavris.experiments.training.train_expert`)
and the files a user may pass to any command, which are never pickles (safetensors + JSON:
docs/reproducing.md, "Files you may share").

Unpickling runs whatever the file says, so uavris unpickles only to resume a run, and only a
file whose seal matches the key: a file it wrote on a machine that has the key. The key is
``$UAVRIS_SEAL_KEY`` (hex; give every node of a cluster the same one) or, without it, 32
random bytes made on first use in ``$XDG_CONFIG_HOME/uavris/seal.key`` (default
``~/.config/uavris/seal.key``, readable by its owner only). A run copied from a colleague
carries seals of another key: its pickles are refused unless ``--trust-pickle`` says the
user trusts them.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from pathlib import Path

from uavris.errors import CheckpointError
from uavris.io import atomic_write_bytes

SUFFIX = ".seal"
TRUST_FLAG = "--trust-pickle"


MIN_KEY_BYTES = 16  # an HMAC key shorter than this can be guessed; an empty one forges any seal


def _key() -> bytes:
    given = os.environ.get("UAVRIS_SEAL_KEY")
    if given is not None:
        try:
            key = bytes.fromhex(given)
        except ValueError:
            raise CheckpointError("UAVRIS_SEAL_KEY must be hex digits (e.g. python -c 'import secrets; "
                                  "print(secrets.token_hex(32))')") from None
        if len(key) < MIN_KEY_BYTES:
            raise CheckpointError(f"UAVRIS_SEAL_KEY holds {len(key)} bytes; a seal key needs at least "
                                  f"{MIN_KEY_BYTES} (e.g. python -c 'import secrets; print(secrets.token_hex(32))')")
        return key
    home = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    path = home / "uavris" / "seal.key"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path.with_name(f".seal.key.{os.getpid()}"), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(secrets.token_bytes(32))
        try:
            os.link(path.with_name(f".seal.key.{os.getpid()}"), path)  # the first process to make it wins
        except FileExistsError:
            pass
        finally:
            os.unlink(path.with_name(f".seal.key.{os.getpid()}"))
    key = path.read_bytes()
    if len(key) < MIN_KEY_BYTES:
        raise CheckpointError(f"{path} holds {len(key)} bytes; a seal key needs at least {MIN_KEY_BYTES}: "
                              "delete it and uavris makes a new one (seals made under it no longer match)")
    return key


def _digest(path: Path) -> str:
    digest = hmac.new(_key(), digestmod=hashlib.sha256)
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def mac(data: bytes) -> str:
    """The HMAC of ``data`` under this user's key: a mark only this user's uavris can make (a plan
    file's, :mod:`uavris.agents.oracle.store`)."""
    return hmac.new(_key(), data, digestmod=hashlib.sha256).hexdigest()


def seal(path: Path) -> None:
    """Seal ``path`` (a file uavris has just written) as uavris's own."""
    atomic_write_bytes(Path(f"{path}{SUFFIX}"), _digest(Path(path)).encode())


def is_sealed(path: Path) -> bool:
    """Whether ``path`` carries a seal of this key, matching its bytes."""
    mark = Path(f"{path}{SUFFIX}")
    try:
        return mark.is_file() and hmac.compare_digest(mark.read_bytes().strip(), _digest(Path(path)).encode())
    except OSError:
        return False


def check_sealed(path: Path, trust: bool = False) -> None:
    """One line (:class:`CheckpointError`) unless ``path`` is sealed as uavris's own, or ``trust``."""
    if not trust and not is_sealed(path):
        raise CheckpointError(f"{path} is corrupt or a pickle this uavris did not write (no matching seal): "
                              f"unpickling it could run any code; pass {TRUST_FLAG} only if you trust where it "
                              "came from")
