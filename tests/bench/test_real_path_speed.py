"""ns2gs-bench real-path-speed: the stage table's arithmetic and its results files (the path itself is
the bench's to run: minutes)."""

from __future__ import annotations

import json

from nerf2gs_bench.real_path_speed import RealPathOptions, Stages, cpu_seconds, write_results


def test_stages_split_moves_a_measured_part_into_its_own_row_before_the_stage():
    st = Stages()
    st.add("process", 10.0, 20.0)
    st.add("masks: mask maths", 100.0, 90.0)
    st.add("StreetNeRF", 50.0, 50.0)
    st.split("masks: mask maths", "masks: renders", 80.0, 85.0)
    assert list(st.rows) == ["process", "masks: renders", "masks: mask maths", "StreetNeRF"]
    assert st.rows["masks: mask maths"] == {"wall_s": 20.0, "cpu_s": 5.0}
    assert st.total("cpu_s") == 20.0 + 90.0 + 50.0 and st.total("wall_s") == 160.0


def test_stage_cpu_seconds_count_work_not_waiting():
    import time

    st = Stages()
    st.run("sleep", lambda: time.sleep(0.3))
    st.run("work", lambda: sum(i * i for i in range(2_000_000)))
    assert st.rows["sleep"]["cpu_s"] < 0.1 <= st.rows["sleep"]["wall_s"] + 0.2
    assert st.rows["work"]["cpu_s"] > 0.05
    assert cpu_seconds() > 0


def _old_doc() -> dict:
    """A results document with only the fields the first results had (options without the later ones)."""
    return {"options": {"frames": 100, "width": 480, "height": 360, "reference_steps": 1000, "streetnerf_steps": None,
                        "warm_start": True, "splatfacto_steps": None, "street_seed": 0, "movers": True},
            "machine": {}, "stage_seconds": {}, "total_cpu_s": 0.0, "total_wall_s": 0.0, "target_minutes": 12.0}


def test_a_kernel_compiled_inside_a_stage_is_named(monkeypatch):
    """A stage that compiled a kernel says so (a rebuild once hid a minute in Splatfacto's first step)."""
    from nerf2gs_bench.real_path_speed import results_md
    from nerf2gs_plugin.utils import extensions

    monkeypatch.setattr(extensions, "_BUILD_SECONDS", [0.0])
    st = Stages()
    st.run("StreetNeRF", lambda: None)
    st.run("Splatfacto", lambda: extensions._BUILD_SECONDS.__setitem__(0, extensions._BUILD_SECONDS[0] + 64.0))
    assert st.kernel_seconds == {"StreetNeRF": 0.0, "Splatfacto": 64.0}
    doc = _old_doc()
    assert "Kernels compiled during the run (wall s, inside the stages above): Splatfacto 64." in results_md(
        {**doc, "kernel_build_seconds": st.kernel_seconds})
    assert "No kernel was compiled during the run (loads 1.5 s in all)." in results_md(
        {**doc, "kernel_build_seconds": {"StreetNeRF": 1.5}})
    assert "compiled" not in results_md(doc)  # results of before the field say nothing


def test_results_state_machine_options_and_total(tmp_path):
    from nerf2gs_bench.machine import machine_info
    from dataclasses import asdict

    st = Stages()
    st.add("process (frames, SfM)", 60.0, 50.0)
    st.add("StreetNeRF", 120.0, 110.0)
    doc = {"options": asdict(RealPathOptions()), "machine": machine_info(), "registered": 100, "stage_seconds": st.rows,
           "total_wall_s": st.total("wall_s"), "total_cpu_s": st.total("cpu_s"), "target_minutes": 12.0, "load_average": [1.0, 1.0, 1.0]}
    write_results(tmp_path, doc)
    assert json.loads((tmp_path / "real_path_speed.json").read_text())["total_cpu_s"] == 160.0
    md = (tmp_path / "real_path_speed.md").read_text()
    assert "Machine: " in md and "| StreetNeRF | 110.0 | 120.0 |" in md and "160 (2.7 min)" in md
    assert "warm-started from the masks' reference" in md and "100/100" in md
    write_results(tmp_path, doc | {"warm_start_from": "masks-reference-second-pass"})
    assert "warm-started from the masks' second-pass reference" in (tmp_path / "real_path_speed.md").read_text()
    doc["options"] = asdict(RealPathOptions(capture="kitti", view_downscale=2, splatfacto_steps=4200))
    write_results(tmp_path, doc)  # the half-size views' path lands beside the default's, not over it
    md = (tmp_path / "real_path_speed_kitti_view_downscale2.md").read_text()
    assert "Splatfacto 4200 steps with NeRF views (the views from above at 1/2 size)" in md
    doc["frames_used"], doc["registered"] = 53, 46  # a capture shorter than --frames says how many it had
    write_results(tmp_path, doc)
    md = (tmp_path / "real_path_speed_kitti_view_downscale2.md").read_text()
    assert "kitti's first 53 frames" in md and "Registered 46/53." in md
    doc["kept"] = 40  # the capture check kept a stretch: said beside SfM's count
    write_results(tmp_path, doc)
    assert "Registered 46/53, 40 kept by the capture check." in (tmp_path / "real_path_speed_kitti_view_downscale2.md").read_text()
    doc["options"] = asdict(RealPathOptions(capture="nuscenes", crop_bottom=0.17))
    write_results(tmp_path, doc)  # another crop of the capture lands beside it, not over its default crop's results
    assert "the bottom 17% of each frame cut off" in (tmp_path / "real_path_speed_nuscenes_crop17.md").read_text()
    assert not (tmp_path / "real_path_speed_nuscenes.md").exists()


def test_a_real_capture_becomes_a_video_of_its_first_frames_at_the_stand_ins_pixel_count(tmp_path):
    import cv2
    import numpy as np
    import pytest

    from nerf2gs_bench.real_path_speed import make_capture, stem
    from nerf2gs_plugin.errors import ConfigError

    folder = tmp_path / "data" / "kitti"
    folder.mkdir(parents=True)
    for i in range(12):
        img = np.zeros((24, 80, 3), np.uint8)
        img[:, : 5 * (i + 1)] = 200  # a bar growing frame by frame: the order is visible in the video
        cv2.imwrite(str(folder / f"{i + 1:04d}.png"), img)
    opts = RealPathOptions(capture="kitti", data_root=tmp_path / "data", frames=10, width=48, height=36)
    video, fov, height = make_capture(tmp_path / "work", opts)
    assert (fov, height) == (81.0, 1.65) and stem(opts) == "real_path_speed_kitti" and stem(RealPathOptions()) == "real_path_speed"
    assert stem(RealPathOptions(capture="kitti", view_downscale=2)) == "real_path_speed_kitti_view_downscale2"
    cap, frames = cv2.VideoCapture(str(video)), []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    assert len(frames) == 10
    assert frames[0].shape == (22, 76, 3)  # 48 x 36 pixels' worth at 80:24, even sides
    bright = [int((f[11, :, 1] > 100).sum()) for f in frames]
    assert bright == sorted(bright) and bright[0] < bright[-1]
    with pytest.raises(ConfigError, match="unknown capture"):
        make_capture(tmp_path / "work", RealPathOptions(capture="nowhere", data_root=tmp_path / "data"))


def test_the_process_stage_runs_sfm_on_the_products_default_threads(tmp_path, monkeypatch):
    """The bench times what a user runs: COLMAP on all cores (SfmOptions' default), said in the results."""
    import pytest

    import nerf2gs_bench.real as br
    import nerf2gs_bench.real_path_speed as rps
    from nerf2gs_plugin.data.process.sfm import SfmOptions

    seen = {}

    class Stop(Exception):
        pass

    def fake_process(video, out, n, fov, height, num_threads=1):
        seen["threads"] = num_threads
        raise Stop

    monkeypatch.setattr(br, "process_capture", fake_process)
    monkeypatch.setattr(rps, "make_capture", lambda root, opts: (tmp_path / "drive.avi", 60.0, 1.6))
    monkeypatch.setattr(rps, "_video_size", lambda video: "480x360")
    with pytest.raises(Stop):
        rps.run(tmp_path / "root", tmp_path / "out", RealPathOptions())
    assert seen["threads"] == SfmOptions().num_threads == -1
    doc = _old_doc()
    assert "SfM threads 1;" in rps.results_md(doc)  # results of before the field: one thread
    assert "SfM threads all cores (the product's default);" in rps.results_md({**doc, "sfm_threads": -1})


def test_the_readme_path_is_the_benched_path(tmp_path):
    """The README's "Your own capture" commands train what real-path-speed times: StreetNeRF warm-started from
    the masks' reference with its default config, Splatfacto with the NeRF views at the augmentation's defaults
    (a flag in the README that the bench does not pass would make the bench's minutes and scores another path's)."""
    import shlex
    from pathlib import Path

    from nerf2gs_plugin.cli.train import parse_args

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    lines = [line.split("#")[0] for line in readme.splitlines() if line.startswith("ns2gs-train ") and "data/drive" in line]
    assert {line.split()[1] for line in lines} == {"streetnerf", "splatfacto"} and len(lines) >= 4  # the pipeline and "Your own capture"
    for sn_line, sf_line in zip([x for x in lines if x.split()[1] == "streetnerf"], [x for x in lines if x.split()[1] == "splatfacto"]):
        _check_readme_pair(parse_args(shlex.split(sn_line)[1:])[0], parse_args(shlex.split(sf_line)[1:])[0], tmp_path)


def _check_readme_pair(sn, sf, tmp_path):
    from nerf2gs_bench.real_path_speed import _trainer_config
    from nerf2gs_plugin.masking.mask_reference import default_reference_dir

    from nerf2gs_plugin.masking.second_pass import kept_run_dir

    assert RealPathOptions().warm_start and sn.warm_start == kept_run_dir(default_reference_dir(sn.data))  # what masks prints
    bench_sn = _trainer_config("streetnerf", sn.data, tmp_path / "sn", None, warm_start=sn.warm_start)
    assert (sn.pipeline, sn.max_num_iterations, sn.optimizers) == (bench_sn.pipeline, bench_sn.max_num_iterations, bench_sn.optimizers)
    bench_sf = _trainer_config("splatfacto", sf.data, tmp_path / "sf", None, augment_from=sf.augment_from)
    assert sf.augment_from is not None and sf.augment == bench_sf.augment
    assert (sf.pipeline, sf.max_num_iterations) == (bench_sf.pipeline, bench_sf.max_num_iterations)


def test_results_say_whether_splatfacto_trained_coarse_to_fine():
    """Two timings of the target differ by a fifth with coarse to fine on: the results name which it was."""
    import nerf2gs_bench.real_path_speed as rps

    doc = _old_doc()
    assert "coarse to fine" not in rps.results_md(doc) and "full size throughout" not in rps.results_md(doc)
    off = {**doc, "splatfacto_coarse_to_fine": {"num_downscales": 0, "resolution_schedule": 300}}
    on = {**doc, "splatfacto_coarse_to_fine": {"num_downscales": 2, "resolution_schedule": 300}}
    assert "with NeRF views (full size throughout)" in rps.results_md(off)
    assert "(coarse to fine: 1/4 size first, doubled every 300 steps)" in rps.results_md(on)
