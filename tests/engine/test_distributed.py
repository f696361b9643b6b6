"""Data-parallel training: 2 CPU ranks (gloo) against one process that draws the same batches.

The single-process equivalent of an R-rank run is ``--machine.batches-per-rank R`` in one process:
batch k of a step is drawn by sampling stream k (seeded seed + k, the stream rank k owns in the
R-rank run, which seeds its DataManager with seed + rank) and starts from the step's global random
state (as every rank does); the K gradients are summed and divided by K (the ranks' all-reduce
divided by R); the densification statistics of the batches are accumulated into the one
strategy (the ranks sum theirs before every refine decision). Both runs therefore take the same
cameras in the same order and the same updates: their parameters agree to float rounding (the
order of the statistics' sums differs), and densification must have changed the primitive count
on the way, so the combined statistics are exercised. Checkpoints keep every stream's sampling
state, so a 2-rank checkpoint continues in one process (2 batches per step) exactly, and back.
"""

from __future__ import annotations

import dataclasses
import os
import time

import pytest
import torch

from nerf2gs_plugin.cli.train import train
from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
from nerf2gs_plugin.engine.launch import MachineConfig, launch
from nerf2gs_plugin.registry import get_method

STEPS = 12


@pytest.fixture(autouse=True)
def one_thread(monkeypatch):
    """One thread per process (2 ranks on 2 cores), and deterministic kernels on both sides."""
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _config(method, data, out, *, ranks=1, batches=1, steps=STEPS, **kw):
    cfg = get_method(method).config
    pipe = cfg.pipeline
    if method == "splatfacto":  # densify from step 3, every 3 steps, with an opacity reset at 9
        model = pipe.model
        pipe = dataclasses.replace(pipe, model=dataclasses.replace(model, strategy=dataclasses.replace(
            model.strategy, warmup_length=3, refine_every=3, reset_alpha_every=9, max_pause_after_reset=0,
            stop_screen_size_at=100)))
    else:  # streetnerf: a small ray batch
        pipe = dataclasses.replace(pipe, datamanager=dataclasses.replace(pipe.datamanager, rays_per_batch=256))
    # CPU ranks whatever the machine: these compare ranks with one process, and a one-GPU machine has no GPU for rank 1
    kw.setdefault("device", "cpu")
    return dataclasses.replace(cfg, data=data, output_dir=out, max_num_iterations=steps, steps_per_save=4,
                               keep_all_checkpoints=True, steps_per_eval_image=0, progress=False, timestamp="run",
                               pipeline=pipe, machine=MachineConfig(num_devices=ranks, batches_per_rank=batches), **kw)


def _run(cfg):
    launch(train, cfg)
    return cfg.get_run_dir()


def _model(run_dir, step):
    ckpt = [p for p in list_checkpoints(run_dir) if p.name == f"step-{step:09d}.ckpt"][0]
    return load_checkpoint(ckpt)["model"]


def _assert_same(a, b, atol):
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].shape == b[k].shape, (k, a[k].shape, b[k].shape)
        assert torch.allclose(a[k].float(), b[k].float(), atol=atol, rtol=0), (k, float((a[k].float() - b[k].float()).abs().max()))


def _count(run_dir, step):
    return _model(run_dir, step)["gauss.means"].shape[0]


def test_two_ranks_equal_one_process_with_two_batches_and_checkpoints_cross_over(tiny_scene, tmp_path):
    """One process (2 batches per step) to step 11; 2 ranks from its step-3 checkpoint to step 11;
    one process again from the 2-rank step-7 checkpoint. Checkpoints fall on steps whose densification
    statistics are not used later (refined at 3, reset-pause at 9): checkpoints do not hold them."""
    one = _run(_config("splatfacto", tiny_scene, tmp_path / "one", batches=2))
    two = _run(_config("splatfacto", tiny_scene, tmp_path / "two", ranks=2, load_checkpoint=one / "checkpoints/step-000000003.ckpt"))
    assert _count(two, 11) != _count(one, 3)  # densified at step 6 on the statistics of both ranks
    _assert_same(_model(one, 7), _model(two, 7), 1e-6)
    _assert_same(_model(one, 11), _model(two, 11), 1e-5)
    back = _run(_config("splatfacto", tiny_scene, tmp_path / "back", batches=2, load_checkpoint=two / "checkpoints/step-000000007.ckpt"))
    _assert_same(_model(back, 11), _model(two, 11), 1e-5)
    # a plain single-process run (one batch per step) takes a 2-rank checkpoint too
    plain = _run(_config("splatfacto", tiny_scene, tmp_path / "plain", steps=9, load_checkpoint=two / "checkpoints/step-000000007.ckpt"))
    assert [p.name for p in list_checkpoints(plain)] == ["step-000000008.ckpt"]


def test_streetnerf_two_ranks_equal_one_process_with_two_batches(tiny_scene, tmp_path):
    one = _run(_config("streetnerf", tiny_scene, tmp_path / "one", batches=2, steps=3))
    two = _run(_config("streetnerf", tiny_scene, tmp_path / "two", ranks=2, steps=3))
    _assert_same(_model(one, 2), _model(two, 2), 1e-5)


def _fail_on_rank_1(config):
    """Rank 1 raises at its third step, while rank 0 waits for it in the gradient all-reduce."""
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.utils.collectives import rank

    if rank() == 1:
        original = Trainer.train_step

        def failing(self, step):
            if step == 2:
                raise RuntimeError("boom at step 2")
            return original(self, step)

        Trainer.train_step = failing
    train(config)


def test_a_failing_rank_stops_all_with_its_rank_named(tiny_scene, tmp_path, capsys):
    t0 = time.monotonic()
    with pytest.raises(SystemExit) as e:
        launch(_fail_on_rank_1, _config("splatfacto", tiny_scene, tmp_path, ranks=2))
    assert e.value.code == 1
    assert time.monotonic() - t0 < 60
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err == ["error: rank 1: RuntimeError: boom at step 2"], err
    assert not list_checkpoints(tmp_path / os.path.basename(tiny_scene) / "splatfacto" / "run")


def test_replicas_that_differ_are_an_error_naming_the_rank(tiny_scene, tmp_path, monkeypatch):
    """The hash check of every save: rank 1's parameters are not rank 0's."""
    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.errors import TrainingDiverged
    from nerf2gs_plugin.utils import collectives

    trainer = Trainer(_config("splatfacto", tiny_scene, tmp_path))
    trainer.setup()
    state = trainer.pipeline.model.state_dict()
    other = {k: v.clone() for k, v in state.items()}
    other["gauss.means"][7, 1] += 1e-6
    assert collectives.param_digest(state) == collectives.param_digest({k: v.clone() for k, v in state.items()})
    assert collectives.param_digest(state) != collectives.param_digest(other)
    monkeypatch.setattr(collectives, "all_gather_object", lambda obj: [obj, collectives.param_digest(other)])
    with pytest.raises(TrainingDiverged, match=r"replicas differ at step 3: the parameters of rank\(s\) 1 are not rank 0's"):
        trainer.check_replicas(3)


def test_a_rank_killed_while_writing_its_failure_is_not_read(tmp_path):
    """The parent kills the other ranks once one has failed: a record cut short (an empty file) is skipped, and the
    failing rank's own record names the failure."""
    from nerf2gs_plugin.engine.launch import _first_failure

    (tmp_path / "rank0").write_text("")  # killed mid-write
    (tmp_path / "rank1").write_text(f"{time.time()!r}\t0\t1\tdata error: bad flag")
    assert _first_failure(str(tmp_path), [], 1, 0) == (1, 1, "data error: bad flag")
