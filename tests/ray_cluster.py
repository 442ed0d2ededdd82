"""A two-node Ray cluster on loopback whose second node sees its own, empty file system at one
folder (``unshare -m`` and a tmpfs over it: needs root), for the tests of a study on a cluster
without a shared file system. Never ``ray stop``: it would stop every Ray instance on the
machine, other tests' included; the cluster's processes are killed by session and namespace."""

from __future__ import annotations

import contextlib
import os
import secrets
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator

RAY = str(Path(sys.executable).with_name("ray"))


def can_unshare() -> str | None:
    """Why a node with a file system of its own cannot be made here (None when it can)."""
    if sys.platform != "linux":
        return "needs Linux mount namespaces"
    try:
        done = subprocess.run(["unshare", "-m", "true"], capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"unshare is not available ({e})"
    if done.returncode:
        return f"unshare -m needs root: {done.stderr.decode().strip()}"
    return None


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _node_ports() -> list[str]:
    """Ports of a node's agents, free ones (the defaults would meet another test's local Ray)."""
    agent, grpc, metrics, runtime = _free_ports(4)
    return ["--dashboard-agent-listen-port", str(agent), "--dashboard-agent-grpc-port", str(grpc),
            "--metrics-export-port", str(metrics), "--runtime-env-agent-port", str(runtime)]


def _processes(match: str, field: str) -> list[int]:
    """Processes whose session id (``field="sid"``) or mount namespace (``"mnt"``) is ``match``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if field == "sid":
                value = (entry / "stat").read_text().rsplit(")", 1)[1].split()[3]
            else:
                value = os.readlink(entry / "ns" / "mnt")
        except OSError:
            continue
        if value == match:
            found.append(int(entry.name))
    return found


def _kill(pids: list[int]) -> None:
    for pid in pids:
        if pid != os.getpid():
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


class Cluster:
    """The running cluster: its ``address``, and the far node (its own file system at ``out``)."""

    def __init__(self, address: str, head: subprocess.Popen, far: subprocess.Popen, out: Path) -> None:
        self.address, self.head, self.far, self.out = address, head, far, out
        self.namespace = os.readlink(f"/proc/{far.pid}/ns/mnt")
        self.root = Path(f"/proc/{far.pid}/root")  # the far node's file system, seen from here

    def far_view(self, path: Path) -> Path:
        """``path`` as the far node sees it."""
        return self.root / Path(os.path.abspath(path)).relative_to("/")

    def kill_far_node(self) -> None:
        """SIGKILL every process of the far node (all of its mount namespace), as a lost machine."""
        _kill(_processes(self.namespace, "mnt"))


@contextlib.contextmanager
def two_node_cluster(out: Path, logs: Path) -> Iterator[Cluster]:
    """A head node (1 CPU) and a far node (1 CPU) that sees an empty tmpfs at ``out``; both
    use the token in ``~/.ray/auth_token`` (the head makes it when missing)."""
    import ray

    out.mkdir(parents=True, exist_ok=True)
    logs.mkdir(parents=True, exist_ok=True)
    port, client = _free_ports(2)
    # token authentication, as on a real cluster, with a token of its own (~/.ray is left alone)
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("RAY_")}, **auth}
    saved = {k: os.environ.get(k) for k in (*auth, "RAY_AUTH_TOKEN_PATH")}
    os.environ.pop("RAY_AUTH_TOKEN_PATH", None)
    os.environ.update(auth)  # this process is the driver
    _reset_auth()
    common = ["--node-ip-address", "127.0.0.1", "--num-cpus", "1", "--disable-usage-stats", "--block"]
    head = subprocess.Popen([RAY, "start", "--head", "--port", str(port), "--ray-client-server-port", str(client),
                             "--include-dashboard", "false", *common, *_node_ports()], env=env,
                            stdout=open(logs / "head.log", "w"), stderr=subprocess.STDOUT, start_new_session=True)
    far = None
    try:
        address = f"127.0.0.1:{port}"
        _wait_for(lambda: _alive_nodes(address, env) >= 1, 60, "the head node", logs / "head.log")
        start_far = shlex.join([RAY, "start", "--address", address, *common, *_node_ports()])
        mount = shlex.join(["mount", "-t", "tmpfs", "uavris-far", str(out)])
        far = subprocess.Popen(["unshare", "-m", "sh", "-c", f"{mount} && exec {start_far}"],
                               env=env, stdout=open(logs / "far.log", "w"), stderr=subprocess.STDOUT,
                               start_new_session=True)
        _wait_for(lambda: _alive_nodes(address, env) >= 2, 90, "the far node", logs / "far.log")
        yield Cluster(address, head, far, out)
    finally:
        if ray.is_initialized():
            ray.shutdown()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        _reset_auth()
        if far is not None:
            with contextlib.suppress(OSError):
                _kill(_processes(os.readlink(f"/proc/{far.pid}/ns/mnt"), "mnt"))
            _kill(_processes(str(far.pid), "sid"))
        _kill(_processes(str(head.pid), "sid"))
        for p in (head, far):
            if p is not None:
                p.wait(timeout=30)
        # `ray start` left its address for a plain ray.init() on this machine: not a dead cluster's
        current = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"
        with contextlib.suppress(OSError):
            if current.read_text().strip().endswith(f":{port}"):
                current.unlink()


def _reset_auth() -> None:
    """Ray's cached token and configuration, read again from the environment."""
    from ray._raylet import AuthenticationTokenLoader, Config

    Config.initialize("")
    AuthenticationTokenLoader.instance().reset_cache()


def _alive_nodes(address: str, env: dict[str, str]) -> int:
    """How many nodes the cluster at ``address`` has alive (0 while it cannot be reached)."""
    code = ("import ray; ray.init(address=%r, log_to_driver=False); "
            "print(sum(n['Alive'] for n in ray.nodes()))" % address)
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    except subprocess.TimeoutExpired:
        return 0
    lines = done.stdout.strip().splitlines()
    return int(lines[-1]) if done.returncode == 0 and lines and lines[-1].isdigit() else 0


def _wait_for(ready, limit_s: float, what: str, log: Path) -> None:
    end = time.monotonic() + limit_s
    while not ready():
        if time.monotonic() > end:
            raise RuntimeError(f"{what} did not start in {limit_s:.0f} s: {log.read_text()[-2000:]}")
        time.sleep(1.0)
