"""The SfM stages (features, matching, mapping) in a child process.

COLMAP ends some failures with a native abort, SQLite's "disk I/O error" / "database or disk is full"
among them (another writer filling the disk during the SfM): in-process that kills the command with a
stack dump (exit 134). In a child the abort is the child's; the command turns it into one line naming
the stage, COLMAP's own message and the disk. The child's progress goes to the parent's bars through
the pipe; it dies with the parent (a kill -9 of ``process`` leaves no COLMAP writing on behind its lock).
"""

from __future__ import annotations

import os
import pickle
import signal
import socket
import subprocess
import sys
import time
import traceback
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Optional

from nerf2gs_plugin.errors import DataError, UserError
from nerf2gs_plugin.utils.disk import free_bytes, mount_point

LOW_FREE_BYTES = 64 * 1024 * 1024
"""Less than this free after a crash: the disk is named as the cause."""


class _RemoteProgress:
    """The progress calls the stages make (``add_task`` / ``update``), sent to the parent's display."""

    def __init__(self, conn: Connection) -> None:
        self.conn, self.n = conn, 0

    def add_task(self, description: str, **kw: Any) -> int:
        self.n += 1
        self.conn.send(("add_task", self.n, description, kw))
        return self.n

    def update(self, task: int, **kw: Any) -> None:
        self.conn.send(("update", task, kw))


def _stages(conn: Connection, job: dict) -> tuple:
    from nerf2gs_plugin.data.process import sfm
    from nerf2gs_plugin.data.process.output import silence_colmap

    silence_colmap(job["logs"])
    progress = _RemoteProgress(conn) if job["progress"] else None
    work, opt, times = Path(job["work"]), job["sfm"], {}

    def stage(name: str) -> float:
        conn.send(("stage", name))
        return time.perf_counter()

    t = stage("features")
    sfm.extract(work / "database.db", work / "frames", job["names"], opt, job["focal"], progress, hashes=job["hashes"])
    times["features"] = time.perf_counter() - t
    t = stage("matching")
    changed = sfm.match(work / "database.db", job["method"], opt, work / "matching.json", progress, content=job["content"])
    times["matching"] = time.perf_counter() - t
    t = stage("mapping")
    score = None
    if job.get("check") is not None:  # the capture check's options: rank the mapping attempts by what it keeps
        from nerf2gs_plugin.data.process.capture_check import consistent_frames

        def score(rec) -> int:
            return consistent_frames(rec, job["check"], job["ordered"])
    mapped = sfm.reconstruct(work / "database.db", work / "frames", work / "distorted", len(job["names"]), opt, changed, progress,
                             content=job["content"], method=job["method"], score=score)
    times["mapping"] = time.perf_counter() - t
    return mapped, times


# nerf2gs_plugin.data's __init__ imports the parsers and torch (1.5 s of CPU); the SfM stages need
# none of it: the child imports its modules from an empty package of that name
_BOOT = ("import sys, types; pkg = types.ModuleType('nerf2gs_plugin.data'); pkg.__path__ = [{data!r}]; "
         "sys.modules['nerf2gs_plugin.data'] = pkg; "
         "from nerf2gs_plugin.data.process.sfm_worker import _child_main; _child_main({fd}, {parent})")


def _die_with_parent(parent: int) -> None:
    """SIGKILL when the parent dies (Linux; elsewhere the parent's clean-up is all there is)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died before the call
        os._exit(1)


def _child_main(fd: int, parent: int) -> None:
    _die_with_parent(parent)
    conn = Connection(fd)
    job = conn.recv()
    try:
        conn.send(("result", _stages(conn, job)))
    except KeyboardInterrupt:  # Ctrl-C reaches the whole process group: the parent reports it
        os._exit(130)
    except BaseException as e:  # noqa: BLE001 - every failure goes back to the parent
        tb = traceback.format_exc()
        try:
            pickle.dumps(e)
        except Exception:  # noqa: BLE001
            e = RuntimeError(str(e))
        conn.send(("error", e, tb))


def run_sfm_stages(work: Path, names: list[str], sfm_opts, focal: Optional[float], hashes: dict[str, str], content: str,
                   method: str, logs: Path, progress=None, check=None, ordered: bool = False) -> tuple:
    """Features, matching and mapping of ``work/frames`` in a child process: (``MapResult``, stage
    seconds). ``check``: the process options whose capture check ranks the mapping attempts (``ordered``: a
    video or sequential photos). A crash of the child is a :class:`DataError` naming the stage (and the disk when it is full)."""
    logs.mkdir(parents=True, exist_ok=True)
    ours, theirs = socket.socketpair()
    err_path = logs / f"sfm-stderr.{os.getpid()}.txt"
    job = {"work": str(work), "names": names, "sfm": sfm_opts, "focal": focal, "hashes": hashes, "content": content,
           "method": method, "logs": logs, "progress": progress is not None, "check": check, "ordered": ordered}
    with open(err_path, "wb") as err:
        proc = subprocess.Popen([sys.executable, "-c", _BOOT.format(data=str(Path(__file__).parents[1]), fd=theirs.fileno(), parent=os.getpid())],
                                pass_fds=[theirs.fileno()], stderr=err)
    theirs.close()
    conn = Connection(ours.detach())
    try:
        conn.send(job)
        stage, reply = _relay(conn, proc, progress)
    except BaseException:  # the parent interrupted (Ctrl-C, SIGTERM): the child goes too
        _stop(proc, conn, err_path, terminate=True)
        raise
    rc = _stop(proc, conn, err_path, terminate=False, keep_log=reply is None)
    if reply is not None and reply[0] == "result":
        return reply[1]
    if reply is not None:
        _raise_child_error(reply[1], reply[2], stage, work, err_path)
    if rc == 130:
        raise KeyboardInterrupt
    raise DataError(crash_line(stage, rc, work, err_path), work)


def _relay(conn: Connection, proc: subprocess.Popen, progress) -> tuple[str, Optional[tuple]]:
    """Pass the child's progress to ``progress`` until it replies or dies: (its last stage, its reply or None)."""
    stage, tasks = "start", {}
    while True:
        if not conn.poll(0.2):
            if proc.poll() is not None and not conn.poll(0):
                return stage, None
            continue
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return stage, None
        if msg[0] == "stage":
            stage = msg[1]
        elif msg[0] == "add_task" and progress is not None:
            tasks[msg[1]] = progress.add_task(msg[2], **msg[3])
        elif msg[0] == "update" and progress is not None:
            progress.update(tasks[msg[1]], **msg[2])
        elif msg[0] in ("result", "error"):
            return stage, msg


def _stop(proc: subprocess.Popen, conn: Connection, err_path: Path, terminate: bool, keep_log: bool = False) -> int:
    """Wait for the child (terminated first when asked); its stderr file goes when empty and not named in an error."""
    conn.close()
    if terminate and proc.poll() is None:
        proc.terminate()
    try:
        rc = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        rc = proc.wait()
    if not keep_log and err_path.is_file() and err_path.stat().st_size == 0:
        err_path.unlink()
    return rc


def _raise_child_error(e: BaseException, tb: str, stage: str, work: Path, err_path: Path) -> None:
    """Our own errors as they are; COLMAP's (a ``RuntimeError`` from pycolmap) one line, the traceback in the log."""
    if isinstance(e, (UserError, OSError, KeyboardInterrupt)):
        raise e
    with open(err_path, "a") as f:
        f.write(tb)
    if isinstance(e, RuntimeError):
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise DataError(f"COLMAP failed during the SfM ({stage}): {first}{_disk_hint(work)} (details: {err_path})", work) from None
    raise RuntimeError(f"the SfM stage '{stage}' failed in its worker process:\n{tb}")


def _disk_hint(work: Path) -> str:
    try:
        free = free_bytes(work)
    except OSError:
        return ""
    if free >= LOW_FREE_BYTES:
        return ""
    return f"; the disk is full: {free / 1e6:.0f} MB free on {mount_point(work)} (free space there, then run again: finished stages are reused)"


def colmap_message(err_path: Path) -> str:
    """COLMAP's own last words in the child's stderr: the ``what():`` of an uncaught exception, a glog
    ``Check failed`` / fatal line, else the last line that is not part of the stack dump."""
    try:
        lines = [ln.strip() for ln in err_path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    for key in ("what():", "Check failed", "] "):  # a glog line: "F1127 06:30:39.1 123 file.cc:45] message"
        hits = [ln for ln in lines if key in ln and not ln.startswith(("***", "@", "PC:"))]
        if hits:
            return hits[-1].split(key, 1)[1].strip()[:300] if key != "Check failed" else hits[-1].split("] ", 1)[-1][:300]
    rest = [ln for ln in lines if not ln.startswith(("***", "@", "PC:"))]
    return rest[-1][:300] if rest else ""


def crash_line(stage: str, rc: int, work: Path, err_path: Path) -> str:
    """One line for a child that died without a reply: the stage, the signal or status, COLMAP's message, the disk."""
    try:
        how = f"signal {signal.Signals(-rc).name}" if rc < 0 else f"exit status {rc}"
    except ValueError:
        how = f"signal {-rc}"
    said = colmap_message(err_path)
    return (f"COLMAP stopped during the SfM ({stage}) with {how}{': ' + said if said else ''}{_disk_hint(work)} "
            f"(details: {err_path}; run again to resume)")
