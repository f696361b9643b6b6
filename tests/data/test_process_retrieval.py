"""Loop-closure pairs without a vocabulary file (``data/process/retrieval.py``) and the ground-plane
scale ``process`` asks for when no ground plane is found."""

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


def test_no_level_plane_and_process_asks_for_the_scale(tmp_path):
    """Sparse points only on a 40 deg plane below the cameras (a roof line, the foot of walls): no
    ground plane within ``MAX_TILT_DEG`` (``data/ground.py``, the one place of that limit), so
    ``process`` asks for ``--metres-per-unit``, and with it takes up from the cameras."""
    from nerf2gs_plugin.data.process.capture_check import metric_scale
    from nerf2gs_plugin.data.process.pipeline import ProcessOptions
    from nerf2gs_plugin.errors import DataError

    rng = np.random.default_rng(0)
    c2w = np.tile(np.eye(4)[:3], (6, 1, 1))  # OpenGL: up is +y
    c2w[:, 0, 3] = np.linspace(-2, 2, 6)
    c2w[:, 1, 3] = 1.5
    u, x = rng.uniform(0, 3, 400), rng.uniform(-3, 3, 400)
    t = np.radians(40.0)
    pts = np.stack([x, u * np.sin(t) - 1.0, -u * np.cos(t)], 1)  # rises 40 deg away from the cameras
    with pytest.raises(DataError, match="within 30 deg.*pass --metres-per-unit"):
        metric_scale(pts, c2w, ProcessOptions(out=tmp_path))
    with pytest.warns(UserWarning, match="up is the cameras' own"):
        s = metric_scale(pts, c2w, ProcessOptions(out=tmp_path, metres_per_unit=2.0))
    assert s.metres_per_unit == 2.0 and np.allclose(s.up, [0, 1, 0]) and s.source == "override"
    level = np.stack([x, np.full(400, -0.0) + rng.normal(0, 0.005, 400), -u], 1)  # a level ground: kept
    s = metric_scale(level, c2w, ProcessOptions(out=tmp_path))
    assert s.source == "camera-height" and s.metres_per_unit == pytest.approx(1.0, rel=0.02)