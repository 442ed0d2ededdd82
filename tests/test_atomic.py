"""Atomic writes: readers see the old file or the new one, with ordinary permissions."""

import os
import stat

import pytest

from uavris.errors import UavrisError
from uavris.io import atomic_write_bytes, read_csv
from uavris.runs import prepare


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


def test_readers_name_a_directory_or_non_utf8_file_in_one_error(tmp_path):
    (tmp_path / "bad.csv").write_bytes(b"a,b\n\xff\xfe,1\n")
    with pytest.raises(UavrisError, match="is a directory, not a CSV file"):
        read_csv(tmp_path)
    with pytest.raises(UavrisError, match="is not a CSV file"):
        read_csv(tmp_path / "bad.csv")
    with pytest.raises(UavrisError, match="does not exist"):
        read_csv(tmp_path / "missing.csv")


def test_run_guard_refuses_a_file_in_place_of_the_run_directory(tmp_path):
    path = tmp_path / "run"
    path.write_text("keep me")
    for resume, force in ((False, False), (True, False), (False, True)):
        with pytest.raises(UavrisError, match="exists and is not a directory"):
            prepare(path, {"x": 1}, resume=resume, force=force)
    assert path.read_text() == "keep me"
