// Torch bindings of the CPU tile compositor for 3D Gaussians (kernel in gaussians_core.h).
//
// Inputs come from the torch side (projection, SH, tile binning): per camera-Gaussian pair
// (flattened as c * N + n) the pixel-space mean, the conic (inverse 2D covariance a, b, c), the
// features to composite and the (possibly antialiasing-compensated) opacity; per tile the
// front-to-back depth-sorted list of pairs (tile_offsets, flat_ids). float32 and float64.
#include <torch/extension.h>
#include <ATen/Parallel.h>

#include "binning_core.h"
#include "gaussians_core.h"
#include "projection_bwd.h"
#include "projection_core.h"
#include "sh_core.h"

namespace {

void check(const torch::Tensor& x, const char* name) {
  TORCH_CHECK(x.device().is_cpu(), name, " must be a CPU tensor");
  TORCH_CHECK(x.is_contiguous(), name, " must be contiguous");
}

gs3d::Dims dims(const torch::Tensor& colors, int64_t n_cams, int64_t height, int64_t width, int64_t ts) {
  TORCH_CHECK(ts >= 1 && ts <= gs3d::kMaxTile, "tile_size must be in 1..", gs3d::kMaxTile);
  return gs3d::Dims{n_cams, height, width, colors.size(1), static_cast<int>(ts)};
}

template <typename T>
std::vector<torch::Tensor> forward_t(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                                     const torch::Tensor& opacities, const torch::Tensor& offsets, const torch::Tensor& ids,
                                     const gs3d::Dims d, bool need_last, bool need_median) {
  auto opts = means2d.options();
  auto render = torch::zeros({d.n_cams, d.height, d.width, d.D}, opts);
  auto alpha = torch::zeros({d.n_cams, d.height, d.width}, opts);
  auto last = torch::full({d.n_cams, d.height, d.width}, -1, opts.dtype(torch::kInt64));
  auto median = torch::full({d.n_cams, d.height, d.width}, -1, opts.dtype(torch::kInt64));
  gs3d::forward_tiles<T>(means2d.data_ptr<T>(), conics.data_ptr<T>(), colors.data_ptr<T>(), opacities.data_ptr<T>(),
                         offsets.data_ptr<int64_t>(), ids.data_ptr<int64_t>(), d, means2d.size(0), std::max(1, at::get_num_threads()),
                         render.data_ptr<T>(), alpha.data_ptr<T>(), last.data_ptr<int64_t>(), median.data_ptr<int64_t>(),
                         need_last, need_median);
  return {render, alpha, last, median};
}

template <typename T>
std::vector<torch::Tensor> backward_t(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                                      const torch::Tensor& opacities, const torch::Tensor& offsets, const torch::Tensor& ids,
                                      const torch::Tensor& alpha, const torch::Tensor& last, const torch::Tensor& v_render,
                                      const torch::Tensor& v_alpha, const gs3d::Dims d) {
  const int nt = std::max(1, at::get_num_threads());
  const int64_t CN = means2d.size(0), D = d.D;
  auto grads = torch::zeros({nt, CN, 6 + D}, means2d.options());
  gs3d::backward_tiles<T>(means2d.data_ptr<T>(), conics.data_ptr<T>(), colors.data_ptr<T>(), opacities.data_ptr<T>(),
                          offsets.data_ptr<int64_t>(), ids.data_ptr<int64_t>(), alpha.data_ptr<T>(), last.data_ptr<int64_t>(),
                          v_render.data_ptr<T>(), v_alpha.data_ptr<T>(), d, CN, nt, grads.data_ptr<T>());
  auto total = nt > 1 ? grads.sum(0) : grads[0];  // [CN, 6 + D]
  return {total.slice(1, 0, 2).contiguous(), total.slice(1, 2, 5).contiguous(), total.slice(1, 6, 6 + D).contiguous(),
          total.select(1, 5).contiguous()};
}

}  // namespace

std::vector<torch::Tensor> rasterize_forward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                             torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor flat_ids,
                                             int64_t n_cams, int64_t height, int64_t width, int64_t tile_size,
                                             bool need_last, bool need_median) {
  // need_last: record each pixel's last composited list entry (what backward needs);
  // need_median: record the median-depth Gaussian. Unrequested outputs stay -1.
  for (auto* x : {&means2d, &conics, &colors, &opacities, &tile_offsets, &flat_ids}) check(*x, "input");
  TORCH_CHECK(tile_offsets.scalar_type() == torch::kInt64 && flat_ids.scalar_type() == torch::kInt64, "tile lists must be int64");
  TORCH_CHECK(means2d.size(0) < (int64_t(1) << 31), "too many camera x Gaussian pairs");
  const auto d = dims(colors, n_cams, height, width, tile_size);
  if (means2d.scalar_type() == torch::kDouble)
    return forward_t<double>(means2d, conics, colors, opacities, tile_offsets, flat_ids, d, need_last, need_median);
  TORCH_CHECK(means2d.scalar_type() == torch::kFloat, "rasterizer inputs must be float32 or float64");
  return forward_t<float>(means2d, conics, colors, opacities, tile_offsets, flat_ids, d, need_last, need_median);
}

std::vector<torch::Tensor> rasterize_backward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                              torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor flat_ids,
                                              torch::Tensor alpha, torch::Tensor last, torch::Tensor v_render,
                                              torch::Tensor v_alpha, int64_t n_cams, int64_t height, int64_t width,
                                              int64_t tile_size) {
  for (auto* x : {&means2d, &conics, &colors, &opacities, &tile_offsets, &flat_ids, &alpha, &last, &v_render, &v_alpha})
    check(*x, "input");
  const auto d = dims(colors, n_cams, height, width, tile_size);
  if (means2d.scalar_type() == torch::kDouble)
    return backward_t<double>(means2d, conics, colors, opacities, tile_offsets, flat_ids, alpha, last, v_render, v_alpha, d);
  return backward_t<float>(means2d, conics, colors, opacities, tile_offsets, flat_ids, alpha, last, v_render, v_alpha, d);
}

std::vector<torch::Tensor> bin_gaussians(torch::Tensor means2d, torch::Tensor cov2d, torch::Tensor opacities,
                                         torch::Tensor depths, torch::Tensor radii, int64_t width, int64_t height,
                                         int64_t tile_size) {
  // means2d [C, N, 2], cov2d [C, N, 2, 2], opacities / depths [C, N], radii [C, N] int32
  for (auto* x : {&means2d, &cov2d, &opacities, &depths, &radii}) check(*x, "input");
  TORCH_CHECK(radii.scalar_type() == torch::kInt32, "radii must be int32");
  const int64_t n_cams = depths.size(0), n = depths.size(1);
  std::vector<int64_t> offsets, ids;
  const int nt = std::max(1, at::get_num_threads());
  if (means2d.scalar_type() == torch::kDouble) {
    ids = gs3d::bin_pairs<double>(means2d.data_ptr<double>(), cov2d.data_ptr<double>(), opacities.data_ptr<double>(),
                                  depths.data_ptr<double>(), radii.data_ptr<int32_t>(), n_cams, n, width, height,
                                  static_cast<int>(tile_size), nt, offsets);
  } else {
    TORCH_CHECK(means2d.scalar_type() == torch::kFloat, "binning inputs must be float32 or float64");
    ids = gs3d::bin_pairs<float>(means2d.data_ptr<float>(), cov2d.data_ptr<float>(), opacities.data_ptr<float>(),
                                 depths.data_ptr<float>(), radii.data_ptr<int32_t>(), n_cams, n, width, height,
                                 static_cast<int>(tile_size), nt, offsets);
  }
  auto o = torch::tensor(offsets, torch::kInt64);
  auto i = torch::empty({static_cast<int64_t>(ids.size())}, torch::kInt64);
  std::copy(ids.begin(), ids.end(), i.data_ptr<int64_t>());
  return {o, i};
}

std::vector<torch::Tensor> project_forward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                           torch::Tensor sh, torch::Tensor viewmats, torch::Tensor Ks,
                                           int64_t width, int64_t height, double near_plane, double far_plane,
                                           int64_t sh_degree) {
  // sh: [N, K, 3] SH coefficients, or an empty tensor for no colour evaluation
  for (auto* x : {&means, &quats, &scales, &sh, &viewmats, &Ks}) check(*x, "input");
  const int64_t C = viewmats.size(0), N = means.size(0);
  const int64_t K = sh.numel() > 0 ? sh.size(1) : 0;
  TORCH_CHECK(sh_degree >= 0 && sh_degree <= 3 && (K == 0 || K >= (sh_degree + 1) * (sh_degree + 1)), "bad SH degree");
  auto opts = means.options();
  auto means2d = torch::empty({C, N, 2}, opts), conics = torch::empty({C, N, 3}, opts), depths = torch::empty({C, N}, opts);
  auto radii = torch::empty({C, N}, opts.dtype(torch::kInt32)), comp = torch::empty({C, N}, opts);
  auto cov2d = torch::empty({C, N, 2, 2}, opts), colors = torch::empty({C, N, K > 0 ? 3 : 0}, opts);
  const gs3d::ProjectArgs a{C, N, width, height, K, static_cast<int>(sh_degree), near_plane, far_plane, 0.3};
  const int nt = std::max(1, at::get_num_threads());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "project_forward", [&] {
    gs3d::project_forward<scalar_t>(means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(), scales.data_ptr<scalar_t>(),
                                    K > 0 ? sh.data_ptr<scalar_t>() : nullptr,
                                    viewmats.data_ptr<scalar_t>(), Ks.data_ptr<scalar_t>(), a, nt, means2d.data_ptr<scalar_t>(),
                                    conics.data_ptr<scalar_t>(), depths.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(),
                                    comp.data_ptr<scalar_t>(), cov2d.data_ptr<scalar_t>(), colors.data_ptr<scalar_t>());
  });
  return {means2d, conics, depths, radii, comp, cov2d, colors};
}

std::vector<torch::Tensor> project_backward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                            torch::Tensor sh, torch::Tensor viewmats, torch::Tensor Ks, int64_t width,
                                            int64_t height, double near_plane, double far_plane, int64_t sh_degree,
                                            torch::Tensor v_means2d, torch::Tensor v_conics, torch::Tensor v_depths,
                                            torch::Tensor v_comp, torch::Tensor v_colors) {
  // v_comp / v_colors may be empty (no gradient reaches them); returns v_means, v_quats, v_scales, v_sh
  for (auto* x : {&means, &quats, &scales, &sh, &viewmats, &Ks, &v_means2d, &v_conics, &v_depths, &v_comp, &v_colors})
    check(*x, "input");
  const int64_t C = viewmats.size(0), N = means.size(0);
  const int64_t K = sh.numel() > 0 ? sh.size(1) : 0;
  TORCH_CHECK(sh_degree >= 0 && sh_degree <= 3 && (K == 0 || K >= (sh_degree + 1) * (sh_degree + 1)), "bad SH degree");
  TORCH_CHECK(v_means2d.numel() == C * N * 2 && v_conics.numel() == C * N * 3 && v_depths.numel() == C * N,
              "projection gradients have the wrong size");
  auto v_means = torch::empty_like(means), v_quats = torch::empty_like(quats), v_scales = torch::empty_like(scales);
  auto v_sh = torch::empty_like(sh);
  const gs3d::ProjectArgs a{C, N, width, height, K, static_cast<int>(sh_degree), near_plane, far_plane, 0.3};
  const int nt = std::max(1, at::get_num_threads());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "project_backward", [&] {
    gs3d::project_backward<scalar_t>(
        means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(), scales.data_ptr<scalar_t>(),
        K > 0 ? sh.data_ptr<scalar_t>() : nullptr, viewmats.data_ptr<scalar_t>(), Ks.data_ptr<scalar_t>(), a, nt,
        v_means2d.data_ptr<scalar_t>(), v_conics.data_ptr<scalar_t>(), v_depths.data_ptr<scalar_t>(),
        v_comp.numel() > 0 ? v_comp.data_ptr<scalar_t>() : nullptr,
        (K > 0 && v_colors.numel() > 0) ? v_colors.data_ptr<scalar_t>() : nullptr, v_means.data_ptr<scalar_t>(),
        v_quats.data_ptr<scalar_t>(), v_scales.data_ptr<scalar_t>(), K > 0 ? v_sh.data_ptr<scalar_t>() : nullptr);
  });
  return {v_means, v_quats, v_scales, v_sh};
}

torch::Tensor sh_forward(int64_t degree, torch::Tensor dirs, torch::Tensor coeffs) {
  // dirs [C, N, 3] (mean - camera centre), coeffs [N, K, 3] -> colours [C, N, 3]
  check(dirs, "dirs");
  check(coeffs, "coeffs");
  TORCH_CHECK(degree >= 0 && degree <= 3 && coeffs.size(1) >= (degree + 1) * (degree + 1), "bad SH degree");
  auto out = torch::empty_like(dirs);
  AT_DISPATCH_FLOATING_TYPES(dirs.scalar_type(), "sh_forward", [&] {
    gs3d::sh_forward<scalar_t>(static_cast<int>(degree), dirs.data_ptr<scalar_t>(), coeffs.data_ptr<scalar_t>(), dirs.size(0),
                               dirs.size(1), coeffs.size(1), std::max(1, at::get_num_threads()), out.data_ptr<scalar_t>());
  });
  return out;
}

std::vector<torch::Tensor> sh_backward(int64_t degree, torch::Tensor dirs, torch::Tensor coeffs, torch::Tensor v_colors) {
  for (auto* x : {&dirs, &coeffs, &v_colors}) check(*x, "input");
  auto v_coeffs = torch::zeros_like(coeffs);
  auto v_dirs = torch::empty_like(dirs);
  AT_DISPATCH_FLOATING_TYPES(dirs.scalar_type(), "sh_backward", [&] {
    gs3d::sh_backward<scalar_t>(static_cast<int>(degree), dirs.data_ptr<scalar_t>(), coeffs.data_ptr<scalar_t>(),
                                v_colors.data_ptr<scalar_t>(), dirs.size(0), dirs.size(1), coeffs.size(1),
                                std::max(1, at::get_num_threads()), v_coeffs.data_ptr<scalar_t>(), v_dirs.data_ptr<scalar_t>());
  });
  return {v_coeffs, v_dirs};
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &rasterize_forward, "3DGS tile compositing forward (CPU)");
  m.def("backward", &rasterize_backward, "3DGS tile compositing backward (CPU)");
  m.def("sh_forward", &sh_forward, "SH colours, 3DGS convention (CPU)");
  m.def("sh_backward", &sh_backward, "SH colours backward (CPU)");
  m.def("project_forward", &project_forward, "projection + SH colours (CPU)");
  m.def("project_backward", &project_backward, "backward of project_forward (CPU)");
  m.def("bin_gaussians", &bin_gaussians, "per-tile depth-sorted lists of (camera, Gaussian) pairs (CPU)");
}
