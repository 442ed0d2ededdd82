"""Are two study outputs the same? Every stage file of ``A/stages`` against ``B/stages``.

Feeds docs/reproducing.md.

Usage: ``python benchmarks/findings/same_bytes.py runs/w1 runs/w2``

The check: the same command with ``--workers 1`` (pinned to one core) and
``--workers 2`` must write the same files. Compared: every file of every stage directory
present in both, byte for byte. Left out, because they record when and how long rather
than what: ``timing.json``, TensorBoard event files (``tb/``, which stamp wall-clock
times) and job logs (``*.log``). A file whose bytes differ is compared by content where
the format records something other than results, with each run's output directory
replaced by ``OUT`` (a stage records the paths of its inputs, which differ by the two runs'
``--out``): a zip (SB3's ``model.zip``) member by member, with the memory addresses SB3
writes into its ``data`` member (``<function ... at 0x7f...>``) masked; a pickle (the
experts' resume state) by its unpickled contents (torch keys pickled storages by object
id); an HDF5 file (Minari's data) dataset by dataset and attribute by attribute; a text
file (JSON, YAML, CSV, markdown) as text. Prints one line
per differing file and the count of identical ones; exits 1 if anything differs.
"""

from __future__ import annotations

import pickle
import re
import sys
import zipfile
from pathlib import Path
from typing import Any

ADDRESS = re.compile(rb" at 0x[0-9a-f]+")

SKIPPED_NAMES = {"timing.json"}
SKIPPED_DIRS = {"tb"}
SKIPPED_SUFFIXES = {".log"}


def _skipped(rel: Path) -> bool:
    return (rel.name in SKIPPED_NAMES or rel.suffix in SKIPPED_SUFFIXES
            or any(part in SKIPPED_DIRS for part in rel.parts))


def _norm(data: bytes, root: Path) -> bytes:
    return ADDRESS.sub(b" at 0x", data.replace(str(root).encode(), b"OUT"))


def _same_zip(a: Path, b: Path, roots: tuple[Path, Path]) -> bool:
    with zipfile.ZipFile(a) as za, zipfile.ZipFile(b) as zb:
        names = sorted(za.namelist())
        return names == sorted(zb.namelist()) and all(
            _norm(za.read(n), roots[0]) == _norm(zb.read(n), roots[1]) for n in names)


def _equal(x: Any, y: Any, roots: tuple[Path, Path]) -> bool:
    import numpy as np
    import torch

    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_equal(x[k], y[k], roots) for k in x)
    if isinstance(x, (list, tuple)) and isinstance(y, (list, tuple)):
        return len(x) == len(y) and all(_equal(u, v, roots) for u, v in zip(x, y))
    if isinstance(x, torch.Tensor) and isinstance(y, torch.Tensor):
        return x.shape == y.shape and x.dtype == y.dtype and bool(torch.equal(x, y))
    if isinstance(x, np.ndarray) and isinstance(y, np.ndarray):
        return x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True)
    if isinstance(x, bytes) and isinstance(y, bytes):
        return _norm(x, roots[0]) == _norm(y, roots[1])
    if isinstance(x, str) and isinstance(y, str):
        return x.replace(str(roots[0]), "OUT") == y.replace(str(roots[1]), "OUT")
    if isinstance(x, float) and isinstance(y, float) and x != x and y != y:
        return True  # NaN
    if type(x) is not type(y):
        return False
    if type(x).__eq__ is object.__eq__ and hasattr(x, "__dict__"):  # a plain object: by its fields
        return _equal(vars(x), vars(y), roots)
    try:
        return bool(x == y)
    except Exception:
        return _equal(vars(x), vars(y), roots) if hasattr(x, "__dict__") else False


def _same_pickle(a: Path, b: Path, roots: tuple[Path, Path]) -> bool:
    try:
        x, y = pickle.loads(a.read_bytes()), pickle.loads(b.read_bytes())
    except Exception:
        return False
    return _equal(x, y, roots)


def _attr_equal(x: Any, y: Any, roots: tuple[Path, Path]) -> bool:
    import numpy as np

    if isinstance(x, (str, bytes)) and isinstance(y, (str, bytes)):
        return _equal(x, y, roots)
    return bool(np.array_equal(x, y))


def _same_hdf5(a: Path, b: Path, roots: tuple[Path, Path]) -> bool:
    import h5py
    import numpy as np

    def items(f: h5py.File) -> dict[str, object]:
        out: dict[str, object] = {}

        def visit(name: str, obj: object) -> None:
            out[name] = obj

        f.visititems(visit)
        return out

    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        ia, ib = items(fa), items(fb)
        if sorted(ia) != sorted(ib) or dict(fa.attrs).keys() != dict(fb.attrs).keys():
            return False
        if any(not _attr_equal(fa.attrs[k], fb.attrs[k], roots) for k in fa.attrs):
            return False
        for name, obj in ia.items():
            other = ib[name]
            if dict(obj.attrs).keys() != dict(other.attrs).keys():
                return False
            if any(not _attr_equal(obj.attrs[k], other.attrs[k], roots) for k in obj.attrs):
                return False
            if isinstance(obj, h5py.Dataset) and not np.array_equal(obj[()], other[()]):
                return False
    return True


TEXT_SUFFIXES = {".json", ".yaml", ".yml", ".csv", ".md"}


def same(a: Path, b: Path, roots: tuple[Path, Path]) -> bool:
    if a.read_bytes() == b.read_bytes():
        return True
    if a.suffix in TEXT_SUFFIXES:
        ta, tb = (p.read_text().replace(str(r), "OUT") for p, r in zip((a, b), roots))
        return ta == tb
    if zipfile.is_zipfile(a) and zipfile.is_zipfile(b):
        return _same_zip(a, b, roots)
    if a.suffix in (".hdf5", ".h5"):
        return _same_hdf5(a, b, roots)
    if a.suffix in (".pkl", ".pickle"):
        return _same_pickle(a, b, roots)
    return False


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("a", type=Path, metavar="OUT_A", help="a study's output directory")
    parser.add_argument("b", type=Path, metavar="OUT_B", help="another, made by the same command")
    args = parser.parse_args(argv)
    return compare(args.a, args.b)


def compare(a_root: Path, b_root: Path) -> int:
    """Print every difference between the stage files of two studies; 1 where any differs."""
    sa, sb = a_root / "stages", b_root / "stages"
    stages_a = {p.name for p in sa.iterdir() if p.is_dir()}
    stages_b = {p.name for p in sb.iterdir() if p.is_dir()}
    bad = 0
    for only, where in ((stages_a - stages_b, a_root), (stages_b - stages_a, b_root)):
        for name in sorted(only):
            print(f"stage {name} only in {where}")
            bad += 1
    identical = 0
    for stage in sorted(stages_a & stages_b):
        files_a = {p.relative_to(sa / stage) for p in (sa / stage).rglob("*") if p.is_file()}
        files_b = {p.relative_to(sb / stage) for p in (sb / stage).rglob("*") if p.is_file()}
        for rel in sorted(files_a ^ files_b):
            if not _skipped(rel):
                print(f"{stage}/{rel}: only in {a_root if rel in files_a else b_root}")
                bad += 1
        for rel in sorted(files_a & files_b):
            if _skipped(rel):
                continue
            if same(sa / stage / rel, sb / stage / rel, (a_root, b_root)):
                identical += 1
            else:
                print(f"{stage}/{rel}: differs")
                bad += 1
    print(f"{len(stages_a & stages_b)} stages, {identical} files identical, {bad} differences "
          f"(left out: {', '.join(sorted(SKIPPED_NAMES))}, {', '.join(sorted(SKIPPED_DIRS))}/, "
          f"*{', *'.join(sorted(SKIPPED_SUFFIXES))})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
