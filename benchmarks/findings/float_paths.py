"""Do the references give the same numbers on both float paths (AVX2, what uavris pins, and a CPU's native AVX-512)?

Feeds docs/timings.md.

(Its section "One float path on every CPU".)

For each unseen hall of the quick study's deployment track (4 devices, layout seed 0), every
reference row its evaluation stage scores, as that stage scores them
(:func:`uavris.experiments.study.workers.evaluate_row`, on the study's episodes
``EVAL_SEED ..``): the zero action, hovering with optimised phases, the oracle (with and
without the attitude safety layer) and the oracle plan of the nearest training hall flown
there. Each hall's scores are written, at full precision, to ``--out/HALL.json``, with the
float path this process took (``UAVRIS_NATIVE_FLOATS`` set: native) and the CPU.

Run it twice on a CPU with AVX-512, once as is and once with ``UAVRIS_NATIVE_FLOATS=1``, then
``--compare A B [REPORT]``: every score of A and B (each such a folder, or a study's folder, whose
deployment evaluation stages hold the same rows) and of the per-layout table of a study's
``report.md`` (printed to 2 decimals) side by side, and whether they agree to the printed digit.

    python benchmarks/findings/float_paths.py --halls 0 1 --out /tmp/pinned
    UAVRIS_NATIVE_FLOATS=1 python benchmarks/findings/float_paths.py --halls 0 1 --out /tmp/native
    python benchmarks/findings/float_paths.py --compare /tmp/pinned /tmp/native runs/quick/report.md
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import uavris  # noqa: E402, F401 - first: it pins the float path before numpy loads


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def measure(halls: list[int], out: Path, episodes: int) -> None:
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.tracks import TRACK_SPECS, track_rows, transfer_sources
    from uavris.experiments.study.workers import evaluate_row

    rc = ReproduceConfig("quick", track="deployment")
    track = TRACK_SPECS["deployment"]
    train, unseen = rc.sites(track)
    out.mkdir(parents=True, exist_ok=True)
    path = "native" if os.environ.get("UAVRIS_NATIVE_FLOATS") else "pinned"
    for j in halls:
        site = unseen[j]
        rows = track_rows(track, site, transfer_sources(track, site, train), {}, [], train)
        with tempfile.TemporaryDirectory() as tmp:
            scores = {r.key: evaluate_row(Path(tmp), site, track, episodes, r)["mean"] for r in rows}
        (out / f"{site.name}.json").write_text(json.dumps(
            {"hall": site.name, "path": path, "cpu": _cpu(), "episodes": episodes, "scores": scores}, indent=1))
        print(site.name, path, {k: f"{v:.4f}" for k, v in scores.items()}, flush=True)


def _study_scores(folder: Path) -> dict[str, dict[str, float]]:
    """A study's deployment evaluations, where they finished: ``{hall: {row: score}}``, at full precision."""
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.tracks import TRACK_SPECS

    study, track = Study.open(folder), TRACK_SPECS["deployment"]
    out = {}
    for w in study.sites(track)[1]:
        found = study.evaluation(track, w.name)
        if found is not None:
            out[w.name] = {k: v["mean"] for k, v in found[1].items()}
    return out


def _report_scores(report: Path) -> dict[str, dict[str, float]]:
    """The per-layout table of a study's report: ``{hall: {label: score}}`` (2 decimals)."""
    lines = report.read_text().splitlines()
    i = next(i for i, line in enumerate(lines) if line.startswith("| layout |"))
    labels = [c.strip() for c in lines[i].strip("|").split("|")][1:]
    out = {}
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[cells[0]] = {lab: float(re.match(r"[-\d.]+", c).group()) for lab, c in zip(labels, cells[1:])}
    return out


# a reference row's key -> its label's start in a report's per-layout table
REPORT_LABELS = {"zero-action": "zero action (hover, level, equal phases)",
                 "hover-optimizer": "hover with the optimiser's phases", "oracle": "oracle (planning)",
                 "oracle-safe": "oracle (planning), safety layer",
                 "transfer": "oracle plan of the nearest training layout, flown here"}


def _measured(folder: Path) -> dict[str, dict]:
    """This script's files in ``folder``, or a study folder's evaluation stages read as such."""
    if (folder / "study.yaml").is_file():
        return {h: {"hall": h, "path": "a study's", "cpu": "its machine", "scores": sc}
                for h, sc in _study_scores(folder).items()}
    return {json.loads(p.read_text())["hall"]: json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))}


def compare(a: Path, b: Path, report: Path | None) -> None:
    left, right = _measured(a), _measured(b)
    printed = _report_scores(report) if report else {}
    halls = [h for h in left if h in right]
    first = left[halls[0]], right[halls[0]]
    print(f"A: {a} ({first[0]['path']}, {first[0]['cpu']}); B: {b} ({first[1]['path']}, {first[1]['cpu']})"
          + (f"; report: {report}" if report else ""))
    print("| hall | row | A | B | A - B | same to 2 decimals" + (" | report | A same as report |" if report else " |"))
    print("|---|---|---:|---:|---:|---|" + ("---:|---|" if report else ""))
    same = differ = same_report = differ_report = 0
    for h in halls:
        for key, x in left[h]["scores"].items():
            y = right[h]["scores"].get(key)
            if y is None:
                continue
            agree = f"{x:.2f}" == f"{y:.2f}"
            same, differ = same + agree, differ + (not agree)
            cells = [h, key, f"{x:.4f}", f"{y:.4f}", f"{x - y:+.2e}", "yes" if agree else "NO"]
            if report:
                kind = "transfer" if key.startswith("transfer-") else key
                row = printed.get(h, {})
                label = REPORT_LABELS[kind] if REPORT_LABELS[kind] in row else None
                if label is None:
                    cells += ["-", "-"]
                else:
                    ok = f"{x:.2f}" == f"{row[label]:.2f}"
                    same_report, differ_report = same_report + ok, differ_report + (not ok)
                    cells += [f"{row[label]:.2f}", "yes" if ok else "NO"]
            print("| " + " | ".join(cells) + " |")
    print(f"\nA and B agree to 2 decimals in {same} of {same + differ} scores"
          + (f"; A and the report in {same_report} of {same_report + differ_report}" if report else ""))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--halls", type=int, nargs="*", default=list(range(16)), help="unseen halls (default 0-15)")
    ap.add_argument("--episodes", type=int, default=32, help="evaluation episodes per row (default 32, the study's)")
    ap.add_argument("--out", type=Path, help="folder of the per-hall JSON files")
    ap.add_argument("--compare", type=Path, nargs="+", metavar="PATH",
                    help="two such folders, and optionally a study's report.md: print them side by side")
    args = ap.parse_args(argv)
    if args.compare:
        if len(args.compare) not in (2, 3):
            ap.error("--compare takes two folders and optionally a report.md")
        compare(args.compare[0], args.compare[1], args.compare[2] if len(args.compare) == 3 else None)
    elif args.out:
        measure(args.halls, args.out, args.episodes)
    else:
        ap.error("give --out (measure) or --compare")


if __name__ == "__main__":
    main()
