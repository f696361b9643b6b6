"""The motion benches' per-kind breakdown (``nerf2gs_bench/mover_kinds.py``): every mover pixel of a synthetic
frame has exactly one kind, the kinds follow the street's cars' directions, and the static pixels a mask marks
are split into those on the ground and those beside a mover."""

from __future__ import annotations

import torch

from nerf2gs_bench import mover_kinds as mk
from nerf2gs_plugin.data.synthetic.layout import Car


def test_every_mover_pixel_has_one_kind_and_traffic_follows_its_direction():
    cars = [Car(0.0, -1.75, 1.0, 5.0, (1, 0, 0)), Car(5.0, 1.75, -1.0, 5.0, (0, 1, 0))]
    n_static, n_moving = 10, 3 * len(cars) + 6 + 4  # cars, lead car, cyclist, two pedestrians
    obj = torch.arange(-2, n_static + n_moving + 3).reshape(1, -1)  # sky, ground, static boxes, movers, crowns
    kinds = mk.kinds_of_hits(obj, n_moving, n_static, cars)
    assert set(kinds) == set(mk.KINDS)
    stacked = torch.stack([kinds[k][0] for k in mk.KINDS]).int()
    moving = (obj[0] >= n_static) & (obj[0] < n_static + n_moving)
    assert torch.equal(stacked.sum(0), moving.int())  # each mover pixel one kind; nothing static has one
    ids = lambda k: (obj[0][kinds[k][0]] - n_static).tolist()  # noqa: E731
    assert ids("traffic, same way") == [0, 1, 2] and ids("traffic, oncoming") == [3, 4, 5]
    assert ids("lead car") == [6, 7, 8] and ids("cyclist") == [9, 10, 11] and ids("pedestrians") == [12, 13, 14, 15]


def test_kind_ids_on_a_street_frame_match_the_exact_transient_mask():
    c2w = torch.tensor([[0.0, 0.0, -1.0, -10.0], [-1.0, 0.0, 0.0, -1.75], [0.0, 1.0, 0.0, 3.0]])  # looks along +x
    frame = {"transform_matrix": c2w.tolist() + [[0.0, 0.0, 0.0, 1.0]], "time": 0.0}
    kinds = mk.kind_ids(0, [frame], (40.0, 40.0, 48.0, 27.0, 96, 54))[0]
    assert kinds["lead car"].any() and kinds["cyclist"].any()  # both ride ahead of the camera, in view
    assert sum(int(v.sum()) for v in kinds.values()) == int(torch.stack(list(kinds.values())).any(0).sum())


def test_static_marked_splits_ground_and_near():
    gt = torch.zeros(1, 100, dtype=torch.bool)
    gt[0, :10] = True
    pred = torch.zeros_like(gt)
    pred[0, 5:20] = True  # 10 static pixels beside the mover
    pred[0, 80:90] = True  # 10 far from it
    ground = torch.zeros_like(gt)
    ground[0, 10:20] = True
    s = mk.static_marked([pred], [gt], [ground])
    assert s["static_marked"] == 20
    assert s["static_marked_near_share"] == 0.5 and s["static_marked_ground_share"] == 0.5
    r = mk.recall_by_kind([pred], [{k: (gt if k == "lead car" else torch.zeros_like(gt)) for k in mk.KINDS}])
    assert r["lead car"] == {"pixels": 10, "recall": 0.5} and r["cyclist"] == {"pixels": 0, "recall": 0.0}
