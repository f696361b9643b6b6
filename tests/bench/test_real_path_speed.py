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
    assert "warm-started from the masks reference" in md and "100/100" in md
