"""What made a results page: its stamp, a machine-readable comment at the page's top.

Lives here: :class:`Stamp` (the results format, the oracle's version, the demonstrations'
teacher, the preset, the commit, the machine and float path, the date, the studies read, the
command), :func:`stamp_block` (the comment the page writers put first), :func:`read_stamp`
(the stamp of a page's text, JSON only: reading a page runs nothing) and :func:`stale`
(what makes a stamp older than this code). Not here: the pages themselves (the report,
:mod:`.report`; the claims, :mod:`.claims`; the table of every page and what makes it,
:mod:`.pages`).

A page is current where its stamp's results format, oracle version and teacher are this
code's (:func:`stale` says what differs); a page that is not current is listed as historical,
with the reason, in ``docs/results/historical.yaml`` and says so at its top
(:func:`historical_banner`), which the suite checks.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import uavris
from uavris.agents.oracle.planner import ORACLE_VERSION, TEACHER
from uavris.errors import UavrisError
from uavris.experiments.engine.process import machine
from uavris.float_paths import float_path

STAMP_FORMAT = 1  # the stamp's own fields; raised when they change
OPEN, CLOSE = "<!-- uavris-page", "-->"
_BLOCK = re.compile(r"\A<!-- uavris-page\n(.*?)\n-->\n", re.S)


@dataclass(frozen=True)
class Stamp:
    """What made a page: the code's versions of what moves results, and where and from what it ran."""

    page: str  # the page's name in the table of pages (uavris.experiments.study.pages)
    results_format: int  # the evaluation stages' results format (uavris.experiments.study.workers.RESULTS_FORMAT)
    oracle_version: int  # the oracle's plans and flights (uavris.agents.oracle.planner.ORACLE_VERSION)
    teacher: dict[str, Any]  # the demonstrations' teacher's settings (uavris.agents.oracle.planner.TEACHER)
    preset: str | None  # the studies' preset, None where the page reads none
    commit: str | None  # the git commit of the code that wrote the page ("+dirty": uncommitted changes)
    version: str  # uavris's version
    machine: str  # CPU, CPUs, float path, Python and library versions (engine.process.machine)
    float_path: str  # the float path this process ran (uavris.float_paths.float_path)
    date: str  # the day the page was written (UTC, ISO)
    studies: tuple[str, ...] = ()  # the study directories (or files) the page read
    command: str = ""  # the command that wrote it
    stamp: int = STAMP_FORMAT
    extra: dict[str, Any] = field(default_factory=dict)  # what a page adds (its studies' seeds, say)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["studies"] = list(self.studies)
        return d


def current_versions() -> dict[str, Any]:
    """This code's results format, oracle version and teacher: what a current page's stamp holds."""
    from uavris.experiments.study.workers import RESULTS_FORMAT

    return {"results_format": RESULTS_FORMAT, "oracle_version": ORACLE_VERSION,
            "teacher": dataclasses.asdict(TEACHER)}


PAGES_WRITE = ("docs/results", "docs/figures", "src/uavris/pretrained")  # what `uavris pages` writes


def commit() -> str | None:
    """The git commit of the code running (12 hex digits, "+dirty" with uncommitted changes to
    tracked files other than what the pages write: the pages, their figures and the shipped
    controller), None outside a git checkout."""
    where = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "-C", str(where), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                              text=True, timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no", "--",
                                ":(top)", *(f":(top,exclude){made}" for made in PAGES_WRITE)],
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def make_stamp(page: str, studies: Sequence[str | Path] = (), preset: str | None = None, command: str = "",
               **extra: Any) -> Stamp:
    """The stamp of ``page`` written now by this code, on this machine."""
    return Stamp(page=page, **current_versions(), preset=preset, commit=commit(), version=uavris.__version__,
                 machine=machine(), float_path=float_path(),
                 date=datetime.datetime.now(datetime.timezone.utc).date().isoformat(),
                 studies=tuple(str(s) for s in studies), command=command, extra=dict(extra))


def stamp_block(stamp: Stamp) -> str:
    """The comment a page starts with (ends with a newline): the stamp as indented JSON."""
    return f"{OPEN}\n{json.dumps(stamp.to_dict(), indent=1, sort_keys=True)}\n{CLOSE}\n"


def stamped(stamp: Stamp, text: str) -> str:
    """``text`` (a page, with or without a stamp) with ``stamp`` first."""
    return stamp_block(stamp) + _BLOCK.sub("", text, count=1)


def read_stamp(text: str, where: str = "the page") -> Stamp | None:
    """The stamp at the top of a page's ``text``, None where it has none; one line where it is
    not a stamp this code can read (JSON only: reading a page runs nothing)."""
    m = _BLOCK.match(text)
    if m is None:
        return None
    try:
        data = json.loads(m.group(1))
        data["studies"] = tuple(data.get("studies", ()))
        return Stamp(**data)
    except (ValueError, TypeError) as e:
        raise UavrisError(f"{where}: its stamp is not one uavris writes ({e})") from None


def stale(stamp: Stamp | None) -> list[str]:
    """What makes ``stamp`` older than this code (empty: the page is current): no stamp, or a
    results format, oracle version or teacher that is not this code's."""
    if stamp is None:
        return ["no stamp (made before pages were stamped)"]
    now = current_versions()
    return [f"its {name.replace('_', ' ')} is {getattr(stamp, name)!r}, this code's {now[name]!r}"
            for name in ("results_format", "oracle_version", "teacher") if getattr(stamp, name) != now[name]]


HISTORICAL_FILE = "historical.yaml"  # beside the results pages: page file -> why it is kept though not current


def historical_banner(reason: str) -> str:
    """The line a historical page shows first under its title (the suite checks it)."""
    return f"> **Historical page**: {reason}"


__all__ = ["HISTORICAL_FILE", "STAMP_FORMAT", "Stamp", "commit", "current_versions", "historical_banner",
           "make_stamp", "read_stamp", "stale", "stamp_block", "stamped"]
