"""The job runner when a worker process dies: the job that killed its
worker is reported failed with its log, the jobs beside it finish with their own results,
and the runner goes on. Jobs are standard-library functions, which every worker (a spawned
process, a Ray worker) can import."""

from __future__ import annotations

import math
import os
import socket
import threading
import time
from pathlib import Path

import pytest

from uavris.experiments.engine.jobs import Job, JobRunner

HANG_S = 120.0  # the six jobs take seconds (worker start-up included)


def _jobs(tmp_path: Path) -> list[Job]:
    return [Job("nap", time.sleep, (2.0,), tmp_path / "nap.log", 5.0),
            Job("dies", os._exit, (3,), tmp_path / "dies.log", 4.0),
            *(Job(f"factorial-{n}", math.factorial, (n,), tmp_path / f"f{n}.log", 1.0) for n in range(3, 7))]


def _check(results, tmp_path: Path) -> None:
    by_name = {r.name: r for r in results}
    assert set(by_name) == {"nap", "dies", "factorial-3", "factorial-4", "factorial-5", "factorial-6"}
    dead = by_name.pop("dies")
    assert not dead.ok and "died" in dead.error and dead.log == tmp_path / "dies.log"
    assert all(r.ok for r in by_name.values()), [(r.name, r.error) for r in by_name.values()]
    assert by_name["nap"].value is None
    assert [by_name[f"factorial-{n}"].value for n in range(3, 7)] == [6, 24, 120, 720]


def test_a_dying_worker_fails_its_own_job_and_no_other(tmp_path: Path):
    """On the local pool a dying worker breaks the pool for every job running in it; before the
    fix the runner then hung for ever (its callback raised, no result ever came)."""
    runner, box = JobRunner(2, "local"), {}
    caller = threading.Thread(target=lambda: box.update(results=runner.run(_jobs(tmp_path))), daemon=True)
    caller.start()
    caller.join(HANG_S)
    assert not caller.is_alive(), f"the runner hung: no result after {HANG_S:.0f} s"
    with runner:
        _check(box["results"], tmp_path)
        [again] = runner.run([Job("after", math.factorial, (5,), tmp_path / "after.log", 1.0)])
        assert again.ok and again.value == 120  # the runner is still usable


def _held_while(path: str) -> None:
    while os.path.exists(path):
        time.sleep(0.05)


def test_an_aborted_runner_stops_the_jobs_its_workers_run(tmp_path: Path):
    """Closing on Ctrl-C or an error stops what the workers run instead of waiting for it: a job
    a worker took between the signal and the close (the sweep's Ctrl-C test on a loaded machine)
    would otherwise run to its end, here never."""
    hold = tmp_path / "hold"
    hold.touch()
    runner, box = JobRunner(2, "local"), {}
    jobs = [Job(f"held-{i}", _held_while, (str(hold),), tmp_path / f"held{i}.log", 1.0) for i in range(2)]
    caller = threading.Thread(target=lambda: box.update(results=runner.run(jobs)), daemon=True)
    caller.start()
    deadline = time.time() + HANG_S
    while not all(log.exists() for log in (j.log for j in jobs)) and time.time() < deadline:  # both started
        time.sleep(0.1)
    closer = threading.Thread(target=runner.close, kwargs={"abort": True}, daemon=True)
    closer.start()
    closer.join(HANG_S)
    try:
        assert not closer.is_alive(), "close(abort=True) waited for jobs that never end"
        caller.join(HANG_S)
        assert not caller.is_alive() and len(box["results"]) == 2 and not any(r.ok for r in box["results"])
    finally:
        hold.unlink()


@pytest.mark.slow
def test_a_dying_ray_worker_fails_its_own_job_and_no_other(tmp_path: Path):
    pytest.importorskip("ray")
    with JobRunner(2, "ray") as runner:
        _check(runner.run(_jobs(tmp_path)), tmp_path)


@pytest.mark.slow
def test_ray_runs_a_job_again_when_its_worker_is_lost_but_not_when_it_fails(tmp_path: Path):
    """A lost worker (a preempted node, here a process that exits) is a system failure that
    Ray retries, and the job resumes; an error of the job itself is its result, run once."""
    pytest.importorskip("ray")
    marker, count = tmp_path / "first-attempt", tmp_path / "attempts"
    # builtins.exec: a function every Ray worker can import
    lost_once = (f"import os, pathlib\np = pathlib.Path({str(marker)!r})\n"
                 "if not p.exists():\n    p.write_text('x')\n    os._exit(3)\n")
    fails = (f"import pathlib\nc = pathlib.Path({str(count)!r})\nc.write_text((c.read_text() if c.exists() else '') "
             "+ 'x')\nraise ValueError('the job itself is wrong')\n")
    with JobRunner(1, "ray") as runner:
        results = {r.name: r for r in runner.run([Job("lost", exec, (lost_once,), tmp_path / "lost.log"),
                                                  Job("fails", exec, (fails,), tmp_path / "fails.log")])}
    assert results["lost"].ok and marker.exists(), results["lost"].error  # the second attempt finished it
    assert not results["fails"].ok and "the job itself is wrong" in results["fails"].error
    assert count.read_text() == "x"  # run once: an application error is not retried


def test_a_cluster_that_does_not_answer_is_one_line_and_nothing_is_written(tmp_path: Path, capsys):
    """Ray itself retries an unreachable address for minutes; uavris says so at once."""
    pytest.importorskip("ray")
    from uavris.cli import main

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "study"
    code = main(["reproduce", "--preset", "smoke", "--backend", "ray", "--ray-address", f"127.0.0.1:{port}",
                 "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1 and f"cannot reach the Ray cluster at 127.0.0.1:{port}" in err
    assert not out.exists()


def test_a_cluster_job_must_say_what_it_writes(tmp_path: Path):
    """On a cluster a job's files travel with it: one that declares none is refused, not lost."""
    pytest.importorskip("ray")
    runner = JobRunner(1, "ray", ray_address="127.0.0.1:1")
    runner._ray_started = True  # as if joined: the check comes before any job leaves
    import ray

    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        with pytest.raises(ValueError, match="declare no files they write"):
            runner.run([Job("silent", print, ("x",), tmp_path / "silent.log")])
    finally:
        runner.close()


def _dies_then_holds(marker: str, hold: str) -> None:
    """Kills its worker the first time; run again (alone), waits while ``hold`` exists."""
    if not os.path.exists(marker):
        Path(marker).touch()
        os._exit(3)
    Path(marker + ".again").touch()
    _held_while(hold)


def test_an_aborted_runner_stops_a_job_rerun_alone(tmp_path: Path):
    """A job whose worker died runs again in a pool of its own, which Ctrl-C may have broken the
    pool for after the signal: closing on abort stops that pool too (before, the command waited
    for the job there; the sweep's Ctrl-C test timed out)."""
    hold, marker = tmp_path / "hold", tmp_path / "died"
    hold.touch()
    runner, box = JobRunner(2, "local"), {}
    jobs = [Job("dies-then-holds", _dies_then_holds, (str(marker), str(hold)), tmp_path / "d.log", 1.0)]
    caller = threading.Thread(target=lambda: box.update(results=runner.run(jobs)), daemon=True)
    caller.start()
    deadline = time.time() + HANG_S
    while not Path(str(marker) + ".again").exists() and time.time() < deadline:  # running alone now
        time.sleep(0.1)
    try:
        assert Path(str(marker) + ".again").exists()
        runner.close(abort=True)
        caller.join(HANG_S)
        assert not caller.is_alive(), "close(abort=True) left the job rerun alone running"
        assert not box["results"][0].ok
    finally:
        hold.unlink()
