"""``ns2gs-data process`` on bad captures and hostile conditions: replaced photos, a second run into
the same folder, a full disk, unreadable photos, mixed photo sizes, bad video flags, third-party logs,
SIGTERM and early failures. Tiny synthetic photos; no test here needs the SfM to succeed."""

from __future__ import annotations

import errno
import fcntl
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from nerf2gs_plugin.cli.data import main
from nerf2gs_plugin.errors import ConfigError, DataError

REPO = Path(__file__).resolve().parents[2]


def _photos(folder: Path, n: int = 6, w: int = 64, h: int = 48, seed: int = 0, start: int = 0) -> list[Path]:
    """``n`` textured PNG photos ``p<i>.png`` in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    out = []
    for i in range(start, start + n):
        img = cv2.resize(rng.integers(0, 255, (h // 4, w // 4, 3), dtype=np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
        out.append(folder / f"p{i}.png")
        cv2.imwrite(str(out[-1]), img)
    return out


def _process(photos: Path, out: Path, *extra: str) -> None:
    main(["process", "images", str(photos), "--out", str(out), "--no-progress", "--num-threads", "1", *extra])


def test_replaced_photos_are_processed_again(tmp_path):
    """Photos replaced under the same names: the frames, the features and the matches are those of the new
    photos (the old frames were kept by name and the dataset built from them)."""
    import pycolmap

    from nerf2gs_plugin.data.process.sfm import SfmOptions, extract

    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos, seed=0)
    with pytest.raises(DataError, match="registration failed"):  # noise photos: no model, but frames and features
        _process(photos, out)
    db = out / "colmap" / "database.db"
    with pycolmap.Database.open(str(db)) as d:
        before = {im.name: d.read_keypoints(im.image_id).shape[0] for im in d.read_all_images()}
    _photos(photos, seed=1)
    with pytest.raises(DataError, match="registration failed"):
        _process(photos, out)
    assert (out / "colmap" / "frames" / "p0.png").read_bytes() == (photos / "p0.png").read_bytes()
    # the features are recomputed from the new frames (a changed frame restarts the database)
    frames = out / "colmap" / "frames"
    names = sorted(p.name for p in frames.iterdir())
    other = tmp_path / "other.db"
    extract(other, frames, names, SfmOptions(num_threads=1), None)
    with pycolmap.Database.open(str(db)) as d, pycolmap.Database.open(str(other)) as o:
        now = {im.name: d.read_keypoints(im.image_id).shape[0] for im in d.read_all_images()}
        fresh = {im.name: o.read_keypoints(im.image_id).shape[0] for im in o.read_all_images()}
    assert now == fresh != before


def test_match_and_mapping_keys_follow_content(tmp_path, monkeypatch):
    """The matching marker and the mapping marker are keyed on the frames' content, not their names."""
    from nerf2gs_plugin.data.process import sfm

    calls = []
    monkeypatch.setattr(sfm, "_marker", lambda path, key: calls.append(key) or False)
    import pycolmap

    db = tmp_path / "database.db"
    with pycolmap.Database.open(str(db)) as d:
        cam = d.write_camera(pycolmap.Camera.create_from_model_name(1, "SIMPLE_PINHOLE", 100.0, 64, 48))
        for i in range(3):
            d.write_image(pycolmap.Image(name=f"f{i}.png", camera_id=cam))
    monkeypatch.setattr(pycolmap, "match_exhaustive", lambda *a, **k: None)
    sfm.match(db, "exhaustive", sfm.SfmOptions(), tmp_path / "m.json", content="aaa")
    sfm.match(db, "exhaustive", sfm.SfmOptions(), tmp_path / "m.json", content="bbb")
    assert calls[0] != calls[1]


def test_second_run_into_the_same_out_is_refused(tmp_path):
    """A process run holding DATA's lock: a second run says so in one line and touches nothing."""
    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos)
    (out / "colmap").mkdir(parents=True)
    with open(out / "colmap" / "process.lock", "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        f.write("4242\n")
        f.flush()
        with pytest.raises(DataError, match="another `ns2gs-data process` run .*pid 4242"):
            _process(photos, out)
    assert sorted(p.name for p in (out / "colmap").iterdir()) == ["process.lock"]


def test_too_little_free_space_is_one_line_before_anything_is_written(tmp_path, monkeypatch):
    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos)
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda p: real(p)._replace(free=100_000))
    with pytest.raises(DataError, match=r"not enough free space on .* \(0\.1 MB free, about .* MB needed\)"):
        _process(photos, out)
    assert not out.exists()


def test_disk_full_error_names_the_disk(tmp_path, capsys):
    from nerf2gs_plugin.cli.common import run_cli

    def full():
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "x" / "database.db"))

    with pytest.raises(SystemExit) as e:
        run_cli(full)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "MB free on" in err[0]


def test_unreadable_photos_are_named(tmp_path):
    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos)
    (photos / "broken.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    (photos / "empty.png").write_bytes(b"")
    with pytest.warns(UserWarning, match=r"2 unreadable photos skipped: broken\.jpg, empty\.png"):
        with pytest.raises(DataError, match="registration failed"):
            _process(photos, out)


def test_photos_of_two_sizes_are_named_before_the_sfm(tmp_path):
    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos, n=5)
    _photos(photos, n=2, w=48, h=64, start=5)
    with pytest.raises(DataError, match=r"photos of 2 sizes: 5 of 64x48 \(p0\.png, \.\.\.\), 2 of 48x64 \(p5\.png, p6\.png\)"):
        _process(photos, out)
    assert not out.exists()


@pytest.mark.parametrize("flags,what", [(["--num-frames", "0"], "--num-frames"), (["--num-frames", "-5"], "--num-frames"),
                                        (["--fps", "-1"], "--fps"), (["--fps", "nan"], "--fps"), (["--fps", "0"], "--fps")])
def test_video_frame_flags_are_checked_up_front(tmp_path, flags, what):
    video = tmp_path / "v.avi"
    video.write_bytes(b"not looked at")
    with pytest.raises(ConfigError, match=what):
        main(["process", "video", str(video), "--out", str(tmp_path / "d"), "--no-progress", *flags])
    assert not (tmp_path / "d").exists()


def test_early_failure_leaves_no_folder(tmp_path):
    """Too few photos: nothing valid was made, so nothing is left (an empty colmap/ was)."""
    photos, out = tmp_path / "photos", tmp_path / "d"
    _photos(photos, n=2)
    with pytest.raises(DataError, match="too few images"):
        _process(photos, out)
    assert not out.exists()
    out.mkdir()
    (out / "mine.txt").write_text("the user's")
    with pytest.raises(DataError, match="too few images"):
        _process(photos, out)
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]  # only what the run made is removed


def _env(tmp: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO), "TMPDIR": str(tmp)}
    env.pop("GLOG_log_dir", None)
    return env


def test_colmap_logs_go_under_the_dataset(tmp_path):
    """A failing SfM leaves pycolmap's glog files in DATA/colmap/logs, none in the system temp folder."""
    photos, out, tmp = tmp_path / "photos", tmp_path / "d", tmp_path / "tmp"
    _photos(photos)
    tmp.mkdir()
    r = subprocess.run([sys.executable, "-m", "nerf2gs_plugin.cli.data", "process", "images", str(photos), "--out", str(out),
                        "--no-progress", "--num-threads", "1"], env=_env(tmp), capture_output=True, text=True, timeout=120)
    err = r.stderr.strip().splitlines()  # COLMAP's own error lines are in its log, not around the run's one line
    assert r.returncode == 2 and len(err) == 1 and "registration failed" in err[0], r.stderr
    assert "--matching exhaustive" not in err[0]  # 6 photos were matched exhaustively already
    assert not [p.name for p in tmp.rglob("*") if ".log." in p.name or p.name.endswith((".INFO", ".WARNING", ".ERROR"))]
    assert "Failed to create any sparse model" in next((out / "colmap" / "logs").iterdir()).read_text()


def test_a_write_failing_during_the_sfm_is_one_line_not_a_native_abort(tmp_path):
    """A disk filling up during the SfM: SQLite's write error inside COLMAP was a native abort with a
    stack dump (exit 134). The SfM stages run in a child process: one line naming the stage and COLMAP's
    message, exit 2, and a re-run with room resumes."""
    from nerf2gs_bench.faults_capture import limit_file_size

    photos, out, tmp = tmp_path / "photos", tmp_path / "d", tmp_path / "tmp"
    _photos(photos, n=8, w=320, h=240)  # megabytes of SIFT features: the database outgrows the limit
    tmp.mkdir()
    cmd = [sys.executable, "-m", "nerf2gs_plugin.cli.data", "process", "images", str(photos), "--out", str(out), "--no-progress",
           "--num-threads", "1"]
    r = subprocess.run(cmd, env=_env(tmp), capture_output=True, text=True, timeout=120, preexec_fn=limit_file_size(256_000))
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1, (r.returncode, r.stderr[-2000:])
    assert "during the SfM (features)" in err[0] and "SQLite" in err[0] and str(out / "colmap" / "logs") in err[0]
    r = subprocess.run(cmd, env=_env(tmp), capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "registration failed" in r.stderr  # noise photos: features and matches made, no model


def test_a_crash_with_the_disk_full_names_the_disk(tmp_path, monkeypatch):
    """The crash line of a worker that died with the disk (nearly) full says so, naming the mount point."""
    from nerf2gs_plugin.data.process import sfm_worker
    from nerf2gs_plugin.utils.disk import mount_point

    err = tmp_path / "sfm-stderr.1.txt"
    err.write_text("terminate called after throwing an instance of 'std::runtime_error'\n"
                   "  what():  [database_sqlite.cc:1737] SQLite error: database or disk is full\n"
                   "*** Aborted at 1795761039 (unix time) ***\n    @     0x7f323aeac057 abort\n")
    monkeypatch.setattr(sfm_worker, "free_bytes", lambda p: 3_000_000)
    line = sfm_worker.crash_line("matching", -6, tmp_path, err)
    assert line.startswith("COLMAP stopped during the SfM (matching) with signal SIGABRT: [database_sqlite.cc:1737] SQLite error: "
                           "database or disk is full; the disk is full: 3 MB free on " + str(mount_point(tmp_path)))
    monkeypatch.setattr(sfm_worker, "free_bytes", lambda p: 10**10)
    assert "MB free on" not in sfm_worker.crash_line("matching", -6, tmp_path, err)


def _sigterm_run(tmp_path, setup: str = "") -> subprocess.CompletedProcess:
    """A CLI main that runs SETUP, then gets SIGTERM; its Ctrl-C clean-up prints 'cleaned up'."""
    code = ("import os, signal, time\n"
            "from pathlib import Path\n"
            "from nerf2gs_plugin.cli.common import run_cli\n"
            "def main():\n"
            f"    {setup or 'pass'}\n"
            "    try:\n"
            "        os.kill(os.getpid(), signal.SIGTERM); time.sleep(5)\n"
            "    except KeyboardInterrupt:\n"
            "        print('cleaned up', flush=True); raise\n"
            "run_cli(main)\n")
    return subprocess.run([sys.executable, "-c", code], env=_env(tmp_path), capture_output=True, text=True, timeout=60)


def test_sigterm_exits_143(tmp_path):
    """SIGTERM is not SIGINT: 143 (128 + 15), after the same clean-up as Ctrl-C."""
    r = _sigterm_run(tmp_path)
    assert r.returncode == 143 and "cleaned up" in r.stdout and r.stderr.strip() == "terminated", (r.returncode, r.stderr)


def test_sigterm_after_pycolmap_is_imported_still_cleans_up(tmp_path):
    """pycolmap's import put glog's failure handler over SIGTERM: a stack dump and no clean-up."""
    setup = ("from nerf2gs_plugin.data.process.output import silence_colmap; "
             f"silence_colmap(Path({str(tmp_path / 'logs')!r}))")
    r = _sigterm_run(tmp_path, setup)
    assert r.returncode == 143 and "cleaned up" in r.stdout and r.stderr.strip() == "terminated", (r.returncode, r.stderr[-800:])


def test_train_sigterm_saves_and_exits_143(monkeypatch, capsys):
    """The trainer's preemption signal saves a checkpoint like Ctrl-C, and exits 143, not SIGINT's 130."""
    from types import SimpleNamespace

    from nerf2gs_plugin.cli import train as train_cli
    from nerf2gs_plugin.cli.common import run_cli

    class FakeTrainer:
        step = 3

        def __init__(self, config):
            pass

        def setup(self):
            pass

        def train(self):
            os.kill(os.getpid(), signal.SIGTERM)
            raise AssertionError("not interrupted")

        def save_checkpoint(self, step, synced):
            return Path(f"step-{step}.ckpt")

    previous = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(train_cli, "Trainer", FakeTrainer)
    try:
        with pytest.raises(SystemExit) as e:
            run_cli(lambda: train_cli.train(SimpleNamespace(augment_from=None, viewer=False)))
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert e.value.code == 143 and "checkpoint saved to step-3.ckpt" in capsys.readouterr().err


def test_onnxruntime_leaves_no_files_outside(tmp_path):
    """Opening an ONNX model (masks, enhancers) writes nothing under the user's cache or temp folder
    (onnxruntime's telemetry wrote a device id, a database and a .ses file there on import)."""
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 4, 4])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 3, 4, 4])])
    model = tmp_path / "id.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)]), str(model))
    cache, tmp, home = tmp_path / "cache", tmp_path / "tmp", tmp_path / "home"
    for d in (cache, tmp, home):
        d.mkdir()
    env = {**_env(tmp), "XDG_CACHE_HOME": str(cache), "HOME": str(home)}
    code = f"from nerf2gs_plugin.utils.onnx_model import open_session; open_session({str(model)!r}, ['CPUExecutionProvider'])"
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert [str(p.relative_to(tmp_path)) for d in (cache, tmp, home) for p in d.rglob("*")] == []
