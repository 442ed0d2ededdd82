"""A job's files, carried to a cluster node that does not share the driver's file system and back.

Lives here: :func:`pack`, :func:`unpack` and :func:`run_shipped`, which the Ray backend of
:class:`~uavris.experiments.engine.jobs.JobRunner` runs on a node when the study goes to a
cluster (``--ray-address``). Not here: what a job reads and writes (each job declares it:
:attr:`~uavris.experiments.engine.worker.Job.reads` and ``writes``).

A job's paths are absolute and the same on every node: the driver packs what the job reads
and what it writes so far (its checkpoints, for a resumed job) into one tar archive, the
node writes those files where the driver has them and runs the job, and the job's writes
(and its log) come back in another archive, which the driver unpacks into its own output
directory. Files the same on both sides are left alone, and each file is replaced
atomically, so a node that does share the driver's file system (the head node of a test
cluster, a cluster with NFS) reads and writes as before. What comes back replaces the
driver's copy of the job's writes exactly: a file the job removed is removed. The driver
accepts only paths inside what the job declared, so a job cannot write elsewhere in the
driver's file system.
"""

from __future__ import annotations

import hashlib
import io
import os
import tarfile
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Iterable, Iterator

from uavris.io import atomic_write_bytes

MANIFEST = ".uavris-manifest"  # the archive's list of every file under the paths it packs


def _files(roots: Iterable[Path]) -> Iterator[tuple[Path, bool]]:
    """Every directory and regular file at or under ``roots`` (path, is a directory), each once."""
    seen: set[Path] = set()
    for root in roots:
        if not root.exists() or root in seen:
            continue
        todo = [root]
        while todo:
            path = todo.pop()
            if path in seen:
                continue
            seen.add(path)
            if path.is_dir() and not path.is_symlink():
                yield path, True
                todo.extend(sorted(path.iterdir(), reverse=True))
            elif path.is_file() and not path.is_symlink():
                yield path, False


def _name(path: Path) -> str:
    return Path(os.path.abspath(path)).as_posix().lstrip("/")


def pack(roots: Iterable[Path]) -> bytes:
    """The directories and files at and under ``roots`` (absolute paths) as an uncompressed tar
    archive, with a manifest of the files it holds."""
    roots = [Path(os.path.abspath(r)) for r in roots]
    buffer = io.BytesIO()
    names = []
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for path, is_dir in _files(roots):
            info = tarfile.TarInfo(_name(path))
            if is_dir:
                info.type, info.mode = tarfile.DIRTYPE, 0o755
                tar.addfile(info)
            else:
                data = path.read_bytes()
                info.size, info.mode = len(data), 0o644
                tar.addfile(info, io.BytesIO(data))
                names.append(info.name)
        listing = "\n".join(names).encode()
        info = tarfile.TarInfo(MANIFEST)
        info.size = len(listing)
        tar.addfile(info, io.BytesIO(listing))
    return buffer.getvalue()


def _inside(name: str, roots: list[PurePosixPath]) -> bool:
    path = PurePosixPath(name)
    return ".." not in path.parts and any(path == r or r in path.parents for r in roots)


def unpack(blob: bytes, allowed: Iterable[Path], exact: Iterable[Path] = ()) -> None:
    """Write the archive ``blob`` of :func:`pack` to its absolute paths, each of which must lie
    at or under one of ``allowed``; a file already there with the same bytes is left alone.
    Under each of ``exact``, files the archive's manifest does not list are removed (the
    archive is the whole truth about them)."""
    roots = [PurePosixPath(_name(Path(a))) for a in allowed]
    try:
        listed = _write(blob, roots)
    except tarfile.TarError as e:
        raise ValueError(f"a job's files are not a readable archive: {e}") from None
    for path, is_dir in list(_files(Path(os.path.abspath(e)) for e in exact)):
        if not is_dir and _name(path) not in listed:
            path.unlink()


def _write(blob: bytes, roots: list[PurePosixPath]) -> set[str]:
    """The archive's files written (the same left alone), once every name in it is checked;
    returns its manifest."""
    listed: set[str] = set()
    with tarfile.open(fileobj=io.BytesIO(blob), mode="r") as tar:
        members = tar.getmembers()
        for member in members:
            if member.name == MANIFEST:
                continue
            if not _inside(member.name, roots):
                raise ValueError(f"a job's files hold {member.name!r}, outside what the job declared")
            if not (member.isdir() or member.isfile()):
                raise ValueError(f"a job's files hold {member.name!r}, which is not a file or a folder")
        for member in members:
            target = Path("/") / member.name
            if member.name == MANIFEST:
                listed = set(tar.extractfile(member).read().decode().split("\n")) - {""}  # type: ignore[union-attr]
            elif member.isdir():
                target.mkdir(parents=True, exist_ok=True)
            else:
                data = tar.extractfile(member).read()  # type: ignore[union-attr]
                if not (target.is_file() and _same(target, data)):
                    target.parent.mkdir(parents=True, exist_ok=True)
                    atomic_write_bytes(target, data)
    return listed


def _same(path: Path, data: bytes) -> bool:
    if path.stat().st_size != len(data):
        return False
    return hashlib.sha256(path.read_bytes()).digest() == hashlib.sha256(data).digest()


def outputs(job: Any) -> tuple[Path, ...]:
    """What comes back from a job (a :class:`~uavris.experiments.engine.worker.Job`): its declared
    writes and its log."""
    return (*job.writes, job.log)


def run_shipped(job: Any, inputs: bytes, run: Callable[[Any], Any]) -> tuple[Any, bytes]:
    """On a cluster node: the job's files from the driver (``inputs``, :func:`pack` of its reads
    and writes), the job (``run(job)``, the job runner's logged call), and its writes packed for
    the driver, whether it succeeded or not (a failed job's log and checkpoints are the
    driver's too)."""
    # the job's own files as the driver has them (a newer checkpoint left here by an attempt the
    # driver never heard of is not resumed beside the driver's older ones)
    unpack(inputs, (*job.reads, *outputs(job)), exact=outputs(job))
    result = run(job)
    return result, pack(outputs(job))


__all__ = ["pack", "unpack", "outputs", "run_shipped"]
