"""Same bits on any machine: the phase optimiser's compiled kernels give the same result
whatever CPU numba compiles them for. Two fresh processes, one with the kernel numba compiled for
this machine's CPU and one compiling it afresh for a generic x86-64 (no AVX, no FMA); the phases and sum rates of
the same slots must agree bit for bit. (With fast-math, reassociated sums and fused multiply-adds
made them differ: in 1,597 of 4,352 values of 256 slots, by up to 7.6 bps/Hz in a slot.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from uavris.float_paths import PINNED, _has_flag

SCRIPT = """
import sys
import numpy as np
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.physics.phase_opt import optimize_slot_phases

c = SystemConfig()
n = 96
sim = BatchedSimulator(c.replace(safety_distance=0.0), "fig2", n)
sim.seed(np.arange(n))
sim.reset()
rng = np.random.default_rng(0)
sim.place(np.c_[rng.uniform(0, 40, (n, 2)), rng.uniform(c.z_min, c.z_max, n)], rng.uniform(-0.4, 0.4, (n, 3)))
sol = optimize_slot_phases(c, sim.channels, sim.cos_theta, sim.pairing)
warm = optimize_slot_phases(c, sim.channels, sim.cos_theta, sim.pairing, warm=np.roll(sol.phases, 1, axis=0))
np.save(sys.argv[1], np.concatenate([sol.phases.ravel(), sol.sum_rate, warm.phases.ravel(), warm.sum_rate]))
"""


@pytest.mark.slow
def test_the_optimiser_gives_the_same_bits_compiled_for_the_host_and_for_a_generic_cpu(tmp_path: Path):
    results = {}
    for cpu in ("host", "generic"):
        # the host's kernel from numba's own cache (compiled by `make` for this CPU, or here if it is not);
        # the generic one compiled afresh into a cache of its own (numba keys its cache by the CPU as well)
        env = dict(os.environ)
        env.pop("NUMBA_CPU_NAME", None)
        env.pop("NUMBA_CPU_FEATURES", None)
        if cpu == "generic":
            env.update(NUMBA_CPU_NAME="generic", NUMBA_CACHE_DIR=str(tmp_path / "cache-generic"))
        out = tmp_path / f"{cpu}.npy"
        proc = subprocess.run([sys.executable, "-c", SCRIPT, str(out)], env=env, capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        results[cpu] = np.load(out)
    assert results["host"].size == 2 * (96 * 16 + 96)
    assert np.all(np.isfinite(results["host"]))
    assert results["host"].tobytes() == results["generic"].tobytes()


PATHS = """
import os, json, sys
import uavris  # first: it pins the float path before numpy and torch load
import numpy, threadpoolctl, torch
from numpy._core._multiarray_umath import __cpu_dispatch__ as targets, __cpu_features__ as features
blas = sorted({i.get("architecture") for i in threadpoolctl.threadpool_info() if i.get("internal_api") == "openblas"})
# the kernels numpy may dispatch to on this CPU: its dispatch targets still enabled (a CPU feature that is no
# target, such as numpy 2.4's AVX512VNNI beside its X86_V4 level, is reported as the CPU's and chooses no kernel)
from uavris.float_paths import float_path
print(json.dumps({"avx512": sorted(k for k in targets if features.get(k) and ("AVX512" in k or k == "X86_V4")),
                  "blas": blas, "torch": torch.backends.cpu.get_cpu_capability(), "path": float_path(),
                  "set": {k: os.environ.get(k) for k in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE",
                                                        "MKL_CBWR")}}))
"""


def _paths(env: dict[str, str]) -> dict:
    import json

    clean = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE",
                                                               "MKL_CBWR", "MKL_ENABLE_INSTRUCTIONS",
                                                               "ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY")}
    out = subprocess.run([sys.executable, "-c", PATHS], env={**clean, **env}, capture_output=True, text=True,
                         check=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the pinned path is x86-64's AVX2")
def test_import_uavris_pins_every_library_to_the_avx2_path() -> None:
    """numpy without its AVX-512 kernels, OpenBLAS on its Haswell (AVX2) kernels and torch at AVX2,
    whatever the CPU (an Intel Xeon's AVX-512 rounded the oracle's plan otherwise); unchanged where
    the user chose (UAVRIS_NATIVE_FLOATS, or a variable already set)."""
    pinned = _paths({})
    assert pinned["avx512"] == [] and pinned["blas"] == ["Haswell"] and pinned["torch"] in ("AVX2", "DEFAULT")
    assert pinned["set"]["OPENBLAS_CORETYPE"] == "Haswell" and pinned["set"]["MKL_CBWR"] == "AVX2"
    # what a report's machine line says of it (uavris.float_paths.float_path), read from the libraries
    assert pinned["path"] == "the AVX2 path" + (" (its AVX-512 switched off)" if _has_flag("avx512f") else "")
    assert {"X86_V4", "AVX512F"} & set(pinned["set"]["NPY_DISABLE_CPU_FEATURES"].split())
    native = _paths({"UAVRIS_NATIVE_FLOATS": "1"})
    assert native["set"] == {"NPY_DISABLE_CPU_FEATURES": None, "OPENBLAS_CORETYPE": None, "MKL_CBWR": None}
    if _has_flag("avx512f"):  # the checks above see AVX-512 kernels where they are not switched off
        assert native["avx512"] != [] and native["path"].startswith("native kernels (numpy AVX-512")
    nehalem = _paths({"OPENBLAS_CORETYPE": "Nehalem"})
    assert nehalem["blas"] == ["Nehalem"]  # the user's choice is kept, and said
    assert nehalem["path"].startswith("native kernels (") and "OpenBLAS Nehalem" in nehalem["path"]


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the pinned path is x86-64's AVX2")
def test_a_process_that_loaded_numpy_first_and_its_workers_take_one_path(tmp_path: Path) -> None:
    """numpy imported before uavris cannot be pinned any more; the workers it starts must then keep
    their native path too, or a row evaluated in the process and the same row evaluated in a worker
    differ in the last digits on a CPU with AVX-512 (they did, in CI). And this suite's own process
    is pinned like its workers (tests/conftest.py imports uavris first)."""
    script = (
        "import json, subprocess, sys\n"
        "import numpy\n"
        "import warnings\n"
        "with warnings.catch_warnings():\n"
        "    warnings.simplefilter('ignore')\n"
        "    import uavris\n"
        "child = subprocess.run([sys.executable, '-c', 'import os, uavris; "
        "print(os.environ.get(\"NPY_DISABLE_CPU_FEATURES\"))'], capture_output=True, text=True, check=True)\n"
        "print(json.dumps(child.stdout.strip()))\n"
    )
    clean = {k: v for k, v in os.environ.items()
             if k not in ("NPY_DISABLE_CPU_FEATURES", "UAVRIS_NATIVE_FLOATS", *PINNED)}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=clean, check=True,
                         timeout=120)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == "None"  # the worker kept the native path, as its parent
    if "avx2" in Path("/proc/cpuinfo").read_text() and not os.environ.get("UAVRIS_NATIVE_FLOATS"):
        assert os.environ.get("NPY_DISABLE_CPU_FEATURES")  # this process: pinned, like the workers it starts


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the pinned path is x86-64's AVX2")
def test_importing_numpy_first_is_quiet_and_said_where_a_result_is_made_to_be_compared(tmp_path: Path) -> None:
    """A Gymnasium user imports numpy before uavris: the import says nothing; status() names the
    native path and why; a result meant for comparison (here the call reproduce, benchmark and
    claims make first) warns once on a CPU with AVX-512, and on one without says nothing."""
    script = ("import warnings\nwarnings.simplefilter('always')\nimport numpy\nimport uavris\n"
              "from uavris import float_paths\nprint(float_paths.status())\n"
              "float_paths.warn_if_unpinned('benchmark')\nfloat_paths.warn_if_unpinned('benchmark')\n")
    clean = {k: v for k, v in os.environ.items()
             if k not in ("NPY_DISABLE_CPU_FEATURES", "UAVRIS_NATIVE_FLOATS", *PINNED)}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=clean, check=True,
                         timeout=120)
    assert "imported before uavris" in out.stdout
    warned = [line for line in out.stderr.splitlines() if "UserWarning" in line]
    if _has_flag("avx512f"):
        assert len(warned) == 1 and "uavris: benchmark runs on this CPU's AVX-512 kernels" in warned[0]
        assert out.stderr.count("UserWarning") == 1
    else:
        assert out.stderr == ""
    first = subprocess.run([sys.executable, "-c", script.replace("import numpy\nimport uavris", "import uavris\n"
                                                                 "import numpy")],
                           capture_output=True, text=True, env=clean, check=True, timeout=120)
    assert first.stderr == "" and "imported before" not in first.stdout  # uavris first: pinned, quiet


def test_the_warning_points_at_the_users_line_and_comes_once(monkeypatch, tmp_path: Path) -> None:
    """In a process that is not pinned, on a CPU with AVX-512 (both made so here, whatever this CPU
    is), reproduce called from a user's script warns once, at the user's line, not inside uavris;
    a process the user pinned (the AVX2 path) is not warned."""
    from uavris import float_paths
    from uavris.errors import UavrisError
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.reproduce import reproduce

    monkeypatch.setattr(float_paths, "_LATE", True)
    monkeypatch.setattr(float_paths, "_WARNED", set())
    monkeypatch.setattr(float_paths, "_has_flag", lambda flag: True)
    monkeypatch.setattr(float_paths, "float_path", lambda: "native kernels (numpy AVX-512)")
    for time in range(2):
        with warnings.catch_warnings(record=True) as caught, pytest.raises(UavrisError):
            warnings.simplefilter("always")
            reproduce(ReproduceConfig("smoke"), tmp_path, workers=0)  # warned, then refused
        ours = [w for w in caught if "AVX-512" in str(w.message)]
        if time == 0:
            [w] = ours
            assert w.filename == __file__ and "uavris: reproduce runs on this CPU's AVX-512 kernels" in str(w.message)
        else:
            assert ours == []  # once a process
    assert "imported before uavris" in float_paths.status()
    monkeypatch.setattr(float_paths, "_WARNED", set())
    monkeypatch.setattr(float_paths, "float_path", lambda: "the AVX2 path (its AVX-512 switched off)")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        float_paths.warn_if_unpinned("reproduce")  # pinned by the user's environment: nothing to say


def test_a_report_names_the_cpu_and_the_float_path_it_ran() -> None:
    """The machine line of a report (uavris.experiments.engine.process.machine) tells apart two CPUs of one
    name (an AMD EPYC of family 25 and one of family 26 both call themselves "AMD EPYC") by their family and
    model numbers, and says whether the libraries ran the pinned AVX2 path or their native kernels."""
    from uavris.experiments.engine.process import machine
    from uavris.float_paths import float_path

    info = Path("/proc/cpuinfo").read_text(encoding="utf-8") if Path("/proc/cpuinfo").exists() else ""
    first = dict(line.split(":", 1) for line in info.split("\n\n")[0].splitlines() if ":" in line)
    first = {k.strip(): v.strip() for k, v in first.items()}
    line = machine()
    if "cpu family" in first:
        assert f"(family {first['cpu family']}, model {first['model']})" in line
    assert float_path() in line  # the path itself: test_import_uavris_pins_every_library_to_the_avx2_path
