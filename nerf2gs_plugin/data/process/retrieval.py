"""Loop-closure pairs without a vocabulary file: a bag of visual words learned on the capture itself.

Sequential matching links each frame to the next ``overlap`` ones, so a walk that comes back to
where it started (around a courtyard, a block) is never matched across the seam, and exhaustive
matching costs n^2 pairs. COLMAP's loop detection needs a pre-trained vocabulary tree (none can be
downloaded here). Instead: a few hundred RootSIFT descriptors per image, k-means on them (the
capture's own vocabulary), a TF-IDF word histogram per image, cosine similarity, and each image's
``k`` most similar images outside its sequential window become extra pairs (``k * n`` pairs).
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np


def _root_sift(d: np.ndarray) -> np.ndarray:
    d = d.astype(np.float32)
    d /= np.maximum(d.sum(1, keepdims=True), 1e-6)
    return np.sqrt(d)


def read_descriptors(db: Path) -> dict[str, np.ndarray]:
    """image name -> its SIFT descriptors [N, 128] (uint8) from a COLMAP database."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        rows = con.execute("SELECT images.name, descriptors.rows, descriptors.cols, descriptors.data "
                           "FROM images JOIN descriptors ON images.image_id = descriptors.image_id").fetchall()
    finally:
        con.close()
    return {name: np.frombuffer(data, np.uint8).reshape(r, c) for name, r, c, data in rows if r and data}


def bow_vectors(desc: list[np.ndarray], words: int = 256, sample: int = 300, assign: int = 1500, seed: int = 0) -> np.ndarray:
    """L2-normalised TF-IDF word histograms [n, words] from each image's descriptors."""
    import cv2

    rng = np.random.default_rng(seed)
    picks = [d[rng.choice(len(d), min(sample, len(d)), replace=False)] for d in desc]
    train = _root_sift(np.concatenate(picks))
    k = int(min(words, max(2, len(train) // 4)))
    cv2.setRNGSeed(seed)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 15, 1e-3)
    _, _, centres = cv2.kmeans(train, k, None, crit, 1, cv2.KMEANS_PP_CENTERS)
    c2 = (centres ** 2).sum(1)
    hist = np.zeros((len(desc), k), np.float32)
    for i, d in enumerate(desc):
        x = _root_sift(d[rng.choice(len(d), min(assign, len(d)), replace=False)])
        w = np.argmin(c2[None] - 2.0 * x @ centres.T, axis=1)
        hist[i] = np.bincount(w, minlength=k)
    tf = hist / np.maximum(hist.sum(1, keepdims=True), 1.0)
    idf = np.log(len(desc) / np.maximum((hist > 0).sum(0), 1.0))
    v = tf * idf
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-9)


def loop_pairs(names: list[str], vectors: np.ndarray, overlap: int, k: int) -> list[tuple[str, str]]:
    """Each image's ``k`` most similar images more than ``overlap`` places away in ``names`` order
    (the capture order), as unique (earlier, later) name pairs."""
    if k <= 0 or len(names) <= overlap + 1:
        return []
    sim = vectors @ vectors.T
    idx = np.arange(len(names))
    pairs: set[tuple[int, int]] = set()
    for i in range(len(names)):
        far = np.abs(idx - i) > overlap
        cand = idx[far]
        if len(cand) == 0:
            continue
        best = cand[np.argsort(-sim[i, far], kind="stable")[:k]]
        pairs.update((min(i, int(j)), max(i, int(j))) for j in best)
    return [(names[a], names[b]) for a, b in sorted(pairs)]


def write_pairs(path: Path, pairs: list[tuple[str, str]]) -> Path:
    """COLMAP's image-pair list (one "name1 name2" per line)."""
    import os

    tmp = Path(path).with_name(Path(path).name + ".tmp")
    tmp.write_text("".join(f"{a} {b}\n" for a, b in pairs))
    os.replace(tmp, path)
    return Path(path)
