"""A job's files carried to a cluster node and back (uavris.experiments.engine.shipping): what
arrives is what was packed, nothing lands outside what the job declared, and what comes back
is the whole truth about the job's writes."""

import io
import os
import tarfile
from pathlib import Path

import pytest

from uavris.experiments.engine.shipping import pack, unpack


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _make(root: Path) -> None:
    (root / "model" / "checkpoints").mkdir(parents=True)
    (root / "model" / "weights.safetensors").write_bytes(bytes(range(256)) * 5)
    (root / "model" / "checkpoints" / "step_10.json").write_text('{"step": 10}')
    (root / "logs").mkdir()


def test_what_arrives_is_what_was_packed(tmp_path):
    stage = tmp_path / "stage"
    _make(stage)
    want = _tree(stage)
    blob = pack([stage / "model", stage / "logs", stage / "absent"])
    for p in sorted(stage.rglob("*"), reverse=True):
        p.rmdir() if p.is_dir() else p.unlink()
    unpack(blob, [stage])
    assert _tree(stage) == want and (stage / "logs").is_dir()


def test_a_file_already_the_same_is_left_alone_and_exact_removes_what_the_job_removed(tmp_path):
    stage = tmp_path / "stage"
    _make(stage)
    blob = pack([stage / "model"])
    same = stage / "model" / "weights.safetensors"
    os.utime(same, (1_000_000, 1_000_000))
    stale = stage / "model" / "checkpoints" / "step_20.json"  # written here, not in the archive
    stale.write_text("{}")
    (stage / "model" / "checkpoints" / "step_10.json").write_text('{"step": 11}')  # changed here
    unpack(blob, [stage / "model"], exact=[stage / "model"])
    assert same.stat().st_mtime == 1_000_000  # not rewritten
    assert not stale.exists() and (stage / "model" / "checkpoints" / "step_10.json").read_text() == '{"step": 10}'


def _hostile(name: str) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        info = tarfile.TarInfo(name)
        info.size = 4
        tar.addfile(info, io.BytesIO(b"evil"))
    return buffer.getvalue()


@pytest.mark.parametrize("where", ["elsewhere/x.txt", "stage/../escape.txt", "stage-2/x.txt"])
def test_nothing_lands_outside_what_the_job_declared(tmp_path, where):
    (tmp_path / "stage").mkdir()
    good = pack([tmp_path / "stage"])  # a valid archive, then one more member outside
    blob = _hostile((tmp_path / where).as_posix().lstrip("/"))
    with tarfile.open(fileobj=io.BytesIO(good)) as a, tarfile.open(fileobj=io.BytesIO(blob)) as b:
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as out:
            for tar in (a, b):
                for m in tar.getmembers():
                    out.addfile(m, tar.extractfile(m) if m.isfile() else None)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    with pytest.raises(ValueError, match="outside what the job declared"):
        unpack(buffer.getvalue(), [tmp_path / "stage"])
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_a_link_in_the_archive_is_refused(tmp_path):
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        info = tarfile.TarInfo((tmp_path / "stage" / "link").as_posix().lstrip("/"))
        info.type, info.linkname = tarfile.SYMTYPE, "/etc/passwd"
        tar.addfile(info)
    with pytest.raises(ValueError, match="not a file or a folder"):
        unpack(buffer.getvalue(), [tmp_path / "stage"])
    assert not (tmp_path / "stage" / "link").exists()


def test_an_unreadable_archive_is_one_error(tmp_path):
    with pytest.raises(ValueError, match="not a readable archive"):
        unpack(b"not a tar archive at all" * 40, [tmp_path])
