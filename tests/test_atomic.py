"""Atomic writes: readers see the old file or the new one, with ordinary permissions."""

import os
import stat

import pytest

from uavris.io import atomic_write_bytes


def test_mode_follows_umask_like_open(tmp_path):
    old = os.umask(0o022)
    try:
        ref = tmp_path / "ref.bin"
        ref.write_bytes(b"x")
        atomic_write_bytes(tmp_path / "new.bin", b"y")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.bin").stat().st_mode) == stat.S_IMODE(ref.stat().st_mode)


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "data.bin"
    atomic_write_bytes(path, b"old")

    with pytest.raises(TypeError):
        atomic_write_bytes(path, object())  # type: ignore[arg-type]
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.bin"]
