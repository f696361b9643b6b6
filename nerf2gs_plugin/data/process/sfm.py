"""Stages 2-4 on pycolmap (CPU SIFT): features, matching, incremental mapping.

Resumable: the COLMAP database is reused (images that already have features are skipped by COLMAP
itself; matching writes a marker keyed by its options), the mapping output is reused when its
marker matches. Feature extraction runs in chunks so the progress bar moves.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal, Optional

from nerf2gs_plugin.errors import DataError

Matching = Literal["auto", "sequential", "exhaustive"]


@dataclass
class SfmOptions:
    """SfM options (flags without a prefix: --matching, --overlap, ...)."""

    matching: Matching = "auto"
    """auto: sequential for a video, exhaustive for up to ``exhaustive_max`` photos, sequential beyond."""
    exhaustive_max: int = 40
    overlap: int = 10
    """Sequential matching's window. With --quadratic-overlap (the default, as COLMAP's and nerfstudio's)
    pycolmap 4 pairs each frame with the frames 1, 2, 4, ..., 2^(overlap-1) after it, so any overlap
    above log2 of the frame count gives the same pairs (on 30 frames, overlap 5, 10 and 20 all match the
    frames 1, 2, 4, 8 and 16 apart); --no-quadratic-overlap: the frames 1..overlap after it,
    then those hops too."""
    quadratic_overlap: bool = True
    vocab_tree: Optional[Path] = None
    """Sequential matching: a COLMAP vocabulary tree file turns on loop detection (none is shipped)."""
    loop_pairs: int = 0
    """Sequential matching without --vocab-tree: each frame is also matched with its N most similar
    frames outside the window (a bag of words learned on the capture's own SIFT features: closes loops
    with no vocabulary file; 0: off, the default: a drive that never comes back gains nothing, and on
    castle-P30 they cost SfM time for hardly better poses)."""
    max_image_size: int = 1600
    """SIFT runs on images shrunk to this longest side (speed; the full image is still undistorted)."""
    max_features: int = 4096
    """SIFT features per image at most."""
    mapping_attempts: int = 4
    """Incremental mapping runs (at most) while under 90% of the frames register as one consistent stretch (the
    capture check's; see --join-attempts): COLMAP's defaults, then its own initial pair under looser
    initialisation thresholds, then initial pairs at other points of the capture.
    Runs after the first hold a known focal (EXIF or --fov-deg) fixed, as --no-refine-intrinsics does; a run
    whose refined focal ran away from the known one (over 2x off) counts as failed."""
    camera_model: str = "SIMPLE_RADIAL"
    """COLMAP camera model estimated by the SfM (one camera shared by all frames)."""
    refine_intrinsics: bool = True
    """Refine the focal length and distortion in bundle adjustment. Off (--no-refine-intrinsics) keeps
    the --fov-deg / EXIF prior: a known camera, and much steadier mapping on small or low-texture frames."""
    join_attempts: int = 4
    """More mapping runs (looser initialisation, COLMAP's own initial pair, another random seed each) when a
    run registered half of the frames but no run keeps 90% of them as one consistent stretch in the capture
    check (joined at two scales or in the wrong place): on a forward drive the seed decides where the mapper
    joins; the run that keeps the most frames is taken (0: off)."""
    num_threads: int = -1
    """Threads for SIFT, matching and mapping (-1: all cores; 1 makes a run repeatable: COLMAP's
    multi-threaded mapping is not deterministic)."""


def choose_matching(opt: SfmOptions, num_images: int, is_video: bool) -> str:
    if opt.matching != "auto":
        return opt.matching
    return "sequential" if is_video or num_images > opt.exhaustive_max else "exhaustive"


def _marker(path: Path, key: dict) -> bool:
    try:
        return json.loads(path.read_text()) == key
    except (OSError, json.JSONDecodeError):
        return False


def _write_marker(path: Path, key: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(key, sort_keys=True))
    os.replace(tmp, path)


FEATURES_RECORD = "features.json"
"""Beside the database: the content hash of each frame its features were extracted from."""


def content_key(hashes: dict[str, str]) -> str:
    """One digest of the frames' names and contents (keys the matching and mapping markers)."""
    import hashlib

    return hashlib.sha1(json.dumps(hashes, sort_keys=True).encode()).hexdigest()


def extract(db: Path, image_dir: Path, names: list[str], opt: SfmOptions, focal_px: Optional[float], progress=None, chunk: int = 16,
            hashes: Optional[dict[str, str]] = None) -> None:
    """SIFT features for ``names`` into ``db`` (one shared camera; EXIF focal as its prior). With the
    frames' content ``hashes``, a database holding features of other content under a name starts over."""
    import pycolmap

    ext = pycolmap.FeatureExtractionOptions()
    ext.max_image_size = opt.max_image_size
    ext.num_threads = opt.num_threads
    ext.sift.max_num_features = opt.max_features
    done: set[str] = set()
    record_path = db.with_name(FEATURES_RECORD)
    if db.is_file():
        recorded = {}
        if hashes is not None:
            try:
                recorded = json.loads(record_path.read_text())
            except (OSError, ValueError):
                pass
        with pycolmap.Database.open(str(db)) as d:
            images = d.read_all_images()
            done = {im.name for im in images if d.exists_keypoints(im.image_id)}
            stale = any(im.name not in set(names) or (hashes is not None and recorded.get(im.name) != hashes.get(im.name))
                        for im in images)
        if stale:  # another frame set (other --num-frames/--fps, replaced photos): start the database over
            for p in db.parent.glob(db.name + "*"):
                p.unlink()
            done = set()
    if hashes is not None:  # before extracting: what the database will hold features of
        _write_marker(record_path, {n: hashes[n] for n in names})
    todo = [n for n in names if n not in done]
    task = progress.add_task("features (SIFT)", total=len(names), completed=len(names) - len(todo), stats="") if progress else None
    for s in range(0, len(todo), chunk):
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = opt.camera_model
        cam_ids = []
        if db.is_file():
            with pycolmap.Database.open(str(db)) as d:
                cam_ids = [c.camera_id for c in d.read_all_cameras()]
        if cam_ids:
            reader.existing_camera_id = int(cam_ids[0])
        elif focal_px is not None:
            reader.camera_params = _camera_params(opt.camera_model, focal_px, image_dir / todo[s])
        pycolmap.extract_features(db, image_dir, image_names=todo[s:s + chunk], camera_mode=pycolmap.CameraMode.SINGLE,
                                  reader_options=reader, extraction_options=ext, device=pycolmap.Device.cpu)
        if task is not None:
            progress.update(task, advance=len(todo[s:s + chunk]))


def _camera_params(model: str, f: float, image: Path) -> str:
    """A COLMAP params string with focal ``f`` and the principal point at the centre."""
    import cv2

    img = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
    h, w = img.shape[:2]
    cx, cy = w / 2.0, h / 2.0
    extra = {"SIMPLE_PINHOLE": [], "PINHOLE": None, "SIMPLE_RADIAL": [0.0], "RADIAL": [0.0, 0.0], "OPENCV": None}.get(model, [])
    if model == "PINHOLE":
        vals = [f, f, cx, cy]
    elif model == "OPENCV":
        vals = [f, f, cx, cy, 0.0, 0.0, 0.0, 0.0]
    else:
        vals = [f, cx, cy] + (extra or [])
    return ",".join(f"{v:.6f}" for v in vals)


def match(db: Path, method: str, opt: SfmOptions, marker: Path, progress=None, content: str = "") -> bool:
    """Match (or reuse the matches when ``marker`` records the same method, options and frames:
    ``content``, :func:`content_key` of the frames, else their names)."""
    import hashlib

    import pycolmap

    with pycolmap.Database.open(str(db)) as d:
        names = sorted(im.name for im in d.read_all_images())
    key = {"images": content or hashlib.sha1("|".join(names).encode()).hexdigest(), "method": method, "overlap": opt.overlap, "vocab_tree": str(opt.vocab_tree or ""), "max_features": opt.max_features,
           "max_image_size": opt.max_image_size, "loop_pairs": opt.loop_pairs if method == "sequential" and opt.vocab_tree is None else 0,
           **({} if opt.quadratic_overlap or method != "sequential" else {"quadratic_overlap": False})}  # absent: earlier markers stay valid
    if _marker(marker, key):
        return False
    task = progress.add_task(f"matching ({method})", total=1, stats="") if progress else None
    m = pycolmap.FeatureMatchingOptions()
    m.num_threads = opt.num_threads
    if method == "sequential":
        if opt.vocab_tree is not None and not Path(opt.vocab_tree).is_file():
            raise DataError("vocabulary tree file does not exist (--vocab-tree)", opt.vocab_tree)
        # the linear window, then the quadratic hops (pairs matched already are skipped), or the hops alone
        for quadratic in ([True] if opt.quadratic_overlap else [False, True]):
            pair = pycolmap.SequentialPairingOptions()
            pair.overlap = opt.overlap
            pair.quadratic_overlap = quadratic
            if opt.vocab_tree is not None and quadratic:
                pair.loop_detection = True
                pair.vocab_tree_path = str(opt.vocab_tree)
            pycolmap.match_sequential(db, matching_options=m, pairing_options=pair, device=pycolmap.Device.cpu)
        if opt.vocab_tree is None and opt.loop_pairs > 0:
            _match_loop_pairs(db, names, opt, m, marker.with_name("loop_pairs.txt"))
    elif method == "exhaustive":
        pycolmap.match_exhaustive(db, matching_options=m, device=pycolmap.Device.cpu)
    else:
        raise DataError(f"unknown matching '{method}' (auto, sequential, exhaustive)", "--matching")
    _write_marker(marker, key)
    if task is not None:
        progress.update(task, advance=1)
    return True


def _match_loop_pairs(db: Path, names: list[str], opt: SfmOptions, m, pairs_file: Path) -> int:
    """Match the retrieval pairs (:mod:`.retrieval`) that the sequential window left out."""
    import pycolmap

    from nerf2gs_plugin.data.process.frames import _natural_key
    from nerf2gs_plugin.data.process.retrieval import bow_vectors, loop_pairs, read_descriptors, write_pairs

    desc = read_descriptors(db)
    order = sorted((n for n in names if n in desc), key=_natural_key)  # capture order
    pairs = loop_pairs(order, bow_vectors([desc[n] for n in order]), opt.overlap, opt.loop_pairs)
    if pairs:
        imported = pycolmap.ImportedPairingOptions()
        imported.match_list_path = str(write_pairs(pairs_file, pairs))
        pycolmap.match_image_pairs(db, matching_options=m, pairing_options=imported, device=pycolmap.Device.cpu)
    return len(pairs)


FIXED_PAIR_TRIALS = 3

JOIN_RETRY_REGISTERED = 0.5
"""``join_attempts`` run when a model registered this share of the frames (the capture registers: what it
keeps is a matter of where the mapper joins it, not of a capture that cannot register)."""
"""Mapping runs from a pair of our choice: tries of that pair (only RANSAC's randomness differs)."""


FOCAL_RATIO_MAX = 2.0
"""A refined focal more than this factor from the known one (EXIF / --fov-deg) ran away: a forward drive
constrains the focal weakly, and the mapper can settle on half of it with every frame registered."""


def focal_ran_away(rec, known: float) -> bool:
    """Whether any camera of ``rec`` has a focal more than :data:`FOCAL_RATIO_MAX` from ``known``."""
    return any(not known / FOCAL_RATIO_MAX <= c.mean_focal_length() <= known * FOCAL_RATIO_MAX for c in rec.cameras.values())


@dataclass
class MapResult:
    model_dir: Path
    registered: int
    total: int
    points: int
    reused: bool


def reconstruct(db: Path, image_dir: Path, out_dir: Path, total: int, opt: SfmOptions, matches_changed: bool, progress=None,
                content: str = "", method: str = "", score: Optional[Callable[[Any], int]] = None) -> MapResult:
    """Incremental mapping; the best model is kept as ``out_dir/0`` (reused when its marker records the
    same options and frames' ``content`` and the matches did not change). Models rank by a known focal kept,
    then ``score`` (the frames the capture check keeps: a model joined at two scales or in the wrong place
    ranks by its longest consistent stretch; None: the frames registered), then the frames registered;
    attempts go on while the best scores under 90% of ``total``."""
    import pycolmap

    marker = out_dir / "done.json"
    final = out_dir / "0"
    # the attempts and the ranking decide which model is kept: another setting maps again
    key = {"total": total, "camera_model": opt.camera_model, "refine_intrinsics": opt.refine_intrinsics,
           "mapping_attempts": opt.mapping_attempts, "join_attempts": opt.join_attempts if score is not None else 0,
           "ranked_by": "registered" if score is None else "capture check", **({"frames": content} if content else {})}
    if not matches_changed and _marker(marker, key) and (final / "cameras.bin").is_file():
        rec = pycolmap.Reconstruction(str(final))
        return MapResult(final, rec.num_reg_images(), total, rec.num_points3D(), True)
    shutil.rmtree(out_dir, ignore_errors=True)
    work = out_dir.with_name(out_dir.name + ".tmp")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    task = progress.add_task("mapping (incremental)", total=total, stats="") if progress else None
    count = [0]

    def on_image() -> None:
        count[0] += 1
        if task is not None:
            progress.update(task, completed=min(count[0] + 1, total), stats=f"{count[0] + 1} registered")

    with pycolmap.Database.open(str(db)) as d:
        ids = [int(im.image_id) for im in sorted(d.read_all_images(), key=lambda im: im.name)]
        priors = [c.mean_focal_length() for c in d.read_all_cameras() if c.has_prior_focal_length]
    known_focal = priors[0] if priors else None

    def rank(r) -> tuple[bool, int, int]:  # a model whose focal ran away from the known one ranks below any other
        registered = r.num_reg_images()
        return (known_focal is None or not focal_ran_away(r, known_focal), registered if score is None else score(r), registered)

    best, best_rank, most = None, None, 0
    planned = max(opt.mapping_attempts, 1)
    attempts, attempt = planned, -1
    while attempt + 1 < attempts:
        attempt += 1
        fixed_pair = 1 < attempt < planned
        # The incremental mapper can start from a poor initial pair on small or repetitive captures
        # and stall after a few images: another seed usually registers everything.
        options = pycolmap.IncrementalPipelineOptions()
        options.num_threads = opt.num_threads
        options.multiple_models = True
        options.random_seed = attempt
        # Retries hold a known focal (EXIF or --fov-deg): refined on the first two or three images, focal
        # and distortion can run away (focal x3, k ~ 1e3) and nothing more registers; which run does that
        # turns on a few matches that differ from run to run (multi-threaded matching).
        if not opt.refine_intrinsics or (attempt > 0 and known_focal is not None):
            options.ba_refine_focal_length = options.ba_refine_extra_params = False
            options.mapper.abs_pose_refine_focal_length = options.mapper.abs_pose_refine_extra_params = False
        if attempt > 0:
            # accept what a forward-moving camera gives: smaller angles, fewer inliers. COLMAP's default
            # initial pair needs a 16 deg triangulation angle, which the closely spaced frames of a forward
            # drive never reach (almost nothing registers); with these, every frame does
            options.mapper.init_min_tri_angle = 8.0
            options.mapper.init_max_forward_motion = 0.99
            options.mapper.abs_pose_min_num_inliers = 15
        if fixed_pair and len(ids) > 6:  # its own choice stalled again: start from a pair at another point of the capture
            a = ((attempt - 1) * len(ids)) // (max(opt.mapping_attempts - 1, 2) + 1)
            options.init_image_id1, options.init_image_id2 = ids[a], ids[min(a + 2, len(ids) - 1)]
            # COLMAP retries a given pair up to init_num_trials (200) times when its model stays too
            # small: the same pair each time, a minute of mapping on a 14-frame capture for nothing
            options.init_num_trials = FIXED_PAIR_TRIALS
        count[0] = 0
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        models = pycolmap.incremental_mapping(db, image_dir, work, options=options, next_image_callback=on_image)
        for r in sorted(models.values(), key=lambda r: -r.num_reg_images()):
            if best_rank is not None and r.num_reg_images() < best_rank[1]:
                break  # it cannot keep more frames than the best keeps
            r_rank = rank(r)
            if best_rank is None or r_rank > best_rank:
                best, best_rank = r, r_rank
        if best is not None and best_rank[1] >= 0.9 * total and best_rank[0]:
            break
        most = max([most, *(r.num_reg_images() for r in models.values())])
        if attempts == planned and score is not None and most >= JOIN_RETRY_REGISTERED * total:
            attempts += max(opt.join_attempts, 0)  # it registers, but breaks: other seeds join it elsewhere
        if task is not None:
            kept = "" if score is None or best_rank is None else f", {best_rank[1]} consistent"
            progress.update(task, completed=0, stats=f"retry {attempt + 1}: {best.num_reg_images() if best else 0} registered{kept}")
    if best is None:
        shutil.rmtree(work, ignore_errors=True)
        hint = "" if method == "exhaustive" else "--matching exhaustive, "  # not when it was exhaustive already
        raise DataError(f"registration failed: 0 of {total} images registered (no initial pair; try {hint}more frames, or less blur)",
                        image_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    final.mkdir(parents=True, exist_ok=True)
    best.write(str(final))
    shutil.rmtree(work, ignore_errors=True)
    _write_marker(marker, key)
    if task is not None:
        progress.update(task, completed=total, stats=f"{best.num_reg_images()} registered")
    return MapResult(final, best.num_reg_images(), total, best.num_points3D(), False)
