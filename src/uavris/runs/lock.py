"""One writer per output: a lock that the operating system holds for the writing process.

Lives here: :func:`locked` (a context manager around the work of one invocation). Two
invocations writing one output (two ``uavris train --out X``, two ``benchmark --out X`` of
different targets) would replace each other's checkpoints and results; the second gets one
line naming the first's process instead. Every command that writes takes it
(:func:`uavris.cli.outputs.writing`). Not here: the run directory's other files
(:mod:`uavris.runs`).

The lock is ``flock`` on ``OUT/.uavris.lock``: the kernel grants it to one open file at a time
and drops it when its process ends however it ends (killed, the machine rebooted), so there is
no stale lock to judge and no window in which a holder that has not yet written its record
looks dead. The record (process, host, start, command) is only what the refusal prints. The
file is removed on release while the lock is still held; a writer that opened the name just
before checks that it locked the file the name still points to. A folder inside the output
that is a symbolic link is refused: what a command writes there would land outside the output.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Iterator

from uavris.errors import UavrisError
from uavris.io import LOCK_FILE


def _read(path: Path) -> dict:
    try:
        held = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return held if isinstance(held, dict) else {}


def _same_file(fd: int, path: Path) -> bool:
    try:
        here, there = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _refusal(d: Path, path: Path) -> UavrisError:
    held = _read(path)
    who = (f"process {held.get('pid')} on {held.get('host')} since {held.get('started')} ({held.get('command')})"
           if held else "another process (it has not yet said which)")
    return UavrisError(f"{d} is being written by {who}; wait for it to end or stop it (the lock goes with "
                       "its process)")


def _refuse_links(d: Path) -> None:
    """One line where a folder inside the output is a symbolic link: what the command writes there
    would land outside the output (and a rerun's ``--force`` could not clear it). The output
    itself may be a link: that is where the user asked for it."""
    for folder, subfolders, _ in os.walk(d):  # links to folders are listed, never entered
        for name in subfolders:
            link = Path(folder) / name
            if link.is_symlink():
                raise UavrisError(f"{link} is a symbolic link (to {os.readlink(link)}); uavris writes only inside "
                                  f"{d}: replace the link by a folder, or give --out the place it points to")


@contextlib.contextmanager
def locked(directory: str | Path, what: str = "", links: bool = False) -> Iterator[Path]:
    """Hold ``directory``'s lock for the block (the directory is made if missing, and removed
    again if the block wrote nothing into it); one line (:class:`UavrisError`) naming the holder
    when another open file holds it, in this process or another, or where a folder inside it is
    a symbolic link (``links=True`` allows them: a folder the command writes files into, not
    below)."""
    d = Path(directory)
    made = not d.exists()
    d.mkdir(parents=True, exist_ok=True)
    path = d / LOCK_FILE
    for _ in range(10):
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)  # a planted link is not followed
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise _refusal(d, path) from None
        if _same_file(fd, path):  # not a file its last holder removed between our open and our lock
            break
        os.close(fd)
    else:
        raise UavrisError(f"{d}: could not take its lock {path}")
    try:
        if not links:
            _refuse_links(d)
        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
              "command": what or " ".join(["uavris", *sys.argv[1:]])[:200]}
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps(me).encode())
        yield d
    finally:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        os.close(fd)
        if made:  # a command refused before it wrote anything leaves no empty folder behind
            with contextlib.suppress(OSError):
                d.rmdir()
