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

from uavris.experiments.engine.jobs import JobRunner
from uavris.experiments.engine.worker import Job

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


def test_ctrl_c_at_an_idle_worker_leaves_it_quiet_and_working(tmp_path: Path, capfd):
    """Ctrl-C reaches the terminal's whole process group, the workers included; stopping them is
    the command's work (abort). A worker that raised KeyboardInterrupt while it waited for a
    job printed ``Process SpawnProcess-N:`` beside the command's one line (a CI failure of the
    sweep's Ctrl-C test) and broke the pool."""
    import signal

    with JobRunner(2, "local") as runner:
        [first] = runner.run([Job("pid", os.getpid, (), tmp_path / "pid.log", 1.0)])
        assert first.ok and first.value != os.getpid()
        os.kill(first.value, signal.SIGINT)
        time.sleep(1.0)  # time for a worker that did not ignore it to die
        after = runner.run([Job(f"pid-{i}", os.getpid, (), tmp_path / f"pid{i}.log", 1.0) for i in range(4)])
    assert all(r.ok for r in after), [r.error for r in after]
    assert "Process" not in capfd.readouterr().err


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


def test_an_interrupt_in_a_job_the_command_runs_itself_stops_the_command(tmp_path: Path):
    """With one worker the jobs run in the command's own process, where Ctrl-C or SIGTERM lands
    in the job: it stops the command; before, it failed that job and the next one started."""
    second = tmp_path / "second-ran"
    jobs = [Job("interrupted", exec, ("raise KeyboardInterrupt",), tmp_path / "a.log", 2.0),
            Job("next", exec, (f"import pathlib; pathlib.Path({str(second)!r}).touch()",), tmp_path / "b.log", 1.0)]
    with pytest.raises(KeyboardInterrupt), JobRunner(1) as runner:
        runner.run(jobs)
    assert not second.exists()


# A job that records its worker's pid in the folder PIDS and never ends; builtins.exec, so that
# a spawned worker imports nothing of the test's.
HANG = "import os, pathlib, time\npathlib.Path({pids!r}, str(os.getpid())).touch()\nwhile True:\n    time.sleep(0.05)\n"
ENDED_S = 10.0  # a worker whose command is gone: it polls its parent every second


def _hang_jobs(pids: Path) -> str:
    """Python source of the two jobs ``HANG`` (in a driver script)."""
    logs = pids.parent / "logs"
    return (f"[Job(f'hang-{{i}}', exec, ({HANG.format(pids=str(pids))!r},), Path({str(logs)!r}) / f'{{i}}.log') "
            "for i in range(2)]")


def _workers(pids: Path, proc, err: Path, n: int = 2) -> list[int]:
    """The pids of the ``n`` workers running jobs of ``proc`` once all have started."""
    deadline = time.time() + HANG_S
    while len(list(pids.glob("[0-9]*"))) < n and time.time() < deadline and proc.poll() is None:
        time.sleep(0.1)
    found = sorted(int(p.name) for p in pids.glob("[0-9]*"))
    assert len(found) == n, (found, proc.poll(), err.read_text())
    return found


def _appears(folder: Path, pattern: str) -> None:
    """Wait until a file matching ``pattern`` is in ``folder`` (at most HANG_S)."""
    deadline = time.time() + HANG_S
    while not list(folder.glob(pattern)):
        assert time.time() < deadline, f"no {pattern} in {folder} after {HANG_S} s"
        time.sleep(0.01)


def _gone(pid: int) -> bool:
    """True once ``pid`` has ended: no such process, or a zombie (re-parented to an init that
    does not reap it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    return any(line.split()[:2] == ["State:", "Z"] for line in status.splitlines())


def _running_after(pids: list[int], seconds: float) -> list[int]:
    """Those of ``pids`` still running ``seconds`` from now (returns as soon as none is)."""
    deadline = time.time() + seconds
    while any(not _gone(p) for p in pids) and time.time() < deadline:
        time.sleep(0.1)
    return [p for p in pids if not _gone(p)]


def _kill_all(proc, pids: list[int]) -> None:
    """Whatever a failed test left running: the command's process group and its workers."""
    import signal

    for pid in pids:
        if not _gone(pid):
            os.kill(pid, signal.SIGKILL)
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


def _default_signals() -> None:
    """A suite started in the background by a shell (`make test &`) ignores SIGINT, and a child
    inherits that: the command gets Ctrl-C and SIGTERM as a terminal's foreground job has them."""
    import signal

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_DFL)


def _start(args: list[str], err: Path):
    """``args`` in a session of its own (so that a failed test can end its whole group), its
    stderr into ``err``: a file, not a pipe, which workers left running would hold open."""
    import subprocess

    with open(err, "w") as f:
        return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=f, start_new_session=True,
                                preexec_fn=_default_signals)


def _start_hanging(tmp_path: Path, driver: str, **fields: object):
    """The program ``driver`` (its ``{jobs}``: the two ``HANG`` jobs, ``{pids}``: where they record
    their pids) started with :func:`_start`: the pids folder, the stderr file and the process."""
    import sys

    pids = tmp_path / "pids"
    pids.mkdir()
    err = tmp_path / "stderr"
    script = driver.format(jobs=_hang_jobs(pids), pids=str(pids), **fields)
    return pids, err, _start([sys.executable, "-c", script], err)


def test_workers_end_when_their_command_is_killed(tmp_path: Path):
    """A command killed by SIGKILL (or the OOM killer) stops nothing itself; its workers, which
    went on with their jobs into an output whose lock the kill had freed, now end themselves."""
    import signal

    driver = ("from pathlib import Path\nfrom uavris.experiments.engine.jobs import JobRunner\n"
              "from uavris.experiments.engine.worker import Job\n"
              "with JobRunner(2) as runner:\n    runner.run({jobs})\n")
    pids, err, proc = _start_hanging(tmp_path, driver)
    workers = []
    try:
        workers = _workers(pids, proc, err)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        assert not _running_after(workers, ENDED_S), f"workers {workers} outlived their command"
    finally:
        _kill_all(proc, workers)


HELD_POLICY = '''
import os
import pathlib
import time

import numpy as np


def held(obs):
    """Records its worker's pid, then hovers after waiting while {hold!r} exists: a cell that
    cannot end before SIGTERM."""
    pathlib.Path({pids!r}, str(os.getpid())).touch()
    while os.path.exists({hold!r}):
        time.sleep(0.05)
    return np.zeros((obs.shape[0], 6), dtype=np.float32)


held.phase_control = "optimizer"
'''


def test_sigterm_stops_a_sweep_and_its_workers_in_one_line(tmp_path: Path):
    """SIGTERM (``kill``, a batch system at its time limit) reaches the command alone: before,
    it ended at once, printed nothing and left its workers running; now it is Ctrl-C's path,
    with its own line and exit status 143 (128 + SIGTERM)."""
    import signal
    import sys

    pids, hold, out = tmp_path / "pids", tmp_path / "hold", tmp_path / "s"
    pids.mkdir()
    hold.touch()
    (tmp_path / "held.py").write_text(HELD_POLICY.format(pids=str(pids), hold=str(hold)))
    err = tmp_path / "stderr"
    proc, workers = _start([sys.executable, "-m", "uavris", "sweep", str(tmp_path / "held.py") + ":held",
                            "--param", "system.nx", "2,3", "--episodes", "1", "--workers", "2", "--out", str(out),
                            "--no-progress"], err), []
    try:
        workers = _workers(pids, proc, err)  # both cells are running
        os.kill(proc.pid, signal.SIGTERM)  # as `kill` sends it: to the command alone
        assert proc.wait(timeout=HANG_S / 4) == 143, err.read_text()
        assert [x for x in err.read_text().splitlines() if x.strip()] == [
            "uavris: terminated (SIGTERM); rerun the same command to continue (what finished is reused)"], \
            err.read_text()
        assert not _running_after(workers, 1.0), f"workers {workers} outlived their command"
    finally:
        hold.unlink()
        _kill_all(proc, workers)


STUDY = '''
import os
import sys
from concurrent.futures import ThreadPoolExecutor, wait
from pathlib import Path

import uavris.cli as cli
from uavris.experiments.engine.jobs import JobRunner
from uavris.experiments.engine.worker import Job


def gone(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def study(args):
    """As `uavris reproduce` runs its jobs: from a stage's thread, which the main thread waits
    for before it closes the runner (without abort) and then releases the study's lock."""
    runner = JobRunner({workers})
    try:
        with ThreadPoolExecutor(1) as stages:
            wait([stages.submit(runner.run, {jobs})])
    finally:
        runner.close()
        pids = [int(p.name) for p in Path({pids!r}).glob("[0-9]*") if int(p.name) != os.getpid()]
        Path({pids!r}, "closed").write_text(str(all(gone(p) for p in pids)))


cli.command = lambda name: study
sys.exit(cli.main(["reproduce"]))
'''


LIBRARY_STUDY = '''
from pathlib import Path

from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage
from uavris.experiments.engine.worker import Job

ctx = StudyContext({workers}, "local", None)
jobs = {jobs}
stage = Stage("held", {{}}, lambda d, deps: ctx.submit("held", jobs), costs=(1.0, 1.0))
try:
    Pipeline(Path({out!r}), [stage]).run()
except KeyboardInterrupt:
    Path({out!r}, "interrupted").touch()
finally:
    ctx.close()
'''


@pytest.mark.parametrize("workers", [2, 1])
def test_ctrl_c_in_a_program_that_runs_a_study_stops_its_workers(tmp_path: Path, workers: int):
    """A program that calls the library (no uavris command, so no signal handler of ours) gets
    KeyboardInterrupt on Ctrl-C while its stages wait for their jobs: the pipeline stops the
    workers (they ignore SIGINT themselves) instead of waiting for their jobs to end; with one
    worker, the job its stage's thread runs in the program itself."""
    import signal

    pids, err, proc = _start_hanging(tmp_path, LIBRARY_STUDY, out=str(tmp_path), workers=workers)
    seen = []
    try:
        seen = _workers(pids, proc, err, n=workers)
        workers = [p for p in seen if p != proc.pid]
        os.kill(proc.pid, signal.SIGINT)  # the program alone, as a notebook's interrupt sends it
        proc.wait(timeout=HANG_S / 4)
        assert (tmp_path / "interrupted").exists(), err.read_text()
        assert not _running_after(workers, 5.0), f"workers {workers} outlived the interrupt"
    finally:
        _kill_all(proc, [p for p in seen if p != proc.pid])


# A job that records its process's pid, runs until it is interrupted, then marks that its cleanup
# began, cleans up for 1 s of Python and leaves a mark: a second interrupt in its cleanup would cut
# the last mark off.
CLEANED = ("import os, pathlib, time\npathlib.Path({pids!r}, str(os.getpid())).touch()\ntry:\n"
           "    while True:\n        time.sleep(0.05)\nfinally:\n    pathlib.Path({pids!r}, 'cleaning').touch()\n"
           "    t = time.time()\n    while time.time() - t < 1.0:\n        pass\n"
           "    pathlib.Path({pids!r}, 'cleaned').touch()\n")

COMMAND_STUDY = '''
import sys
from pathlib import Path

import uavris.cli as cli
from uavris.experiments.engine.worker import Job
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage


def study(args):
    ctx = StudyContext(1, "local", None)
    job = Job("cleaned", exec, ({job!r},), Path({out!r}) / "cleaned.log")
    stage = Stage("cleaned", {{}}, lambda d, deps: ctx.submit("cleaned", [job]), costs=(1.0,))
    try:
        Pipeline(Path({out!r}), [stage]).run()
    finally:
        ctx.close()


cli.command = lambda name: study
sys.exit(cli.main(["reproduce"]))
'''


def test_sigterm_stops_a_job_the_command_runs_itself_after_its_cleanup(tmp_path: Path):
    """`uavris reproduce --workers 1`: the job runs in its stage's thread; SIGTERM reaches the
    main thread, whose handler and whose pipeline both abort the runner. The job is interrupted,
    its cleanup runs to its end, and the command stops in one line with 143."""
    import signal
    import sys

    pids = tmp_path / "pids"
    pids.mkdir()
    err = tmp_path / "stderr"
    script = COMMAND_STUDY.format(job=CLEANED.format(pids=str(pids)), out=str(tmp_path))
    proc = _start([sys.executable, "-c", script], err)
    try:
        assert _workers(pids, proc, err, n=1) == [proc.pid]
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(timeout=HANG_S / 4) == 143, err.read_text()
        assert (pids / "cleaned").exists(), "a second interrupt cut the job's cleanup short"
        assert err.read_text().strip().startswith("uavris: terminated (SIGTERM)"), err.read_text()
    finally:
        _kill_all(proc, [])


@pytest.mark.parametrize("workers", [2, 1])
@pytest.mark.parametrize("signame, code, line", [("SIGTERM", 143, "terminated (SIGTERM)"),
                                                  ("SIGINT", 130, "interrupted")])
def test_a_signal_stops_the_workers_of_jobs_a_stage_thread_waits_for(tmp_path: Path, signame: str, code: int,
                                                                      line: str, workers: int):
    """A study's main thread waits for its stages' threads, and they for their jobs, before the
    runner is closed: the main thread's unwinding alone would wait for every running job (and,
    on Ctrl-C, start the jobs waiting). The workers are stopped at once instead, and the
    runner's close returns only after they ended (the study's lock is released after it). With
    one worker the job runs in the command's own process, in the stage's thread, which the
    signal does not reach: it is stopped there too (before, `uavris reproduce --workers 1` ran
    its job to the end, minutes, after SIGTERM)."""
    import signal

    pids, err, proc = _start_hanging(tmp_path, STUDY, workers=workers)
    workers_seen = []
    try:
        workers_seen = _workers(pids, proc, err, n=workers)
        if workers == 1:
            assert workers_seen == [proc.pid]  # the job runs in the command itself
            workers_seen = []
        os.kill(proc.pid, getattr(signal, signame))  # the command alone, as `kill` sends it
        assert proc.wait(timeout=HANG_S / 4) == code, err.read_text()
        assert err.read_text().strip() == (f"uavris: {line}; rerun the same command to continue "
                                           "(what finished is reused)"), err.read_text()
        assert (pids / "closed").read_text() == "True"  # the workers had ended when close returned
        assert not _running_after(workers_seen, 1.0)
    finally:
        _kill_all(proc, workers_seen)


def test_a_second_abort_does_not_interrupt_the_jobs_cleanup(tmp_path: Path):
    """Two aborts of one runner (Ctrl-C's handler and the pipeline both close it), the second
    while the in-process job cleans up after the first: the job is interrupted once; before, the
    second abort interrupted its cleanup too."""
    from concurrent.futures import ThreadPoolExecutor

    pids = tmp_path / "pids"
    pids.mkdir()
    runner = JobRunner(1)
    job = Job("cleaned", exec, (CLEANED.format(pids=str(pids)),), tmp_path / "cleaned.log")
    with ThreadPoolExecutor(1) as stage:
        running = stage.submit(runner.run, [job])
        _appears(pids, "[0-9]*")
        runner.close(abort=True)
        _appears(pids, "cleaning")  # the job is in its cleanup now (1 s of Python), whatever the load
        runner.close(abort=True)
        with pytest.raises(KeyboardInterrupt):
            running.result(timeout=HANG_S)
    assert (pids / "cleaned").exists(), "the second abort interrupted the job's cleanup"
