"""The ``--out`` folder of one ``process`` run: enough free space before anything is written, one run
at a time (a lock), COLMAP's logs inside it, and nothing left behind by a run that failed before it
made anything worth resuming.

COLMAP writes its database through SQLite, and a full disk there is a native abort (no Python error to
catch): the free space is checked up front against a generous estimate of what the run writes, and a
disk that fills up later (another writer) is caught by running the SfM in a child (:mod:`.sfm_worker`).
"""

from __future__ import annotations

import fcntl
import os
import shutil
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.utils.disk import free_bytes, mount_point

LOCK_NAME = "process.lock"
LOGS = "logs"
MB = 1e6
DB_BYTES_PER_FEATURE = 6 * 4 + 128  # a keypoint (6 floats) and its SIFT descriptor
PAIR_BYTES = 16_000  # matches + two-view geometry of one image pair, generously
COPIES = 3.4  # frames, undistorted temp, images, images_2/4/8 (1/4 + 1/16 + 1/64)
MARGIN_BYTES = 50 * MB


def estimate_bytes(frames: int, frame_bytes: float, max_features: int, pairs: int) -> int:
    """About what a run writes for ``frames`` frames of ``frame_bytes`` each (images + COLMAP database,
    SQLite's journal counted as half the database again)."""
    db = frames * max_features * DB_BYTES_PER_FEATURE + pairs * PAIR_BYTES
    return int(frames * frame_bytes * COPIES + 1.5 * db + MARGIN_BYTES)


def check_free_space(root: Path, needed: int) -> None:
    """A :class:`DataError` naming the disk when it has less than ``needed`` bytes free."""
    free = free_bytes(root)
    if free < needed:
        raise DataError(f"not enough free space on {mount_point(root)} ({free / MB:.1f} MB free, about {needed / MB:.1f} MB "
                        "needed): free space there or choose another --out", root)


def _lock(path: Path) -> int:
    """An exclusive ``flock`` on ``path`` (released by the OS when the holder dies, even by kill -9)."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        other = os.read(fd, 32).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise DataError(f"another `ns2gs-data process` run is writing into this folder (pid {other}); wait for it to finish "
                        "or choose another --out", path.parent.parent) from None
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


@dataclass
class Claim:
    """The folders a run made (removed if it fails before :meth:`keep`)."""

    root: Path
    made: list[Path] = field(default_factory=list)
    kept: bool = False

    @property
    def work(self) -> Path:
        return self.root / "colmap"

    def keep(self) -> None:
        """From here on what the run made is worth resuming: a failure leaves it."""
        self.kept = True


def _make(path: Path, made: list[Path]) -> None:
    """``mkdir -p`` that records the topmost folder it created (another run creating it meanwhile: not ours)."""
    missing = []
    p = path
    while not p.exists():
        missing.append(p)
        p = p.parent
    for p in reversed(missing):
        try:
            p.mkdir()
        except FileExistsError:
            continue
        if not made or not p.is_relative_to(made[-1]):
            made.append(p)


@contextmanager
def claimed_output(root: Path, needed_bytes: int) -> Iterator[Claim]:
    """Check the free space, make ``root/colmap`` and lock it for this run; on a failure before
    :meth:`Claim.keep`, remove the folders this run made."""
    root = Path(root)
    check_free_space(root, needed_bytes - _size_of(root))  # a re-run rewrites files already there
    claim = Claim(root)
    _make(claim.work, claim.made)
    fd = _lock(claim.work / LOCK_NAME)  # refused: the folders are the other run's now, left alone
    try:
        yield claim
    except BaseException:
        if not claim.kept:
            for p in reversed(claim.made):
                shutil.rmtree(p, ignore_errors=True)
        raise
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def _size_of(root: Path) -> int:
    """Bytes in the files under ``root`` (0 when it does not exist)."""
    total = 0
    for dirpath, _, files in os.walk(root):
        for f in files:
            try:
                total += os.lstat(os.path.join(dirpath, f)).st_size
            except OSError:
                continue
    return total


def silence_colmap(logs: Path) -> None:
    """COLMAP's errors only, into its log file under ``logs`` (pycolmap also copies every message to
    stderr by default: the run's own error is the one line there); its INFO stream would bury the bars."""
    import pycolmap

    pycolmap.logging.minloglevel = 2
    pycolmap.logging.alsologtostderr = False
    pycolmap.logging.stderrthreshold = 3
    colmap_logs_into(logs)  # not the system temp folder
    _keep_sigterm_handler()


def _keep_sigterm_handler() -> None:
    """Importing pycolmap installs glog's failure handler over SIGTERM (a stack dump, then death): put
    Python's own back, so SIGTERM runs the clean-up and exits 143 (:func:`~nerf2gs_plugin.cli.common.exit_on_sigterm`)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        handler = signal.getsignal(signal.SIGTERM)
        signal.signal(signal.SIGTERM, handler if handler is not None else signal.SIG_DFL)


def colmap_logs_into(folder: Path) -> None:
    """pycolmap's glog file (otherwise ``<tmp>/<prog>.<host>.log.{INFO,WARNING,ERROR}.*`` on every run
    that logs) as ``folder/colmap.<time>.<pid>``: one file, every level (only errors: see minloglevel)."""
    import pycolmap

    folder.mkdir(parents=True, exist_ok=True)
    log = pycolmap.logging
    log.set_log_destination(log.INFO, str(folder / "colmap."))
    for level in (log.WARNING, log.ERROR, log.FATAL):
        log.set_log_destination(level, "")  # glog writes each message into every lower level's file too


def expected_pairs(frames: int, method: str, opt) -> int:
    """Image pairs the matching will store, about (exhaustive: all; sequential: the window, its
    quadratic hops and the loop pairs)."""
    if method == "exhaustive":
        return frames * (frames - 1) // 2
    return frames * (opt.overlap + max(frames, 2).bit_length() + opt.loop_pairs)
