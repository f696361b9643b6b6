"""The one C++ extension loader: a kernel that does not build is an error unless opted out."""

from __future__ import annotations

import pytest

from nerf2gs_plugin.utils import extensions
from nerf2gs_plugin.utils.extensions import OPT_OUT_ENV, KernelBuildError, load_extension


@pytest.fixture()
def broken_source(tmp_path, monkeypatch):
    monkeypatch.setattr(extensions, "_FAILED", {})
    monkeypatch.setattr(extensions, "_EXTS", {})
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    src = tmp_path / "broken.cpp"
    src.write_text("this is not C++;\n")
    return src


def test_a_failing_build_raises_without_the_opt_out(broken_source, monkeypatch, capsys):
    monkeypatch.delenv(OPT_OUT_ENV, raising=False)
    with pytest.raises(KernelBuildError, match=OPT_OUT_ENV):
        load_extension("nerf2gs_test_broken", [broken_source])
    err = capsys.readouterr().err
    assert "compiling the nerf2gs_test_broken kernel (first use, about 1 min)..." in err
    assert err.count("did not build") == 1
    with pytest.raises(KernelBuildError):  # tried once, raised every time, reason printed once
        load_extension("nerf2gs_test_broken", [broken_source])
    assert "did not build" not in capsys.readouterr().err


def test_the_opt_out_falls_back_to_none(broken_source, monkeypatch):
    monkeypatch.setenv(OPT_OUT_ENV, "1")
    assert load_extension("nerf2gs_test_broken", [broken_source]) is None
    assert extensions.extension_error("nerf2gs_test_broken").startswith(("RuntimeError", "CalledProcessError", "Exception"))
    assert "nerf2gs_test_broken" in extensions.failed_extensions()
    monkeypatch.setenv(OPT_OUT_ENV, "0")
    assert not extensions.kernels_opted_out()


def test_a_stale_build_lock_is_removed_a_fresh_one_kept(tmp_path, capsys):
    """A lock left by a killed build (older than any build) would make torch wait forever: removed,
    with one line; a lock of a build still running (fresh) is left alone."""
    import os
    import time

    from nerf2gs_plugin.utils.extensions import STALE_LOCK_SECONDS, _remove_stale_lock

    lock = tmp_path / "lock"
    lock.write_text("")
    assert not _remove_stale_lock(lock) and lock.exists()
    old = time.time() - STALE_LOCK_SECONDS - 5
    os.utime(lock, (old, old))
    assert _remove_stale_lock(lock) and not lock.exists()
    assert "stale kernel-build lock" in capsys.readouterr().err
    assert not _remove_stale_lock(lock)  # none there: nothing to do
