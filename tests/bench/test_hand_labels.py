"""Hand labels of moving objects: the masks drawn from them, the IoU of the masks stage against them, the
capture view whose held-out frames are scored by them, and the real-captures record they fill."""

import json

import cv2
import numpy as np
import pytest

from nerf2gs_bench import hand_labels as hl

# source frames 128x80 whose bottom 16 rows (a bonnet) were cut; the capture's images are 64x32 (half size)
LABELS = {
    "size": [128, 80],
    "ego": [[0, 60], [126, 60], [126, 62], [0, 62]],
    "frames": {
        "000007": {"car": [[20, 10], [60, 10], [60, 50], [20, 50]], "ignore": [[[80, 10], [98, 10], [98, 28], [80, 28]]]},
        "000009": {"moving": [[[0, 0], [38, 0], [38, 18], [0, 18]]], "ignore": []},
    },
}


@pytest.fixture
def capture(tmp_path, monkeypatch):
    cap = tmp_path / "capture"
    (cap / "images").mkdir(parents=True)
    (cap / "masks" / "transient").mkdir(parents=True)
    splits = {"train": ["000006", "000007"], "test": ["000009", "000010"]}
    for stems in splits.values():
        for stem in stems:
            cv2.imwrite(str(cap / "images" / f"{stem}.png"), np.full((32, 64, 3), 128, np.uint8))
    monkeypatch.setattr(hl, "split_images", lambda c, split: [c / "images" / f"{s}.png" for s in splits[split]])
    return cap


def test_frame_masks_scale_both_label_formats_to_the_cropped_frame():
    car, leave_out = hl.frame_masks(LABELS["frames"]["000007"], LABELS, (64, 32), crop_rows=64)
    ys, xs = np.nonzero(car)
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == (10, 30, 5, 25)  # one polygon under its object's name
    assert leave_out[5:15, 40:50].all() and leave_out[30:, :].all()  # the ignore region and the bonnet
    assert not (car & leave_out).any() and leave_out[:, :35].sum() == 2 * 35  # nothing else: the bonnet's two rows
    moving, _ = hl.frame_masks(LABELS["frames"]["000009"], LABELS, (64, 32), crop_rows=64)
    assert moving[:10, :20].all() and moving.sum() == 10 * 20  # a list of polygons under 'moving'
    # drawn on a resized crop of the source (its first 64 rows at 32x16): to source pixels, then to the frame's
    on_crop = {"size": [32, 16], "source_size": [128, 80], "source_rows": 64, "frames": {}}
    car_on_crop, _ = hl.frame_masks({"car": [[5, 2], [15, 2], [15, 12], [5, 12]]}, on_crop, (64, 32), crop_rows=64)
    in_source, _ = hl.frame_masks({"car": [[20, 8], [60, 8], [60, 48], [20, 48]]}, {"size": [128, 80]}, (64, 32), crop_rows=64)
    assert np.array_equal(car_on_crop, in_source) and in_source.sum() == 21 * 21


def test_moving_iou_is_pooled_over_labelled_training_frames(capture):
    car, _ = hl.frame_masks(LABELS["frames"]["000007"], LABELS, (64, 32), crop_rows=64)
    est = np.zeros((32, 64), np.uint8)
    est[5:15, 10:31] = 255  # the car's top half
    est[5:15, 40:50] = 255  # an ignore region: counts neither way
    cv2.imwrite(str(capture / "masks" / "transient" / "000007.png"), est)
    cv2.imwrite(str(capture / "masks" / "transient" / "000006.png"), np.full((32, 64), 255, np.uint8))  # not labelled
    s = hl.moving_scores(capture, LABELS, crop_rows=64)
    assert s["frames"] == ["000007"]
    assert s["precision"] == 1.0 and s["recall"] == pytest.approx(10 * 21 / car.sum())
    assert s["iou"] == pytest.approx(s["recall"])
    cv2.imwrite(str(capture / "masks" / "transient" / "000007.png"), car.astype(np.uint8) * 255)
    assert hl.moving_scores(capture, LABELS, crop_rows=64)["iou"] == 1.0
    assert hl.moving_scores(capture, {**LABELS, "frames": {"000009": LABELS["frames"]["000009"]}}, 64) is None  # held out only
    # frames named by their index in a video: the labels' key from the stem by the caller's rule
    shifted = hl.moving_scores(capture, LABELS, 64, key_of=lambda stem: f"{int(stem) + 1:06d}")
    assert shifted["frames"] == ["000006"] and shifted["recall"] == 1.0 and shifted["precision"] < 0.5  # 000006's mask is all set


def test_completion_bound_marks_whole_only_the_objects_the_masks_cover_enough(capture):
    """The bound: a labelled object the masks cover by more than ``hit`` counts as marked whole; one below
    it stays as marked; what the masks mark off the objects stays as a false alarm."""
    labels = {**LABELS, "frames": {"000007": {**LABELS["frames"]["000007"], "walker": [[100, 40], [120, 40], [120, 58], [100, 58]]}}}
    car, _ = hl.frame_masks({"car": labels["frames"]["000007"]["car"]}, labels, (64, 32), crop_rows=64)
    walker, _ = hl.frame_masks({"walker": labels["frames"]["000007"]["walker"]}, labels, (64, 32), crop_rows=64)
    est = np.zeros((32, 64), bool)
    est[5:10, 10:31] = True  # a quarter of the car
    ys, xs = np.nonzero(walker)
    est[ys[0], xs[0]] = True  # one pixel of the walker
    est[0:2, 0:4] = True  # a false alarm
    cv2.imwrite(str(capture / "masks" / "transient" / "000007.png"), est.astype(np.uint8) * 255)
    plain = hl.moving_scores(capture, labels, crop_rows=64)
    b = hl.completion_bound(capture, labels, 64, hl.frame_key, hit=0.2)
    assert b["recall"] == pytest.approx((car.sum() + 1) / (car.sum() + walker.sum())) and b["recall"] > plain["recall"]
    assert b["precision"] == pytest.approx((car.sum() + 1) / (car.sum() + 1 + 8))
    assert hl.completion_bound(capture, labels, 64, hl.frame_key, hit=0.0)["recall"] == 1.0  # one pixel is more than 0
    assert hl.completion_bound(capture, labels, 64, hl.frame_key, hit=1.0)["iou"] == pytest.approx(plain["iou"])


def test_labelled_view_scores_held_out_frames_by_their_labels(capture, tmp_path):
    cv2.imwrite(str(capture / "masks" / "transient" / "000007.png"), np.zeros((32, 64), np.uint8))
    view = tmp_path / "view"
    assert hl.labelled_view(capture, LABELS, view, crop_rows=64) == ["000009"]
    m = cv2.imread(str(view / "masks" / "transient" / "000009.png"), cv2.IMREAD_GRAYSCALE) > 0
    assert m[:10, :20].all() and m[30:].all() and m.sum() == 10 * 20 + 2 * 64  # moving and the bonnet leave the score
    assert (view / "masks" / "transient" / "000007.png").resolve() == (capture / "masks" / "transient" / "000007.png")
    assert (view / "images").resolve() == (capture / "images").resolve()
    assert not (view / "masks" / "transient" / "000010.png").exists()  # unlabelled: not scored on static pixels


def test_missing_labels_are_named(tmp_path, monkeypatch):
    from nerf2gs_plugin.errors import DataError

    monkeypatch.setattr(hl, "LABELS_DIR", tmp_path)
    with pytest.raises(DataError, match="hand labels 'nowhere'") as e:
        hl.load_labels("nowhere")
    assert "nowhere.json" in str(e.value)
    (tmp_path / "ok.json").write_text(json.dumps(LABELS))
    assert hl.load_labels("ok")["size"] == [128, 80]


def test_committed_labels_name_their_frames_and_source_size():
    for name in ("kitti_moving", "nuscenes_moving_heldout", "nuscenes_moving"):
        labels = hl.load_labels(name)
        assert len(labels["size"]) == 2 and labels["frames"]
        for key, entry in labels["frames"].items():
            assert hl.frame_key(key) == key
            polys = [p for v in entry.values() for p in hl.polygons(v)]
            assert all(p.ndim == 2 and p.shape[1] == 2 and (p >= 0).all() and (p <= labels["size"]).all() for p in polys)


def test_real_captures_record_takes_the_hand_labels():
    import nerf2gs_bench.real_captures as rc

    static = {rc.REFERENCE: 24.0, rc.TARGET: 25.0, rc.AUGMENTED: 24.5}
    hand = {"labels": "x", "moving": {"iou": 0.3, "precision": 0.5, "recall": 0.4, "frames": ["000007"]},
            "static": static, "static_frames": ["000009"]}
    rec = rc.hand_labels(hand)
    assert rec["moving_iou"] == 0.3 and rec["static_psnr"] == static and rec["static_psnr_delta"] == pytest.approx(-0.5)
    rec = rc.hand_labels({**hand, "moving": None, "static_frames": [], "static": dict.fromkeys(static)})
    assert rec["moving_iou"] is None and "static_psnr_delta" not in rec  # the eval's own figure stays
    line = rc.label_lines([{"capture": "c", "hand_labels": hand}])[-1]
    assert "IoU 0.300 (precision 0.50, recall 0.40) on 000007" in line and "25.00 / 24.50 / 24.00" in line


def test_real_captures_scores_a_capture_with_labels(tiny_scene, tmp_path, monkeypatch):
    """The bench's hand-label step on a real dataset folder: its training frames' masks scored against a labels
    file named by the capture; no held-out frame is labelled, so no static PSNR is made up."""
    import nerf2gs_bench.real_captures as rc

    est = cv2.imread(str(tiny_scene / "masks" / "transient" / "train_002.png"), cv2.IMREAD_GRAYSCALE) > 0
    ys, xs = np.nonzero(est)
    box = [[int(xs.min()), int(ys.min())], [int(xs.max()), int(ys.min())], [int(xs.max()), int(ys.max())], [int(xs.min()), int(ys.max())]]
    (tmp_path / "tiny.json").write_text(json.dumps({"size": [est.shape[1], est.shape[0]], "frames": {"002": {"patch": box}}}))
    monkeypatch.setattr(hl, "LABELS_DIR", tmp_path)
    cap = rc.Capture("tiny", "tiny", "tests", "CC0", "tiny scene", camera_height=1.5, labels=("tiny",))
    hand = rc.hand_label_scores(cap, tiny_scene, {})
    assert hand["moving"]["frames"] == ["train_002"] and hand["moving"]["recall"] == 1.0
    assert hand["moving"]["iou"] == pytest.approx(est.sum() / ((ys.max() - ys.min() + 1) * (xs.max() - xs.min() + 1)))
    assert hand["static_frames"] == [] and set(hand["static"].values()) == {None}


def test_label_sets_of_the_same_frames_merge(tmp_path, monkeypatch):
    """Several label sets of one capture make one document: their frames together, the first named winning
    a frame both label; sets of differently sized frames are refused, naming the file."""
    from nerf2gs_plugin.errors import DataError

    square = lambda x: [[x, 0], [x + 4, 0], [x + 4, 4], [x, 4]]  # noqa: E731
    for name, frames in (("a", {"001": {"car": square(0)}, "002": {"car": square(0)}}), ("b", {"002": {"car": square(8)}, "003": {"car": square(8)}})):
        (tmp_path / f"{name}.json").write_text(json.dumps({"size": [16, 8], "frames": frames}))
    (tmp_path / "c.json").write_text(json.dumps({"size": [32, 8], "frames": {}}))
    monkeypatch.setattr(hl, "LABELS_DIR", tmp_path)
    both = hl.merged_labels(["a", "b"])
    assert sorted(both["frames"]) == ["001", "002", "003"] and both["size"] == [16, 8]
    assert hl.polygons(both["frames"]["002"]["car"])[0][0].tolist() == [0, 0]  # a's, the first named
    with pytest.raises(DataError, match="c.json"):
        hl.merged_labels(["a", "c"])
