"""Data-parallel launch: the ``--machine.*`` flags, the process group, and the worker processes.

Three ways to run, one code path per rank (:func:`run_rank`):

* one process (the default, ``--machine.num-devices 1``): no process group at all;
* ``torchrun --nproc-per-node N -m nerf2gs_plugin.cli.train METHOD ...``: torchrun starts the
  ranks and sets ``RANK`` / ``WORLD_SIZE`` / ``LOCAL_RANK`` / ``MASTER_ADDR`` / ``MASTER_PORT``;
* ``ns2gs-train METHOD --machine.num-devices N [--machine.num-machines M --machine.machine-rank I
  --machine.dist-url tcp://HOST:PORT]`` (nerfstudio's flags): :func:`launch` spawns the N local
  ranks itself with the same variables, so they run exactly as under torchrun.

gloo on CPU, NCCL on CUDA (rank ``LOCAL_RANK`` takes ``cuda:LOCAL_RANK``). A failure on any rank
stops every rank and is reported as one line ``error: rank R: <what>``.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional
from urllib.parse import urlparse

from nerf2gs_plugin.errors import ConfigError, Terminated, UserError

ENV_VARS = ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT")


@dataclass
class MachineConfig:
    """Data-parallel training on torch.distributed (--machine.*): every rank holds the whole model,
    draws its own batch, and gradients are averaged, so N ranks train with an N-times larger batch."""

    num_devices: int = 1
    """Ranks per machine (GPUs on CUDA, processes on a CPU); more than 1 launches them."""
    num_machines: int = 1
    """Machines taking part; start the same command on each with its --machine.machine-rank."""
    machine_rank: int = 0
    """This machine's index (0 .. num-machines - 1); machine 0 hosts the rendezvous."""
    dist_url: str = "auto"
    """Rendezvous tcp://HOST:PORT on machine 0; auto: a free port on this machine (one machine only)."""
    batches_per_rank: int = 1
    """Batches each rank draws per step, each from its own sampling stream (stream s = rank x K + k,
    seeded seed + s), gradients averaged over all of them: one process with K batches reproduces a
    K-rank run (the same draws, the same averaged update)."""

    @property
    def world_size(self) -> int:
        return self.num_devices * self.num_machines


def check_machine_config(m: MachineConfig) -> None:
    for name in ("num_devices", "num_machines", "batches_per_rank"):
        if getattr(m, name) < 1:
            raise ConfigError(f"must be >= 1, got {getattr(m, name)}", f"--machine.{name.replace('_', '-')}")
    if not 0 <= m.machine_rank < m.num_machines:
        raise ConfigError(f"must be in [0, {m.num_machines - 1}], got {m.machine_rank}", "--machine.machine-rank")
    if m.num_machines > 1 and m.dist_url == "auto":
        raise ConfigError("several machines need the rendezvous address of machine 0 (tcp://HOST:PORT)", "--machine.dist-url")


def env_world_size() -> int:
    """The world size torchrun (or :func:`launch`) set for this process; 1 when none."""
    return int(os.environ.get("WORLD_SIZE", "1"))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rendezvous(m: MachineConfig) -> tuple[str, int]:
    if m.dist_url == "auto":
        return "127.0.0.1", _free_port()
    url = urlparse(m.dist_url)
    if url.scheme != "tcp" or not url.hostname or not url.port:
        raise ConfigError(f"expected tcp://HOST:PORT, got {m.dist_url!r}", "--machine.dist-url")
    return url.hostname, url.port


# ---------------------------------------------------------------------------------------- one rank
def rank_device(config: Any, local_rank: int) -> str:
    """The device of a rank: ``cuda:LOCAL_RANK`` when the run uses CUDA, else the configured one."""
    import torch

    wants_cuda = config.device.startswith("cuda") or (config.device == "auto" and torch.cuda.is_available())
    if not wants_cuda:
        return "cpu"
    if local_rank >= torch.cuda.device_count():
        raise ConfigError(f"rank {local_rank} of this machine has no GPU ({torch.cuda.device_count()} visible)", "--machine.num-devices")
    return f"cuda:{local_rank}"


def _is_peer_failure(e: BaseException) -> bool:
    """An error raised because another rank went away (its socket closed), not a failure of this rank."""
    import torch.distributed as dist

    if isinstance(e, getattr(dist, "DistError", ())):
        return True
    text = str(e)
    return isinstance(e, RuntimeError) and any(s in text for s in ("Connection closed by peer", "Connection reset by peer", "Broken pipe"))


def _one_line(e: BaseException) -> str:
    if isinstance(e, UserError):
        return str(e)
    if isinstance(e, OSError) and e.strerror:
        return f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text[:300]}" if text else type(e).__name__


def _failure(e: BaseException) -> tuple[int, bool, str]:
    """(exit status, raised because another rank went away, one line) of what a rank raised."""
    if isinstance(e, SystemExit):
        if isinstance(e.code, int) or e.code is None:
            return e.code or 0, False, f"exited with code {e.code}"
        return 1, False, str(e.code)
    if isinstance(e, Terminated):
        return 128 + signal.SIGTERM, False, "terminated"
    if isinstance(e, KeyboardInterrupt):
        return 130, False, "interrupted"
    return 2 if isinstance(e, UserError) else 1, _is_peer_failure(e), _one_line(e)


def run_rank(fn: Callable[..., Any], config: Any, *args: Any, error_dir: Optional[str] = None) -> None:
    """Run ``fn(config, *args)`` as the rank the environment names (torchrun's variables): join the
    process group, take this rank's device, keep ranks other than 0 quiet (no stdout, no warnings),
    and turn a failure into one line ``error: rank R: ...`` (under :func:`launch` the launcher
    prints it) and a non-zero exit."""
    import torch
    import torch.distributed as dist

    rank, local_rank, world = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0")), int(os.environ["WORLD_SIZE"])
    code = 0
    try:
        device = rank_device(config, local_rank)
        config = dataclasses.replace(config, device=device)
        if device.startswith("cuda"):
            torch.cuda.set_device(device)
        dist.init_process_group("nccl" if device.startswith("cuda") else "gloo", init_method="env://", rank=rank, world_size=world)
        if rank == 0:
            from nerf2gs_plugin.warn import install_plain_warnings

            install_plain_warnings()  # a spawned rank is a fresh interpreter: one plain line per warning, as ns2gs-* print them
        else:
            import warnings

            from nerf2gs_plugin.warn import Nerf2gsWarning

            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - for the life of the process
            warnings.simplefilter("ignore", Nerf2gsWarning)
        fn(config, *args)
    except BaseException as e:  # noqa: BLE001 - every failure of a rank stops the run with one line
        code, peer, line = _failure(e)
        if not code:
            pass  # sys.exit(0) inside: a success
        elif error_dir is not None:
            # whole or not at all: the parent kills the other ranks once one has failed, maybe mid-write
            tmp = Path(error_dir, f".rank{rank}.tmp")
            tmp.write_text(f"{time.time()!r}\t{int(peer)}\t{code}\t{line}")
            os.replace(tmp, Path(error_dir, f"rank{rank}"))
        elif isinstance(e, KeyboardInterrupt):
            if rank == 0:
                print(line, file=sys.stderr, flush=True)
        elif not peer:
            print(f"error: rank {rank}: {line}", file=sys.stderr, flush=True)
    finally:
        if dist.is_initialized() and code == 0:
            dist.destroy_process_group()
    if code or error_dir is not None:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        # no interpreter teardown: on failure it could wait on the dead ranks; on success a spawned rank's
        # static destructors met a still-joinable communication thread once ("terminate called without an
        # active exception", exit -6 after the run had finished and its group was destroyed)
        os._exit(code)


def _spawned(local_rank: int, env: dict[str, str], fn: Callable[..., Any], config: Any, args: tuple, error_dir: str,
             threads: Optional[int]) -> None:
    os.environ.update(env)
    os.environ["RANK"] = str(int(env["RANK"]) + local_rank)
    os.environ["LOCAL_RANK"] = str(local_rank)
    if threads is not None:
        import torch

        torch.set_num_threads(threads)
    run_rank(fn, config, *args, error_dir=error_dir)


# ---------------------------------------------------------------------------------------- launcher
def launch(fn: Callable[..., Any], config: Any, *args: Any) -> None:
    """Run ``fn(config, *args)`` on ``config.machine``'s ranks: in this process when there is one
    rank or torchrun started it, else in ``num_devices`` spawned processes of this machine."""
    m: MachineConfig = config.machine
    check_machine_config(m)
    if env_world_size() > 1:  # started by torchrun (or a launcher like it): this process is one rank
        run_rank(fn, config, *args)
        return
    if m.world_size == 1:
        fn(config, *args)
        return
    import torch.multiprocessing as mp

    addr, port = _rendezvous(m)
    env = {"RANK": str(m.machine_rank * m.num_devices), "WORLD_SIZE": str(m.world_size),
           "MASTER_ADDR": addr, "MASTER_PORT": str(port)}
    # a CPU run shares the cores among its ranks unless the user said how many threads
    threads = None if "OMP_NUM_THREADS" in os.environ else max(1, (os.cpu_count() or 1) // m.num_devices)
    ctx = mp.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="ns2gs-ranks-") as error_dir:
        procs = [ctx.Process(target=_spawned, args=(i, env, fn, config, args, error_dir, threads), daemon=False)
                 for i in range(m.num_devices)]
        for p in procs:
            p.start()
        failed = _wait(procs)
        if failed is not None:
            for p in procs:
                if p.is_alive():
                    p.kill()
            for p in procs:
                p.join()
            rank, code, line = _first_failure(error_dir, procs, failed, int(env["RANK"]))
            if code in (130, 128 + signal.SIGTERM):
                print("interrupted" if code == 130 else "terminated", file=sys.stderr)
            else:
                print(f"error: rank {rank}: {line}", file=sys.stderr)
            sys.exit(code)


def _wait(procs: list) -> Optional[int]:
    """Wait until every process has ended well (None) or one has failed (its index)."""
    from multiprocessing.connection import wait

    pending = {p.sentinel: i for i, p in enumerate(procs)}
    while pending:
        try:
            ready = wait(list(pending))
        except KeyboardInterrupt:  # Ctrl-C reached the ranks too: let rank 0 save, then report
            for p in procs:
                p.join()
            return next((i for i, p in enumerate(procs) if p.exitcode), None)
        for s in ready:
            i = pending.pop(s)
            procs[i].join()
            if procs[i].exitcode != 0:
                return i
    return None


def _first_failure(error_dir: str, procs: list, failed: int, first_rank: int) -> tuple[int, int, str]:
    """(rank, exit code, line) of the rank that failed first for a reason of its own; a rank that only
    saw another one go away is reported only when nothing else is known."""
    found = []
    for path in Path(error_dir).glob("rank*"):
        fields = path.read_text().split("\t", 3)
        if len(fields) == 4:
            t, peer, code, line = fields
            found.append((int(peer), float(t), int(path.name[4:]), int(code), line))
    if found:
        peer, _, rank, code, line = min(found)
        # the same failure on several ranks (a bad flag, a missing file): the lowest rank names it
        rank = min(r for p, _, r, _, text in found if p == peer and text == line)
        return rank, code, line
    code = procs[failed].exitcode
    return first_rank + failed, 1, f"exited with code {code}" + (" (killed: out of memory?)" if code == -9 else "")
