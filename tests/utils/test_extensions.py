"""The one C++ extension loader: a kernel that does not build is an error unless opted out."""

from __future__ import annotations

from pathlib import Path

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


def test_a_lock_left_by_a_killed_build_does_not_hang_the_next_one(tmp_path):
    """torch's own build lock, left fresh by a build that was killed (kill -9 mid-compile), is removed by
    the next process at once (it holds the OS build lock, so no build of ours is running) instead of
    torch waiting on it forever."""
    import os
    import subprocess
    import sys

    src = tmp_path / "broken.cpp"
    src.write_text("this is not C++;\n")
    ext = tmp_path / "ext"
    build = ext / extensions._build_name("nerf2gs_test_killed", [src], [])
    build.mkdir(parents=True)
    (build / "lock").write_text("")  # fresh: the age rule alone would wait 20 min
    code = ("from pathlib import Path; from nerf2gs_plugin.utils.extensions import load_extension; "
            f"print(load_extension('nerf2gs_test_killed', [Path({str(src)!r})]))")
    env = {**os.environ, "TORCH_EXTENSIONS_DIR": str(ext), OPT_OUT_ENV: "1"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "None", out.stderr  # built (and failed) instead of hanging
    assert "removed a stale kernel-build lock" in out.stderr and not (build / "lock").exists()


def test_the_build_lock_is_released_when_its_holder_is_killed(tmp_path):
    import fcntl
    import signal
    import subprocess
    import sys

    path = tmp_path / "k.build-lock"
    code = ("import sys, time; from pathlib import Path; from nerf2gs_plugin.utils.extensions import build_lock\n"
            f"with build_lock(Path({str(path)!r})) as held:\n    print(held, flush=True); time.sleep(600)")
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "True"
        with open(path, "a+") as f:  # held by the child: not ours
            with pytest.raises(BlockingIOError):
                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
        with extensions.build_lock(path) as held:  # the OS released it with the killed holder
            assert held
    finally:
        child.kill()


def test_cache_dir_is_where_torch_builds(monkeypatch, tmp_path):
    """The folder holding each kernel's build folder, with or without $TORCH_EXTENSIONS_DIR: the check
    for a built ``.so`` (no "compiling" line when there is one) and the stale-lock path read there. It
    was once torch's default one level up, so every process said it was compiling a built kernel."""
    import shutil

    from torch.utils.cpp_extension import _get_build_directory

    from nerf2gs_plugin.utils.extensions import extension_cache_dir

    monkeypatch.delenv("TORCH_EXTENSIONS_DIR", raising=False)
    probe = Path(_get_build_directory("nerf2gs_cache_dir_probe", verbose=False))  # torch makes the folder
    try:
        assert extension_cache_dir() / probe.name == probe
    finally:
        shutil.rmtree(probe, ignore_errors=True)
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path))
    assert extension_cache_dir() / "probe" == Path(_get_build_directory("probe", verbose=False))


def _tiny_module(build: Path, name: str) -> None:
    """A CPython extension ``name`` (plain C, built in a second) at ``build/name.so``: what torch's build leaves."""
    import subprocess
    import sysconfig

    build.mkdir(parents=True)
    c = build / "tiny.c"
    c.write_text('#include <Python.h>\nstatic struct PyModuleDef m = {PyModuleDef_HEAD_INIT, "%s", NULL, -1, NULL};\n'
                 "PyMODINIT_FUNC PyInit_%s(void) { PyObject* o = PyModule_Create(&m); "
                 'PyModule_AddIntConstant(o, "answer", 42); return o; }\n' % (name, name))
    subprocess.run(["cc", "-shared", "-fPIC", f"-I{sysconfig.get_paths()['include']}", str(c), "-o", str(build / f"{name}.so")],
                   check=True, capture_output=True)


@pytest.mark.skipif(not extensions.compiler_available(), reason="needs a C compiler")
def test_a_built_kernel_is_loaded_from_another_checkout_without_a_rebuild(tmp_path, monkeypatch, capsys):
    """The same sources in another folder, newer (a fresh clone): the build name pins their content, so the built
    module is loaded as it is; torch's load (ninja, which rebuilds when paths or times differ) is not called."""
    import os
    import time

    import torch.utils.cpp_extension as cpp

    monkeypatch.setattr(extensions, "_FAILED", {})
    monkeypatch.setattr(extensions, "_EXTS", {})
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    first, second = tmp_path / "a" / "k.cpp", tmp_path / "b" / "k.cpp"
    for f in (first, second):
        f.parent.mkdir()
        f.write_text("// the kernel\n")
    later = time.time() + 60
    os.utime(second, (later, later))
    build_name = extensions._build_name("nerf2gs_test_tiny", [first], [])
    assert extensions._build_name("nerf2gs_test_tiny", [second], []) == build_name  # content, not path or time
    _tiny_module(tmp_path / "ext" / build_name, build_name)

    def no_build(**kw):
        raise AssertionError("torch's load was called for a built kernel")

    monkeypatch.setattr(cpp, "load", no_build)
    assert load_extension("nerf2gs_test_tiny", [second]).answer == 42
    assert "compiling" not in capsys.readouterr().err


def test_the_build_name_follows_the_flags_and_the_cpu(tmp_path, monkeypatch):
    """-march=native builds for this CPU: another CPU (a home folder shared by machines) gets its own build."""
    src = tmp_path / "k.cpp"
    src.write_text("// the kernel\n")
    base, portable = extensions._build_name("k", [src], []), extensions._build_name("k", [src], [], ("-O3",))
    assert portable != base
    monkeypatch.setattr(extensions, "_cpu_key", lambda: "another CPU")
    assert extensions._build_name("k", [src], []) != base
    assert extensions._build_name("k", [src], [], ("-O3",)) == portable  # without -march=native the CPU does not count


def test_a_build_cut_short_is_made_again(tmp_path, monkeypatch):
    """A truncated module (a link that was killed) is removed, so torch's load builds it again."""
    build = tmp_path / "ext" / "k_0"
    build.mkdir(parents=True)
    (build / "k_0.so").write_bytes(b"\x7fELF")
    assert extensions._load_built("k_0", build) is None and not (build / "k_0.so").exists()
