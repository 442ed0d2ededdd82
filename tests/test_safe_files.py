"""No file a user passes in runs code when read: an expert's run is read from safetensors and JSON,
SB3's pickled archive (a colleague's, uavris 0.3's) only with --trust-pickle, a checkpoint resumed
only where uavris sealed it as its own, and every YAML through the safe loader. Each reader is
tried with a hostile file whose payload would leave a marker file behind."""

from __future__ import annotations

import base64
import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

from uavris.cli import main
from uavris.experiments.training.train_expert import TrainConfig, train


class _Payload:
    """Unpickling this runs ``touch MARKER``: what a hostile pickle does."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _poison_archive(archive: Path, marker: Path) -> None:
    """SB3's archive with its cloudpickled ``policy_class`` replaced by the payload."""
    with zipfile.ZipFile(archive) as z:
        members = {n: z.read(n) for n in z.namelist()}
    data = json.loads(members["data"])
    data["policy_class"][":serialized:"] = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(archive, "w") as z:
        for name, blob in members.items():
            z.writestr(name, blob)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    cfg = TrainConfig(algo="ppo", scenario="fig2", seed=0, preset="smoke", total_steps=256, eval_episodes=2)
    path = tmp_path_factory.mktemp("runs") / "ppo"
    train(cfg, path, progress=False)
    return path


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def _evaluate(run: Path, out: Path, *flags: str) -> int:
    return main(["evaluate", str(run), "--scenario", "fig2", "--episodes", "2", "--out", str(out), "--no-progress",
                 "--no-references", *flags])


def test_uavris_reads_its_own_run_from_safetensors_never_from_the_archive(run, tmp_path, capsys):
    assert (run / "policy.safetensors").is_file() and (run / "policy.json").is_file()
    assert _evaluate(run, tmp_path / "clean") == 0
    clean = json.loads(next((tmp_path / "clean").glob("*.json")).read_text())
    marker = tmp_path / "ran"
    poisoned = _copy(run, tmp_path / "poisoned")
    _poison_archive(poisoned / "model.zip", marker)
    for archive in (poisoned / "checkpoints").glob("*.zip"):
        _poison_archive(archive, marker)
    capsys.readouterr()
    assert _evaluate(poisoned, tmp_path / "out") == 0
    assert not marker.exists()
    got = json.loads(next((tmp_path / "out").glob("*.json")).read_text())
    assert got["mean"] == clean["mean"]  # the same policy, bit for bit


def test_a_run_with_only_sb3s_archive_is_one_line_naming_the_flag_and_runs_nothing(run, tmp_path, capsys):
    marker = tmp_path / "ran"
    old = _copy(run, tmp_path / "old")
    for f in [*old.glob("policy.*"), *(old / "checkpoints").glob("*.policy.*")]:
        f.unlink()  # as uavris 0.3 wrote it, or another tool
    _poison_archive(old / "model.zip", marker)
    for command in (["evaluate", str(old), "--scenario", "fig2", "--episodes", "2", "--out", str(tmp_path / "e")],
                    ["benchmark", str(old), "--preset", "smoke", "--cells", "scenarios", "--out", str(tmp_path / "b")],
                    ["collect", "--experts", str(old), "--trajectories", "1", "--out", str(tmp_path / "d")]):
        capsys.readouterr()
        assert main([*command, "--no-progress"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "--trust-pickle" in err and "pickled archive" in err, err
        assert not marker.exists()
    assert not any((tmp_path / d).exists() and any((tmp_path / d).rglob("*.json")) for d in ("e", "b", "d"))


def test_trust_pickle_loads_an_old_run_with_the_same_numbers(run, tmp_path):
    old = _copy(run, tmp_path / "old")
    for f in [*old.glob("policy.*"), *(old / "checkpoints").glob("*.policy.*")]:
        f.unlink()
    assert _evaluate(run, tmp_path / "new") == 0 and _evaluate(old, tmp_path / "old-e", "--trust-pickle") == 0
    new = json.loads(next((tmp_path / "new").glob("*.json")).read_text())
    trusted = json.loads(next((tmp_path / "old-e").glob("*.json")).read_text())
    assert trusted["mean"] == new["mean"]


def test_resuming_a_checkpoint_uavris_did_not_seal_is_refused_before_unpickling(tmp_path, capsys):
    cfg = TrainConfig(algo="ppo", scenario="fig2", seed=0, preset="smoke", total_steps=640, eval_episodes=2)
    path = tmp_path / "ppo"
    with pytest.raises(KeyboardInterrupt):
        train(cfg, path, progress=False, interrupt_at=400)
    [archive] = (path / "checkpoints").glob("step_*.zip")
    marker = tmp_path / "ran"
    _poison_archive(archive, marker)  # its seal no longer matches
    capsys.readouterr()
    assert main(["train", "--resume", "--out", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--trust-pickle" in err and "did not write" in err, err
    assert not marker.exists()
    # the resume state too: a hostile blob beside an intact archive is refused the same way
    [state] = (path / "checkpoints").glob("step_*.state.pkl")
    state.write_bytes(pickle.dumps(_Payload(marker)))
    assert main(["train", "--resume", "--out", str(path), "--no-progress"]) == 2
    assert not marker.exists()


def test_a_run_resumes_its_own_sealed_checkpoint(tmp_path):
    cfg = TrainConfig(algo="ppo", scenario="fig2", seed=0, preset="smoke", total_steps=640, eval_episodes=2)
    path = tmp_path / "ppo"
    with pytest.raises(KeyboardInterrupt):
        train(cfg, path, progress=False, interrupt_at=400)
    assert all(Path(f"{p}.seal").is_file() for p in (path / "checkpoints").glob("step_*.*")
               if p.suffix in (".zip", ".pkl"))
    train(cfg, path, resume=True, progress=False)
    assert (path / "done.json").is_file()


HOSTILE_YAML = "!!python/object/apply:os.system [\"touch {marker}\"]\n"


def test_every_yaml_a_user_passes_is_read_safely(run, tmp_path, capsys):
    marker = tmp_path / "ran"
    bad_run = _copy(run, tmp_path / "bad")
    (bad_run / "config.yaml").write_text(HOSTILE_YAML.format(marker=marker))
    (tmp_path / "study").mkdir()
    (tmp_path / "study" / "study.yaml").write_text(HOSTILE_YAML.format(marker=marker))
    (tmp_path / "hall.yaml").write_text(HOSTILE_YAML.format(marker=marker))
    (tmp_path / "train.yaml").write_text(HOSTILE_YAML.format(marker=marker))
    for command in (["evaluate", str(bad_run), "--scenario", "fig2", "--out", str(tmp_path / "e")],
                    ["evaluate", str(tmp_path / "study"), "--row", "oracle", "--layout", "layout-unseen-0"],
                    ["claims", str(tmp_path / "study"), "--out", str(tmp_path / "c")],
                    ["plan", str(tmp_path / "hall.yaml"), "--out", str(tmp_path / "p")],
                    ["train", "--config", str(tmp_path / "train.yaml"), "--out", str(tmp_path / "t")]):
        capsys.readouterr()
        assert main([*command, "--no-progress"] if command[0] != "claims" else command) == 2, command
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("uavris: error:"), err
        assert not marker.exists()


def test_a_hostile_label_part_is_refused_without_unpickling(tmp_path):
    from uavris.experiments.training.values import read_labels

    part = tmp_path / "part.npz"
    np.savez(part, users=np.array([object()], dtype=object), position=np.zeros((1, 3)), rate=np.zeros(1),
             hall=np.array(["h"]))
    with pytest.raises(ValueError, match="allow_pickle"):
        read_labels([part])


def test_seal_key_is_made_once_and_kept_private(tmp_path, monkeypatch):
    from uavris.runs.seal import check_sealed, is_sealed, seal

    monkeypatch.delenv("UAVRIS_SEAL_KEY")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    blob = tmp_path / "blob.pkl"
    blob.write_bytes(b"\x80\x04K\x01.")
    seal(blob)
    key = tmp_path / "config" / "uavris" / "seal.key"
    assert key.is_file() and len(key.read_bytes()) == 32 and (key.stat().st_mode & 0o777) == 0o600
    assert is_sealed(blob)
    blob.write_bytes(b"\x80\x04K\x02.")  # one byte changed: the seal no longer matches
    assert not is_sealed(blob)
    check_sealed(blob, trust=True)  # the user's word
    monkeypatch.setenv("UAVRIS_SEAL_KEY", "ab" * 32)  # another machine's key: its seals are not ours
    blob.write_bytes(b"\x80\x04K\x01.")
    assert not is_sealed(blob)


@pytest.mark.parametrize("given", ["\n", "", "  ", "ab" * 15])
def test_a_seal_key_shorter_than_16_bytes_is_one_line(tmp_path, monkeypatch, given):
    """An empty HMAC key (a whitespace-only UAVRIS_SEAL_KEY reads as no bytes) would let anyone
    forge a seal: refused, as is a key file too short to be secret."""
    from uavris.errors import CheckpointError
    from uavris.runs.seal import is_sealed, seal

    blob = tmp_path / "blob.pkl"
    blob.write_bytes(b"\x80\x04K\x01.")
    monkeypatch.setenv("UAVRIS_SEAL_KEY", given)
    with pytest.raises(CheckpointError, match="at least 16") as err:
        seal(blob)
    assert len(str(err.value).splitlines()) == 1
    (tmp_path / "blob.pkl.seal").write_text("1c34a7df1cb776ba1eca1b83febbd99cfc4f51eb1f50c21d1284a3063dff0898")
    with pytest.raises(CheckpointError, match="at least 16"):  # the empty key's HMAC: a forged seal
        is_sealed(blob)
    monkeypatch.setenv("UAVRIS_SEAL_KEY", "ab" * 16)  # 16 bytes: enough
    seal(blob)
    assert is_sealed(blob)
    monkeypatch.delenv("UAVRIS_SEAL_KEY")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    (tmp_path / "config" / "uavris").mkdir(parents=True)
    (tmp_path / "config" / "uavris" / "seal.key").write_bytes(b"")
    with pytest.raises(CheckpointError, match="at least 16"):
        seal(blob)


def _link_out(folder: Path, name: str, outside: Path) -> Path:
    """``folder/name`` replaced by a link to a copy of it in ``outside`` (a file the user's folder does
    not hold)."""
    import shutil

    outside.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(folder / name, outside / name)
    (folder / name).unlink()
    (folder / name).symlink_to(outside / name)
    return folder / name


def _refused(err: str, link: Path) -> None:
    assert err.count("\n") == 0 and f"{link} is a link to" in err and "reads only its own files" in err, err


def test_a_folder_of_every_kind_refuses_a_link_that_leaves_it(run, tmp_path, capsys):
    """An expert's run, a DT model, a learned value and a controller (the shipped one, whose goal
    folder is a learned value and whose model folder a DT's) each refuse, in one line naming it and
    before it is opened, a link that resolves outside the folder; a link inside it is read."""
    import shutil

    from uavris.agents.dt.checkpoint import load_dt
    from uavris.agents.place.checkpoint import load_value
    from uavris.errors import CheckpointError
    from uavris.experiments.tools.rows import PRETRAINED

    for name in ("policy.json", "config.yaml"):  # its weights' description; its configuration, read first
        expert = _copy(run, tmp_path / f"expert-{name}")
        link = _link_out(expert, name, tmp_path / "elsewhere" / f"expert-{name}")
        capsys.readouterr()
        assert _evaluate(expert, tmp_path / "e") == 2
        _refused(capsys.readouterr().err.strip(), link)
    looped = _copy(run, tmp_path / "looped")
    (looped / "a").symlink_to("b")
    (looped / "b").symlink_to("a")
    capsys.readouterr()
    assert _evaluate(looped, tmp_path / "e") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "a loop of links" in err, err
    for folder, name, load in (("model", "model.safetensors", load_dt), ("goal", "value.json", load_value)):
        copy = shutil.copytree(PRETRAINED / folder, tmp_path / folder)
        load(copy)  # as shipped: read
        (copy / "inside").mkdir()
        shutil.move(copy / name, copy / "inside" / name)
        (copy / name).symlink_to(Path("inside") / name)
        load(copy)  # a link that stays inside the folder: read
        (copy / name).unlink()
        shutil.move(copy / "inside" / name, copy / name)
        link = _link_out(copy, name, tmp_path / "elsewhere" / folder)
        with pytest.raises(CheckpointError) as e:
            load(copy)
        _refused(str(e.value), link)
    controller = shutil.copytree(PRETRAINED, tmp_path / "controller")
    link = _link_out(controller / "goal", "value.json", tmp_path / "elsewhere" / "controller")
    capsys.readouterr()
    assert main(["evaluate", str(controller), "--layout", "layout-unseen-0", "--episodes", "1", "--no-progress",
                 "--no-references", "--out", str(tmp_path / "c")]) == 2
    _refused(capsys.readouterr().err.strip(), link)
    assert not (tmp_path / "c").exists() or not any((tmp_path / "c").rglob("*.json"))
