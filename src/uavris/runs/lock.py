"""One writer per output directory: a lock file naming the process that writes it.

Lives here: :func:`locked` (a context manager around the work of one invocation). Two
invocations writing one directory (two ``uavris reproduce --out X`` started together) would
replace each other's checkpoints and results; the second gets one line naming the first's
process instead. A lock left by a process that no longer runs (killed, the machine rebooted)
is taken over. Not here: the run directory's other files (:mod:`uavris.runs`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Iterator

from uavris.errors import UavrisError

LOCK_FILE = ".uavris.lock"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive
        return True
    return True


def _read(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


@contextlib.contextmanager
def locked(directory: str | Path, what: str = "") -> Iterator[Path]:
    """Hold ``directory``'s lock for the block (the directory is made if missing)."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    path = d / LOCK_FILE
    me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
          "command": what or " ".join(["uavris", *sys.argv[1:]])[:200]}
    for _ in range(3):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            held = _read(path)
            if held and held.get("host") == me["host"] and isinstance(held.get("pid"), int) \
                    and not _alive(held["pid"]):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()  # a dead process's lock: taken over
                continue
            if held is None:  # being written this instant, or unreadable: look again
                time.sleep(0.2)
                if _read(path) is None:
                    with contextlib.suppress(FileNotFoundError):
                        path.unlink()
                continue
            raise UavrisError(f"{d} is being written by process {held.get('pid')} on {held.get('host')} since "
                              f"{held.get('started')} ({held.get('command')}); wait for it to end or stop it "
                              f"(the lock of a process that no longer runs is taken over)") from None
        with os.fdopen(fd, "w") as f:
            json.dump(me, f)
        break
    else:
        raise UavrisError(f"{d}: could not take its lock {path}")
    try:
        yield d
    finally:
        if (_read(path) or {}).get("pid") == me["pid"]:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
