"""Loop-closure pairs without a vocabulary file (``data/process/retrieval.py``) and the ground-plane
credibility check (``data/process/ground_check.py``)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from nerf2gs_plugin.data.process.retrieval import bow_vectors, loop_pairs, read_descriptors, write_pairs


def _place_descriptors(rng, n_places: int, per_image: int = 200) -> list[np.ndarray]:
    """Descriptors of places: each place has its own pool of 'visual words' (SIFT-like uint8 rows)."""
    pools = [rng.integers(0, 120, (40, 128)) for _ in range(n_places)]
    return pools, [np.clip(pools[p][rng.integers(0, 40, per_image)] + rng.integers(-6, 7, (per_image, 128)), 0, 255).astype(np.uint8)
                   for p in range(n_places)]


def test_a_walk_that_comes_back_is_closed_by_its_own_vocabulary():
    """12 photos around a loop: photos 10 and 11 see the places of photos 0 and 1 again; with a
    window of 3 only retrieval can pair them, and it does (and pairs nothing inside the window)."""
    rng = np.random.default_rng(0)
    _, desc = _place_descriptors(rng, 10)
    desc = desc + [desc[0][rng.permutation(200)], desc[1][rng.permutation(200)]]
    names = [f"{i:04d}.jpg" for i in range(12)]
    pairs = loop_pairs(names, bow_vectors(desc, words=64), overlap=3, k=1)
    assert ("0000.jpg", "0010.jpg") in pairs and ("0001.jpg", "0011.jpg") in pairs
    assert all(int(b[:4]) - int(a[:4]) > 3 for a, b in pairs)
    assert len(pairs) <= len(names)
    assert loop_pairs(names, bow_vectors(desc, words=64), overlap=3, k=0) == []
    assert loop_pairs(names[:4], bow_vectors(desc[:4], words=16), overlap=3, k=2) == []  # everything is in the window


def test_reads_descriptors_from_a_colmap_database(tmp_path):
    db = tmp_path / "database.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT)")
    con.execute("CREATE TABLE descriptors (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB)")
    d = np.arange(2 * 128, dtype=np.uint8).reshape(2, 128)
    con.execute("INSERT INTO images VALUES (1, 'a.jpg'), (2, 'b.jpg')")
    con.execute("INSERT INTO descriptors VALUES (1, 2, 128, ?), (2, 0, 128, NULL)", (d.tobytes(),))
    con.commit()
    con.close()
    got = read_descriptors(db)
    assert list(got) == ["a.jpg"] and np.array_equal(got["a.jpg"], d)
    assert write_pairs(tmp_path / "pairs.txt", [("a.jpg", "b.jpg")]).read_text() == "a.jpg b.jpg\n"


def test_a_tilted_plane_is_not_credible_and_process_asks_for_the_scale(tmp_path, monkeypatch):
    from nerf2gs_plugin.data.ground import GroundPlane
    from nerf2gs_plugin.data.process.ground_check import credible, tilt_deg
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions, metric_scale
    from nerf2gs_plugin.errors import DataError

    up = np.array([0.0, 1.0, 0.0])
    tilt = np.array([0.0, np.cos(np.radians(40)), np.sin(np.radians(40))])
    assert tilt_deg(tilt, up) == pytest.approx(40.0)
    assert credible(GroundPlane(up, 0.0, 50, 100, 1.0), up) is None
    assert "tilted 40 deg" in credible(GroundPlane(tilt, 0.0, 50, 100, 1.0), up)
    # what the fit returned on castle-P30 (its refit drifted past its own 30 deg gate): rejected
    import nerf2gs_plugin.data.ground as ground

    monkeypatch.setattr(ground, "estimate_metric_scale", lambda *a, **k: ground.MetricScale(0.7, tilt, "camera-height",
                                                                                           GroundPlane(tilt, 0.0, 50, 100, 2.3)))
    c2w = np.tile(np.eye(4)[:3], (6, 1, 1))
    pts = np.zeros((10, 3))
    with pytest.raises(DataError, match="tilted 40 deg.*pass --metres-per-unit"):
        metric_scale(pts, c2w, ProcessOptions(out=tmp_path))
    with pytest.warns(UserWarning, match="cameras' mean up"):
        s = metric_scale(pts, c2w, ProcessOptions(out=tmp_path, metres_per_unit=2.0))
    assert s.metres_per_unit == 2.0 and np.allclose(s.up, up) and s.source == "override"
    monkeypatch.setattr(ground, "estimate_metric_scale", lambda *a, **k: ground.MetricScale(0.7, up, "camera-height",
                                                                                           GroundPlane(up, 0.0, 50, 100, 2.3)))
    assert metric_scale(pts, c2w, ProcessOptions(out=tmp_path)).metres_per_unit == 0.7  # a level plane is kept
