// Mean SSIM of two float32 images [H, W, C] (Wang et al., a separable Gaussian window over the valid region)
// and its gradient with respect to the first image, fused: the five blurred moments are made row by row
// (no [5C, H, W] stack, no depthwise convolution), and the backward blurs only the three moments that depend
// on the first image, with the window's adjoint. Same formula as utils/image_metrics.ssim_map.
#include <torch/extension.h>
#include <ATen/Parallel.h>

#include <omp.h>

#include <algorithm>
#include <vector>

namespace {

// blurred moments of one channel: 5 maps [Ho][Wo] each (mu_x, mu_y, E[xx], E[yy], E[xy])
struct Maps {
  int64_t C, H, W, win, Ho, Wo;
  int64_t plane() const { return Ho * Wo; }
};

void check(const torch::Tensor& t, const char* name) {
  TORCH_CHECK(t.device().is_cpu() && t.scalar_type() == torch::kFloat && t.is_contiguous(), name,
              " must be a contiguous float32 CPU tensor");
}

// row pass of the five moments of channel c: R [5][H][Wo]
void row_moments(const float* x, const float* y, const float* g, const Maps& m, int64_t c, int64_t i, float* R,
                 float* buf) {
  const int64_t W = m.W, C = m.C, Wo = m.Wo, H = m.H;
  float *bx = buf, *by = buf + W, *bxx = buf + 2 * W, *byy = buf + 3 * W, *bxy = buf + 4 * W;
  for (int64_t j = 0; j < W; ++j) {
    const float a = x[(i * W + j) * C + c], b = y[(i * W + j) * C + c];
    bx[j] = a;
    by[j] = b;
    bxx[j] = a * a;
    byy[j] = b * b;
    bxy[j] = a * b;
  }
  for (int k = 0; k < 5; ++k) {
    float* out = R + (k * H + i) * Wo;
    const float* in = buf + k * W;
    std::fill(out, out + Wo, 0.0f);
    for (int64_t t = 0; t < m.win; ++t) {
      const float gt = g[t];
#pragma omp simd
      for (int64_t j = 0; j < Wo; ++j) out[j] += gt * in[j + t];
    }
  }
}

}  // namespace

// -> (mean SSIM [], blurred moments [C, 5, Ho, Wo])
std::vector<torch::Tensor> ssim_forward(torch::Tensor x, torch::Tensor y, torch::Tensor g, double c1d, double c2d) {
  check(x, "x");
  check(y, "y");
  check(g, "window");
  TORCH_CHECK(x.dim() == 3 && x.sizes() == y.sizes(), "images must be [H, W, C] of one shape");
  const Maps m{x.size(2), x.size(0), x.size(1), g.size(0), x.size(0) - g.size(0) + 1, x.size(1) - g.size(0) + 1};
  TORCH_CHECK(m.Ho >= 1 && m.Wo >= 1, "image smaller than the window");
  const float c1 = static_cast<float>(c1d), c2 = static_cast<float>(c2d);
  auto R = torch::empty({m.C, 5, m.H, m.Wo}, x.options());
  auto B = torch::empty({m.C, 5, m.Ho, m.Wo}, x.options());
  auto rows = torch::zeros({m.C, m.Ho}, x.options().dtype(torch::kDouble));
  const float *px = x.data_ptr<float>(), *py = y.data_ptr<float>(), *pg = g.data_ptr<float>();
  float *pR = R.data_ptr<float>(), *pB = B.data_ptr<float>();
  double* prow = rows.data_ptr<double>();
  const int nt = std::max(1, at::get_num_threads());
#pragma omp parallel num_threads(nt)
  {
    std::vector<float> buf(5 * m.W);
#pragma omp for schedule(static)
    for (int64_t ci = 0; ci < m.C * m.H; ++ci) {
      const int64_t c = ci / m.H, i = ci % m.H;
      row_moments(px, py, pg, m, c, i, pR + c * 5 * m.H * m.Wo, buf.data());
    }
#pragma omp for schedule(static)
    for (int64_t ci = 0; ci < m.C * m.Ho; ++ci) {
      const int64_t c = ci / m.Ho, i = ci % m.Ho;
      float* b[5];
      for (int k = 0; k < 5; ++k) {
        b[k] = pB + ((c * 5 + k) * m.Ho + i) * m.Wo;
        const float* r = pR + ((c * 5 + k) * m.H + i) * m.Wo;
        std::fill(b[k], b[k] + m.Wo, 0.0f);
        for (int64_t t = 0; t < m.win; ++t) {
          const float gt = pg[t];
          const float* rt = r + t * m.Wo;
#pragma omp simd
          for (int64_t j = 0; j < m.Wo; ++j) b[k][j] += gt * rt[j];
        }
      }
      double s = 0.0;
#pragma omp simd reduction(+ : s)
      for (int64_t j = 0; j < m.Wo; ++j) {
        const float mx = b[0][j], my = b[1][j];
        const float a1 = 2 * mx * my + c1, a2 = 2 * (b[4][j] - mx * my) + c2;
        const float d1 = mx * mx + my * my + c1, d2 = (b[2][j] - mx * mx) + (b[3][j] - my * my) + c2;
        s += static_cast<double>((a1 * a2) / (d1 * d2));
      }
      prow[ci] = s;
    }
  }
  auto mean = (rows.sum() / static_cast<double>(m.C * m.Ho * m.Wo)).to(torch::kFloat);
  return {mean, B};
}

// gradient of mean SSIM x grad_out with respect to x: [H, W, C]
torch::Tensor ssim_backward(torch::Tensor x, torch::Tensor y, torch::Tensor g, torch::Tensor B, double c1d, double c2d,
                            double grad_out) {
  check(x, "x");
  check(y, "y");
  check(g, "window");
  check(B, "moments");
  const Maps m{x.size(2), x.size(0), x.size(1), g.size(0), x.size(0) - g.size(0) + 1, x.size(1) - g.size(0) + 1};
  const float c1 = static_cast<float>(c1d), c2 = static_cast<float>(c2d);
  const float scale = static_cast<float>(grad_out / static_cast<double>(m.C * m.Ho * m.Wo));
  auto G = torch::empty({m.C, 3, m.Ho, m.Wo}, x.options());  // d/d mu_x, d/d E[xx], d/d E[xy]
  auto Rg = torch::empty({m.C, 3, m.H, m.Wo}, x.options());
  auto dx = torch::empty_like(x);
  const float *px = x.data_ptr<float>(), *py = y.data_ptr<float>(), *pg = g.data_ptr<float>(), *pB = B.data_ptr<float>();
  float *pG = G.data_ptr<float>(), *pRg = Rg.data_ptr<float>(), *pdx = dx.data_ptr<float>();
  const int nt = std::max(1, at::get_num_threads());
#pragma omp parallel num_threads(nt)
  {
    std::vector<float> acc(3 * m.W);
#pragma omp for schedule(static)
    for (int64_t ci = 0; ci < m.C * m.Ho; ++ci) {
      const int64_t c = ci / m.Ho, i = ci % m.Ho;
      const float* b[5];
      for (int k = 0; k < 5; ++k) b[k] = pB + ((c * 5 + k) * m.Ho + i) * m.Wo;
      float* gmx = pG + ((c * 3 + 0) * m.Ho + i) * m.Wo;
      float* gxx = pG + ((c * 3 + 1) * m.Ho + i) * m.Wo;
      float* gxy = pG + ((c * 3 + 2) * m.Ho + i) * m.Wo;
#pragma omp simd
      for (int64_t j = 0; j < m.Wo; ++j) {
        const float mx = b[0][j], my = b[1][j];
        const float a1 = 2 * mx * my + c1, a2 = 2 * (b[4][j] - mx * my) + c2;
        const float d1 = mx * mx + my * my + c1, d2 = (b[2][j] - mx * mx) + (b[3][j] - my * my) + c2;
        const float inv = 1.0f / (d1 * d2);
        const float s = a1 * a2 * inv;
        const float da1 = a2 * inv, da2 = a1 * inv, dd1 = -s / d1, dd2 = -s / d2;
        gmx[j] = scale * (2 * my * (da1 - da2) + 2 * mx * (dd1 - dd2));
        gxx[j] = scale * dd2;
        gxy[j] = scale * 2 * da2;
      }
    }
    // the column pass's adjoint, gathered per output row (no two threads write one row)
#pragma omp for schedule(static)
    for (int64_t ci = 0; ci < m.C * m.H; ++ci) {
      const int64_t c = ci / m.H, i = ci % m.H;
      const int64_t t0 = std::max<int64_t>(0, i - m.Ho + 1), t1 = std::min<int64_t>(m.win - 1, i);
      for (int k = 0; k < 3; ++k) {
        float* out = pRg + ((c * 3 + k) * m.H + i) * m.Wo;
        std::fill(out, out + m.Wo, 0.0f);
        for (int64_t t = t0; t <= t1; ++t) {
          const float gt = pg[t];
          const float* in = pG + ((c * 3 + k) * m.Ho + (i - t)) * m.Wo;
#pragma omp simd
          for (int64_t j = 0; j < m.Wo; ++j) out[j] += gt * in[j];
        }
      }
    }
    // the row pass's adjoint, then d/dx = A_mx + 2 x A_xx + y A_xy
#pragma omp for schedule(static)
    for (int64_t ci = 0; ci < m.C * m.H; ++ci) {
      const int64_t c = ci / m.H, i = ci % m.H;
      std::fill(acc.begin(), acc.end(), 0.0f);
      for (int k = 0; k < 3; ++k) {
        float* out = acc.data() + k * m.W;
        const float* in = pRg + ((c * 3 + k) * m.H + i) * m.Wo;
        for (int64_t t = 0; t < m.win; ++t) {
          const float gt = pg[t];
          float* o = out + t;
#pragma omp simd
          for (int64_t j = 0; j < m.Wo; ++j) o[j] += gt * in[j];
        }
      }
      for (int64_t j = 0; j < m.W; ++j) {
        const int64_t p = (i * m.W + j) * m.C + c;
        pdx[p] = acc[j] + 2 * px[p] * acc[m.W + j] + py[p] * acc[2 * m.W + j];
      }
    }
  }
  return dx;
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &ssim_forward, "mean SSIM of [H, W, C] float32 images and the blurred moments (CPU)");
  m.def("backward", &ssim_backward, "gradient of the mean SSIM with respect to the first image (CPU)");
}
