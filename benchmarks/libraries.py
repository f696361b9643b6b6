"""Hand-written code against the kept libraries that do the same job: speed and exactness.

    OMP_NUM_THREADS=1 python benchmarks/libraries.py        (about a minute on one CPU core)

Prints one line per comparison; docs/libraries.md holds the decisions and a run's numbers. Times
are the best of several repeats on one thread; errors are against a float64 reference (or the
true values) unless a line says otherwise. kornia comes with the test extra.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import torch
import torch.nn.functional as F

from nerf2gs_plugin.cameras import distort_normalized, undistort_normalized
from nerf2gs_plugin.data.ply import read_ply_points, write_ply_points
from nerf2gs_plugin.data.process.exif import exif_focal_px
from nerf2gs_plugin.enhancer.degrade import gaussian_blur
from nerf2gs_plugin.eval.pose_eval import umeyama
from nerf2gs_plugin.masks.from_renders import median_filter
from nerf2gs_plugin.utils.image_metrics import ssim, ssim_map
from nerf2gs_plugin.utils.lie import skew, so3_exp_map
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat, random_quats, rotmat_to_quat


def best_ms(fn, reps: int = 7):
    """(best wall time in ms, the last result)."""
    best, out = math.inf, None
    for _ in range(reps):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best * 1e3, out


def exif(tmp: Path) -> None:
    from PIL import Image, TiffImagePlugin

    def jpeg(name: str, tags: dict) -> Path:
        ex = Image.Exif()
        sub = ex.get_ifd(0x8769)
        sub.update(tags)
        path = tmp / name
        Image.fromarray(np.zeros((480, 640, 3), np.uint8)).save(path, exif=ex.tobytes())
        return path

    rat = TiffImagePlugin.IFDRational
    paths = [jpeg("f35.jpg", {0xA405: 28}), jpeg("res.jpg", {0x920A: rat(45, 10), 0xA20E: rat(4000, 1), 0xA210: 2}),
             jpeg("res_cm.jpg", {0x920A: rat(45, 10), 0xA20E: rat(1500, 1), 0xA210: 3}), jpeg("none.jpg", {})]

    def pil(path: Path):
        with Image.open(path) as im:
            ex = im.getexif().get_ifd(0x8769)
        if ex.get(0xA405):
            return float(ex[0xA405]) / 36.0 * 640
        focal, xres, unit = ex.get(0x920A), ex.get(0xA20E), ex.get(0xA210, 2)
        mm = {2: 25.4, 3: 10.0, 4: 1.0}.get(int(unit))
        return float(focal) * float(xres) / mm if focal and xres and mm else None

    def colmap(path: Path):
        f = pycolmap.Bitmap.read(str(path), as_rgb=True).exif_focal_length()
        return f if f else None

    ours = [exif_focal_px(p, 640, 480) for p in paths]
    for name, fn, reps in (("PIL getexif", pil, 200), ("pycolmap Bitmap.exif_focal_length", colmap, 10)):
        theirs = [fn(p) for p in paths]
        same = all((a is None and b is None) or (a is not None and b is not None and abs(a - b) < 1e-9) for a, b in zip(ours, theirs))
        us_o = best_ms(lambda: [exif_focal_px(p, 640, 480) for p in paths], 200)[0] / len(paths) * 1e3
        us_l = best_ms(lambda: [fn(p) for p in paths], reps)[0] / len(paths) * 1e3
        print(f"EXIF focal: ours {us_o:.0f} us/file | {name} {us_l:.0f} us/file; same focal on all 4 files: {same} "
              f"(ours {[round(v, 1) if v else v for v in ours]}, {name.split()[0]} {[round(v, 1) if v else v for v in theirs]})")


def ply(tmp: Path) -> None:
    rng = np.random.default_rng(0)
    n = 200_000
    xyz = (rng.normal(size=(n, 3)) * 10).astype(np.float32)
    rgb = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    path = tmp / "points.ply"
    write_ply_points(path, xyz, rgb)
    ms_o, (a, c) = best_ms(lambda: read_ply_points(path))
    exact = np.array_equal(a, xyz) and np.array_equal(c, rgb)

    def colmap():
        rec = pycolmap.Reconstruction()
        rec.import_PLY(str(path))
        pts = rec.points3D
        ids = sorted(pts.keys())
        return np.array([pts[i].xyz for i in ids], np.float32), np.array([pts[i].color for i in ids])

    ms_c, (b, d) = best_ms(colmap, 2)
    ms_cv, e = best_ms(lambda: cv2.ppf_match_3d.loadPLYSimple(str(path), 0), 2)
    print(f"PLY read, {n} binary points: ours {ms_o:.1f} ms exact {exact} | pycolmap import_PLY {ms_c:.0f} ms exact "
          f"{np.array_equal(b, xyz) and np.array_equal(d, rgb)} (xyz + rgb only) | cv2 loadPLYSimple {ms_cv:.1f} ms exact "
          f"{e.shape == xyz.shape and np.array_equal(e, xyz)} (ASCII only, xyz only)")


def ssim_row() -> None:
    import kornia

    g = torch.Generator().manual_seed(0)
    img = kornia.filters.gaussian_blur2d(torch.rand(1, 3, 448, 800, generator=g), (9, 9), (3.0, 3.0))[0].permute(1, 2, 0)
    other = (img + 0.08 * torch.randn(img.shape, generator=g)).clamp(0, 1)
    ref = ssim_map(img.double(), other.double())
    ms_o, ours = best_ms(lambda: ssim_map(img, other))
    x = img.clone().requires_grad_(True)
    ms_ob = best_ms(lambda: ssim(x, other).backward())[0]
    nchw = lambda t: t.permute(2, 0, 1)[None]  # noqa: E731
    ms_k, k = best_ms(lambda: kornia.metrics.ssim(nchw(img), nchw(other), 11)[..., 5:-5, 5:-5])
    ms_kb = best_ms(lambda: kornia.metrics.ssim(nchw(x), nchw(other), 11)[..., 5:-5, 5:-5].mean().backward())[0]
    a, b = (img.double().numpy() * 255), (other.double().numpy() * 255)  # its constants assume 0..255
    ms_c, (_, qmap) = best_ms(lambda: cv2.quality.QualitySSIM_compute(a, b))
    cmap = torch.from_numpy(np.asarray(qmap)[5:-5, 5:-5]).permute(2, 0, 1)[None]
    print(f"SSIM 800x448: ours fwd {ms_o:.0f} ms fwd+bwd {ms_ob:.0f} ms err {float((ours - ref).abs().max()):.0e} | kornia "
          f"fwd {ms_k:.0f} ms fwd+bwd {ms_kb:.0f} ms err {float((k - ref).abs().max()):.0e} | cv2.quality {ms_c:.0f} ms "
          f"(float64, no gradient, border included in its mean) err {float((cmap - ref).abs().max()):.0e}")


def rotations() -> None:
    n, m = 100_000, 10_000  # the per-item libraries run on m and are scaled to n
    q = random_quats(n, torch.Generator().manual_seed(0))
    R64 = quat_to_rotmat(q.double())
    ms_o, R = best_ms(lambda: quat_to_rotmat(q))
    qn = q.double().numpy()
    ms_c, Rc = best_ms(lambda: np.stack([pycolmap.Rotation3d(np.r_[v[1:], v[0]]).matrix() for v in qn[:m]]), 2)
    print(f"quaternion -> matrix, {n}: ours {ms_o:.1f} ms err {float((R.double() - R64).abs().max()):.0e} | pycolmap Rotation3d "
          f"{ms_c * n / m:.0f} ms (per item, float64) err {np.abs(Rc - R64[:m].numpy()).max():.0e}")
    truth = torch.where(q[:, :1] < 0, -q, q).double()
    ms_o, qq = best_ms(lambda: rotmat_to_quat(R))
    Rn = R64.numpy()

    def colmap():
        out = np.array([pycolmap.Rotation3d(r).quat for r in Rn[:m]])[:, [3, 0, 1, 2]]
        return np.where(out[:, :1] < 0, -out, out)

    ms_c, qc = best_ms(colmap, 2)
    print(f"matrix -> quaternion, {n}: ours {ms_o:.1f} ms err {float((qq.double() - truth).abs().max()):.0e} (float32 in) | "
          f"pycolmap Rotation3d {ms_c * n / m:.0f} ms (per item) err {np.abs(qc - truth[:m].numpy()).max():.0e} (float64 in)")
    w = torch.randn(n, 3, generator=torch.Generator().manual_seed(1)) * 0.5
    ref = torch.linalg.matrix_exp(skew(w.double()))
    wp = w.clone().requires_grad_(True)
    ms_o, E = best_ms(lambda: so3_exp_map(w))
    ms_ob = best_ms(lambda: so3_exp_map(wp).sum().backward())[0]
    ms_m, M = best_ms(lambda: torch.linalg.matrix_exp(skew(w)), 3)
    ms_mb = best_ms(lambda: torch.linalg.matrix_exp(skew(wp)).sum().backward(), 3)[0]
    wn = w.double().numpy()
    ms_r = best_ms(lambda: [cv2.Rodrigues(v)[0] for v in wn[:m]], 2)[0]
    print(f"SO(3) exp, {n}: ours fwd {ms_o:.0f} ms fwd+bwd {ms_ob:.0f} ms err {float((E.double() - ref).abs().max()):.0e} | "
          f"torch.linalg.matrix_exp(skew) fwd {ms_m:.0f} ms fwd+bwd {ms_mb:.0f} ms err {float((M.double() - ref).abs().max()):.0e} | "
          f"cv2.Rodrigues {ms_r * n / m:.0f} ms (per item, float64, no gradient)")


def sim3() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(1000, 3)) * 5
    R = pycolmap.Rotation3d(np.array([0.1, -0.3, 0.2, 0.9]) / np.linalg.norm([0.1, -0.3, 0.2, 0.9])).matrix()
    dst = 2.7 * src @ R.T + [1.0, -2.0, 0.5] + 0.01 * rng.normal(size=src.shape)
    us_o, o = best_ms(lambda: umeyama(src, dst), 200)
    us_c, c = best_ms(lambda: pycolmap.estimate_sim3d(src, dst), 200)
    us_v, (T, s) = best_ms(lambda: cv2.estimateAffine3D(src, dst, force_rotation=True), 200)
    planar = np.c_[rng.normal(size=(10, 2)), np.zeros(10)]
    print(f"Sim(3) fit, 1000 points: ours {us_o * 1e3:.0f} us | pycolmap estimate_sim3d {us_c * 1e3:.0f} us, max|dR| "
          f"{np.abs(c.rotation.matrix() - o.R).max():.0e}, on planar points: {pycolmap.estimate_sim3d(planar, 2 * planar + 1)} "
          f"(ours: scale {umeyama(planar, 2 * planar + 1).s:.3f}) | cv2.estimateAffine3D {us_v * 1e3:.0f} us, max|dR| "
          f"{np.abs(T[:, :3] - o.R).max():.0e}")


def former_blur(x: torch.Tensor, sigma: float) -> torch.Tensor:
    """The enhancer degradations' Gaussian blur before it became OpenCV's: a separable torch convolution."""
    r = min(max(1, int(math.ceil(3 * sigma))), x.shape[-1] - 1, x.shape[-2] - 1)
    k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=x.dtype) / sigma) ** 2)
    k, c = k / k.sum(), x.shape[1]
    x = F.pad(x, (r, r, r, r), mode="reflect")
    x = F.conv2d(x, k.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)
    return F.conv2d(x, k.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)


def warps() -> None:
    g = torch.Generator().manual_seed(0)
    for shape, sigma in (((8, 3, 128, 128), 2.0), ((1, 3, 448, 800), 1.3)):
        x = torch.rand(*shape, generator=g)
        ref = former_blur(x.double(), sigma)
        ms_t, a = best_ms(lambda: former_blur(x, sigma))
        ms_c, b = best_ms(lambda: gaussian_blur(x, sigma))
        print(f"Gaussian blur {tuple(shape)} sigma {sigma}: torch conv {ms_t:.1f} ms err {float((a.double() - ref).abs().max()):.0e} | "
              f"cv2.GaussianBlur (now used) {ms_c:.1f} ms err {float((b.double() - ref).abs().max()):.0e}")
    n = 800 * 448
    dist = torch.tensor([-0.12, 0.03, 1e-3, -5e-4])
    u, v = torch.rand(n, generator=g) * 1.6 - 0.8, torch.rand(n, generator=g) * 0.9 - 0.45
    xd, yd = (c.float() for c in distort_normalized(u.double(), v.double(), dist.double()))
    ms_o, (x, y) = best_ms(lambda: undistort_normalized(xd, yd, dist[None].expand(n, 4)))
    pts = torch.stack([xd, yd], -1).numpy().reshape(-1, 1, 2)
    ms_c, p = best_ms(lambda: cv2.undistortPoints(pts, np.eye(3), dist.double().numpy()))
    truth = torch.stack([u, v], -1).numpy()
    err_o = float(np.abs(torch.stack([x, y], -1).numpy() - truth).max())
    print(f"undistort {n} pixel coords: ours {ms_o:.0f} ms err {err_o:.0e} (torch, per-ray parameters) | cv2.undistortPoints "
          f"{ms_c:.0f} ms err {np.abs(p.reshape(-1, 2) - truth).max():.0e} (one camera per call)")
    for k in (5, 9):
        m = torch.rand(112, 200, generator=g)
        ms_o, a = best_ms(lambda: median_filter(m, k), 3)
        try:
            ms_c, b = best_ms(lambda: cv2.medianBlur(m.numpy(), k), 3)
            lib = f"cv2.medianBlur {ms_c:.2f} ms max|diff| {np.abs(b - a.numpy()).max():.0e}"
        except cv2.error:
            lib = "cv2.medianBlur: float32 only up to 5 px"
        print(f"median filter 200x112, {k} px: ours {ms_o:.1f} ms | {lib}")


if __name__ == "__main__":
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        exif(Path(tmp))
        ply(Path(tmp))
    ssim_row()
    rotations()
    sim3()
    warps()
