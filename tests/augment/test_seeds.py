"""Initial points where only the additional views see the scene (augment/seeds.py, Pipeline + Splatfacto)."""

import numpy as np
import torch

from nerf2gs_plugin.augment.datamanager import AugmentConfig, AugmentedDataManager, Reference
from nerf2gs_plugin.augment.seeds import lifted_points, seed_points, thin_on_grid
from nerf2gs_plugin.cameras import Cameras, look_at
from nerf2gs_plugin.data.ply import write_ply_points
from nerf2gs_plugin.engine.pipeline import Pipeline
from nerf2gs_plugin.registry import get_method


def test_thin_on_grid_keeps_one_mean_point_per_free_voxel():
    xyz = torch.tensor([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2], [2.5, 0.5, 0.5]])
    rgb = torch.tensor([[1.0, 0, 0], [0.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    occupied = torch.tensor([[2.9, 0.9, 0.9]])  # in the voxel of the last point
    pts, cols = thin_on_grid(xyz, rgb, occupied, 1.0)
    order = pts[:, 0].argsort()
    assert torch.allclose(pts[order], torch.tensor([[0.2, 0.2, 0.2], [1.5, 0.2, 0.2]]))
    assert torch.allclose(cols[order], torch.tensor([[0.5, 0, 0], [0, 1.0, 0]]))


def test_seed_points_respects_the_count_and_off():
    g = torch.Generator().manual_seed(0)
    xyz = torch.rand(5000, 3, generator=g) * torch.tensor([10.0, 10.0, 0.0])  # a 10 x 10 ground
    rgb = torch.rand(5000, 3, generator=g)
    pts, _ = seed_points(xyz, rgb, None, 200)
    assert 50 <= len(pts) <= 200  # the finest grid under the count: not far under it
    assert len(seed_points(xyz, rgb, None, 0)[0]) == 0


def _down_camera(h: float = 5.0) -> Cameras:
    c2w = look_at(torch.tensor([[0.0, 0.0, h]]), torch.tensor([[0.5, 0.0, 0.0]]), torch.tensor([0.0, 0.0, 1.0]))
    return Cameras(c2w, fx=16.0, fy=16.0, cx=16.0, cy=12.0, width=32, height=24)


def _plane_depth(cam: Cameras, point: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """``[H, W, 1]`` ray distance to the plane through ``point`` with ``normal`` (0 where the ray misses it)."""
    rays = cam.generate_rays(0)
    o, d = rays.origins.float(), rays.directions.float()
    denom = d @ normal
    t = ((point - o) @ normal) / denom.clamp(max=-1e-6)
    t = torch.where(denom < -1e-3, t, torch.zeros_like(t))
    return t.reshape(int(cam.height[0]), int(cam.width[0]), 1)


def test_lifted_points_lie_on_the_surface_and_inside_the_box():
    cam = _down_camera()
    depth = _plane_depth(cam, torch.zeros(3), torch.tensor([0.0, 0.0, 1.0]))
    xyz, rgb = lifted_points(cam, [depth], [torch.full((24, 32, 3), 0.4)], "ray")
    assert len(xyz) == 12 * 16 and torch.allclose(xyz[:, 2], torch.zeros(len(xyz)), atol=1e-4)
    box = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    inside, _ = lifted_points(cam, [depth], [torch.full((24, 32, 3), 0.4)], "ray", box)
    assert 0 < len(inside) < len(xyz) and bool((inside.abs() <= 1.0).all())


def test_augmented_target_starts_with_points_where_only_the_views_from_above_see(tiny_scene, tmp_path):
    """The tiny scene's sparse points moved into one corner of its ground: the rest of the ground is bare for
    the target, and the reference (a plane renderer) sees it from above; the target must start with points there."""
    import shutil

    data = tmp_path / "scene"
    shutil.copytree(tiny_scene, data)
    g = np.random.default_rng(0)
    corner = np.concatenate([g.uniform(-3, -2, (50, 2)), np.zeros((50, 1))], 1)
    write_ply_points(data / "points.ply", corner, np.full((50, 3), 120, np.uint8))
    cfg = get_method("splatfacto").config

    def plane(camera):
        h, w = int(camera.height[0]), int(camera.width[0])
        return {"rgb": torch.full((h, w, 3), 0.5), "depth": _plane_depth(camera, ground_point, normal),
                "accumulation": torch.ones(h, w, 1)}

    def wrap(dm):
        return AugmentedDataManager(dm, Reference(plane, "plane:1", tmp_path / "ref", depth_along="ray"),
                                    AugmentConfig(delta_h=3.0, theta_pitch=45.0, composites=False, min_coverage=0.0))

    plain = Pipeline(cfg.pipeline, data, "cpu")
    td = plain.datamanager.train_data
    sparse = td.points3D_xyz.float()
    ground_point, normal = sparse.mean(0), torch.nn.functional.normalize(td.up.float(), dim=0)
    augmented = Pipeline(cfg.pipeline, data, "cpu", wrap_datamanager=wrap)
    means = augmented.model.gauss["means"].detach()
    assert plain.model.num_primitives() == len(sparse)
    added = means[len(sparse):]
    assert 0 < len(added) <= len(sparse) * 1000 // 50  # at most seed-points x max(sparse, 1000)
    assert torch.allclose((added - ground_point) @ normal, torch.zeros(len(added)), atol=1e-3)  # on the ground
    far = torch.cdist(added, sparse).min(1).values > 3 * torch.cdist(sparse, sparse).topk(2, largest=False).values[:, 1].max()
    assert bool(far.any())  # and where the sparse points are not
    off = Pipeline(cfg.pipeline, data, "cpu", wrap_datamanager=lambda dm: AugmentedDataManager(
        dm, Reference(plane, "plane:1", tmp_path / "ref", depth_along="ray"),
        AugmentConfig(delta_h=3.0, theta_pitch=45.0, composites=False, min_coverage=0.0, seed_points=0.0)))
    assert off.model.num_primitives() == len(sparse)


def test_surfels_take_initial_points_too(tiny_scene):
    """2DGS (two tangent scales per surfel) grows by the points as Splatfacto does, and still renders."""
    pipeline = Pipeline(get_method("2dgs").config.pipeline, tiny_scene, "cpu")
    model = pipeline.model
    n = model.num_primitives()
    xyz = pipeline.datamanager.train_data.points3D_xyz[:5].float() + 0.01
    assert model.add_initial_points(xyz, torch.full((5, 3), 0.5)) == 5
    assert model.num_primitives() == n + 5 and model.gauss["scales"].shape == (n + 5, 2)
    out = model.render_camera(pipeline.datamanager.train_images.cameras[0])
    assert torch.isfinite(out["rgb"]).all()


def test_scaffold_gs_anchors_the_initial_points_on_its_grid(tiny_scene):
    """Scaffold-GS makes anchors on the voxels of the points that hold none yet (one per voxel), and still renders."""
    pipeline = Pipeline(get_method("scaffold-gs").config.pipeline, tiny_scene, "cpu")
    model = pipeline.model
    n, voxel = model.num_primitives(), float(model.voxel)
    old = model.anchor["anchors"].detach().clone()
    far = old.amax(0) + 10 * voxel
    xyz = torch.stack([far, far + 0.1 * voxel, far + torch.tensor([3 * voxel, 0.0, 0.0])])  # two voxels
    xyz = torch.cat([xyz, old[:4]])  # voxels already anchored: skipped
    assert model.add_initial_points(xyz, torch.full((len(xyz), 3), 0.5)) == 2
    assert model.num_primitives() == n + 2 and model.anchor["offsets"].shape[0] == n + 2
    added = model.anchor["anchors"][n:]
    assert torch.allclose(torch.round(added / voxel) * voxel, added) and bool((torch.cdist(added, far[None]) < 4 * voxel).all())
    assert torch.isfinite(model.anchor["scaling"]).all()
    out = model.render_camera(pipeline.datamanager.train_images.cameras[0])
    assert torch.isfinite(out["rgb"]).all()


def test_seed_points_per_family_give_the_first_family_its_own_grid(tmp_path):
    """A low view of a small patch and a high view of a wide one: on one grid the wide view coarsens the
    patch's points; per family the first family's seeds are those of its views alone, the second's stay clear of them."""
    from types import SimpleNamespace

    from nerf2gs_plugin.augment.seeds import views_seed_points

    centres, heights = torch.tensor([[0.0, 0.0, 3.0], [40.0, 0.0, 60.0]]), torch.tensor([3.0, 60.0])
    cams = Cameras(look_at(centres, centres * torch.tensor([1.0, 1.0, 0.0]) + torch.tensor([0.5, 0.0, 0.0]),
                           torch.tensor([0.0, 0.0, 1.0])), fx=16.0, fy=16.0, cx=16.0, cy=12.0, width=32, height=24)
    images = [torch.full((24, 32, 3), 0.3), torch.full((24, 32, 3), 0.7)]
    for j in range(2):
        np.save(tmp_path / f"{j:05d}_depth.npy", _plane_depth(cams[j], torch.zeros(3), torch.tensor([0.0, 0.0, 1.0])).numpy())
    manifest = SimpleNamespace(num_extra=2, extra_families=["birds-eye", "lane-shift"],
                               extra_png=lambda j, raw: tmp_path / f"{j:05d}.png")
    extra = type("Extra", (), {"cameras": cams, "image": staticmethod(lambda j: images[j]), "__len__": lambda self: 2})()
    train = SimpleNamespace(points3D_xyz=None, scene_box=None)
    ratio = 0.05  # 50 points each
    joint, _ = views_seed_points(manifest, extra, "ray", train, ratio)
    per, per_rgb = views_seed_points(manifest, extra, "ray", train, ratio, per_family=True)
    first = seed_points(*lifted_points(cams[0], [torch.from_numpy(np.load(tmp_path / "00000_depth.npy"))], images[:1], "ray"), None, 50)
    assert torch.allclose(per[: len(first[0])], first[0]) and len(per) > len(first[0])
    assert torch.allclose(per_rgb[len(first[0]):], torch.full((len(per) - len(first[0]), 3), 0.7))  # the second family's
    near = lambda p: int((p[:, :2].norm(dim=1) < heights[0]).sum())  # noqa: E731
    assert near(per) > near(joint)  # the patch keeps its fine points
