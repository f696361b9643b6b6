// Multiresolution hash-grid encoding (Mueller et al. 2022), CPU forward/backward with OpenMP.
//
// Layout (all float32, contiguous):
//   x      [N, 3]     positions in [0, 1]^3 (clamped here)
//   table  [L, T, F]  feature table per level; T is a power of two
//   res    [L]        int32 grid resolution per level (cells per axis)
//   out    [N, L, F]  trilinearly interpolated features
//   grad_x [N, 3]     (backward_x only) gradient w.r.t. the positions: the derivative of the
//                     trilinear weights, zero along an axis where the position was clamped
// A level is indexed densely when (res + 1)^3 <= T, otherwise through the spatial hash
// (x * 1) ^ (y * 2654435761) ^ (z * 805459861) mod T. The math is identical to the pure-torch
// reference in hash_encoding.py; the tests hold the two against each other.
//
// Forward parallelises over points. Backward parallelises over levels: every level owns a
// disjoint slice of the table gradient, so no atomics are needed and the result is
// deterministic (the summation order per entry is the point order). The position gradient
// (used only when positions require grad: a camera optimizer) parallelises over points.

#include <torch/extension.h>
#include <omp.h>
#include <cmath>
#include <cstdint>
#include <type_traits>

namespace {

struct Corners {
    uint32_t idx[8];
    float w[8];
    float fr[3];    // fractional position in the cell per axis
    bool inside[3]; // the position was not clamped along the axis (its derivative passes)
};

static inline void level_corners(const float* p, int32_t res, uint32_t T, Corners& c) {
    const float s = (float)res;
    int32_t ix[3];
    float fr[3];
    for (int d = 0; d < 3; ++d) {
        float v = p[d];
        c.inside[d] = v >= 0.f && v <= 1.f;
        v = v < 0.f ? 0.f : (v > 1.f ? 1.f : v);
        const float pos = v * s;
        int32_t i = (int32_t)std::floor(pos);
        if (i > res - 1) i = res - 1;
        if (i < 0) i = 0;
        ix[d] = i;
        fr[d] = pos - (float)i;
        c.fr[d] = fr[d];
    }
    const uint64_t side = (uint64_t)res + 1;
    const bool dense = side * side * side <= (uint64_t)T;
    const uint32_t mask = T - 1;
    for (int k = 0; k < 8; ++k) {
        const uint32_t cx = (uint32_t)(ix[0] + (k & 1));
        const uint32_t cy = (uint32_t)(ix[1] + ((k >> 1) & 1));
        const uint32_t cz = (uint32_t)(ix[2] + ((k >> 2) & 1));
        const float wx = (k & 1) ? fr[0] : 1.f - fr[0];
        const float wy = ((k >> 1) & 1) ? fr[1] : 1.f - fr[1];
        const float wz = ((k >> 2) & 1) ? fr[2] : 1.f - fr[2];
        c.w[k] = wx * wy * wz;
        if (dense) {
            c.idx[k] = (uint32_t)(cx + side * (cy + side * cz));
        } else {
            c.idx[k] = (cx * 1u ^ cy * 2654435761u ^ cz * 805459861u) & mask;
        }
    }
}

// One level's features at a point: the corners' table entries weighted trilinearly.
template <int F>
static inline void interpolate(const float* tl, const Corners& c, float* acc) {
    for (int f = 0; f < F; ++f) acc[f] = 0.f;
    for (int k = 0; k < 8; ++k) {
        const float* e = tl + (int64_t)c.idx[k] * F;
        const float w = c.w[k];
        for (int f = 0; f < F; ++f) acc[f] += w * e[f];
    }
}

// lw: null, or per-point, per-level weights [N, L] (training's anti-aliasing weights, computed by torch) the
// features are multiplied by: the product a separate multiply would make, in the pass that interpolates.
template <int F>
void forward_impl(const float* x, const float* table, const int32_t* res, float* out, int64_t N, int L, uint32_t T,
                  const float* lw = nullptr) {
#pragma omp parallel for schedule(static)
    for (int64_t n = 0; n < N; ++n) {
        const float* p = x + 3 * n;
        float* o = out + n * (int64_t)L * F;
        Corners c;
        for (int l = 0; l < L; ++l) {
            level_corners(p, res[l], T, c);
            const float* tl = table + (int64_t)l * T * F;
            float acc[F];
            interpolate<F>(tl, c, acc);
            if (lw) {
                const float a = lw[n * L + l];
                for (int f = 0; f < F; ++f) o[l * F + f] = acc[f] * a;
            } else {
                for (int f = 0; f < F; ++f) o[l * F + f] = acc[f];
            }
        }
    }
}

// Forward times the Zip-NeRF level weight erf(1 / sqrt(8 r^2 n_l^2)) of each point's radius r, in the
// same float operations as hash_encoding.level_weights: one pass for renders (no gradient). Level by
// level: one level's table stays in the cache while every point reads it (a render's points are many).
template <int F>
void forward_aa_impl(const float* x, const float* table, const int32_t* res, const float* radius, float* out, int64_t N, int L,
                     uint32_t T) {
    for (int l = 0; l < L; ++l) {
        const float* tl = table + (int64_t)l * T * F;
        const float n_l = (float)res[l];
#pragma omp parallel for schedule(static)
        for (int64_t n = 0; n < N; ++n) {
            Corners c;
            level_corners(x + 3 * n, res[l], T, c);
            const float r0 = radius[n] < 1e-8f ? 1e-8f : radius[n];
            const float rr = r0 * n_l;
            const float arg = 1.f / std::sqrt(8.f * rr * rr);
            const float a = arg >= 4.f ? 1.f : std::erf(arg);  // erf(4) rounds to 1 in float: skip the call
            float acc[F];
            interpolate<F>(tl, c, acc);
            float* o = out + (n * (int64_t)L + l) * F;
            for (int f = 0; f < F; ++f) o[f] = acc[f] * a;
        }
    }
}

// lw: null, or per-point, per-level weights [N, L] the output was multiplied by (forward_impl's): the gradient
// reaching the table is grad_out times them, as the separate multiply's backward makes it.
template <int F>
void backward_impl(const float* x, const float* grad_out, const int32_t* res, float* grad_table, int64_t N, int L, uint32_t T,
                   const float* lw = nullptr) {
#pragma omp parallel for schedule(dynamic, 1)
    for (int l = 0; l < L; ++l) {
        float* gl = grad_table + (int64_t)l * T * F;
        Corners c;
        for (int64_t n = 0; n < N; ++n) {
            float g[F];
            const float* go = grad_out + (n * L + l) * F;
            for (int f = 0; f < F; ++f) g[f] = lw ? go[f] * lw[n * L + l] : go[f];
            bool any = false;
            for (int f = 0; f < F; ++f) any |= (g[f] != 0.f);
            if (!any) continue;
            level_corners(x + 3 * n, res[l], T, c);
            for (int k = 0; k < 8; ++k) {
                float* e = gl + (int64_t)c.idx[k] * F;
                const float w = c.w[k];
                for (int f = 0; f < F; ++f) e[f] += w * g[f];
            }
        }
    }
}

template <int F>
void backward_x_impl(const float* x, const float* table, const float* grad_out, const int32_t* res, float* grad_x, int64_t N, int L,
                     uint32_t T) {
#pragma omp parallel for schedule(static)
    for (int64_t n = 0; n < N; ++n) {
        const float* p = x + 3 * n;
        double gx[3] = {0.0, 0.0, 0.0};
        bool inside[3] = {false, false, false};
        Corners c;
        for (int l = 0; l < L; ++l) {
            const float* g = grad_out + (n * L + l) * F;
            bool any = false;
            for (int f = 0; f < F; ++f) any |= (g[f] != 0.f);
            if (!any) continue;
            level_corners(p, res[l], T, c);
            for (int d = 0; d < 3; ++d) inside[d] = c.inside[d];
            const float* tl = table + (int64_t)l * T * F;
            const float s = (float)res[l];
            for (int k = 0; k < 8; ++k) {
                const float* e = tl + (int64_t)c.idx[k] * F;
                float dot = 0.f;
                for (int f = 0; f < F; ++f) dot += g[f] * e[f];
                const float wx = (k & 1) ? c.fr[0] : 1.f - c.fr[0];
                const float wy = ((k >> 1) & 1) ? c.fr[1] : 1.f - c.fr[1];
                const float wz = ((k >> 2) & 1) ? c.fr[2] : 1.f - c.fr[2];
                const float sx = (k & 1) ? 1.f : -1.f;
                const float sy = ((k >> 1) & 1) ? 1.f : -1.f;
                const float sz = ((k >> 2) & 1) ? 1.f : -1.f;
                gx[0] += (double)(dot * s * sx * wy * wz);
                gx[1] += (double)(dot * s * wx * sy * wz);
                gx[2] += (double)(dot * s * wx * wy * sz);
            }
        }
        for (int d = 0; d < 3; ++d) grad_x[3 * n + d] = inside[d] ? (float)gx[d] : 0.f;
    }
}

void check(const torch::Tensor& x, const torch::Tensor& table, const torch::Tensor& res) {
    TORCH_CHECK(x.device().is_cpu() && table.device().is_cpu() && res.device().is_cpu(), "hashgrid cpu kernel: tensors must be on the CPU");
    TORCH_CHECK(x.dtype() == torch::kFloat32 && table.dtype() == torch::kFloat32, "hashgrid: float32 expected");
    TORCH_CHECK(res.dtype() == torch::kInt32, "hashgrid: res must be int32");
    TORCH_CHECK(x.dim() == 2 && x.size(1) == 3, "hashgrid: x must be [N, 3]");
    TORCH_CHECK(table.dim() == 3 && res.numel() == table.size(0), "hashgrid: table must be [L, T, F], res [L]");
    const int64_t T = table.size(1);
    TORCH_CHECK(T > 0 && (T & (T - 1)) == 0, "hashgrid: table size must be a power of two");
}

// Runs fn(std::integral_constant<int, F>{}) for the feature counts the kernels are compiled for.
template <typename Fn>
static void dispatch_features(int F, Fn&& fn) {
    switch (F) {
        case 1: fn(std::integral_constant<int, 1>{}); break;
        case 2: fn(std::integral_constant<int, 2>{}); break;
        case 4: fn(std::integral_constant<int, 4>{}); break;
        case 8: fn(std::integral_constant<int, 8>{}); break;
        default: TORCH_CHECK(false, "hashgrid: features per level must be 1, 2, 4 or 8");
    }
}

// The checked, contiguous inputs of an entry point and their sizes.
struct Grid {
    torch::Tensor x, table, res;
    int64_t N;
    int L, F;
    uint32_t T;
    Grid(const torch::Tensor& x_, const torch::Tensor& table_, const torch::Tensor& res_) {
        check(x_, table_, res_);
        x = x_.contiguous();
        table = table_.contiguous();
        res = res_.contiguous();
        N = x.size(0);
        L = (int)table.size(0);
        T = (uint32_t)table.size(1);
        F = (int)table.size(2);
    }
};

}  // namespace

// lw: an undefined tensor, or the per-point, per-level weights [N, L] to multiply the features by.
static torch::Tensor forward_weighted(torch::Tensor x, torch::Tensor table, torch::Tensor res, torch::Tensor lw) {
    const Grid g(x, table, res);
    const float* wp = nullptr;
    if (lw.defined()) {
        TORCH_CHECK(lw.device().is_cpu() && lw.dtype() == torch::kFloat32 && lw.dim() == 2 && lw.size(0) == g.N && lw.size(1) == g.L,
                    "hashgrid: w must be float32 [N, L] on the CPU");
        lw = lw.contiguous();
        wp = lw.data_ptr<float>();
    }
    auto out = torch::empty({g.N, g.L, g.F}, g.x.options());
    const float* xp = g.x.data_ptr<float>();
    const float* tp = g.table.data_ptr<float>();
    const int32_t* rp = g.res.data_ptr<int32_t>();
    float* op = out.data_ptr<float>();
    dispatch_features(g.F, [&](auto f) { forward_impl<decltype(f)::value>(xp, tp, rp, op, g.N, g.L, g.T, wp); });
    return out;
}

torch::Tensor hashgrid_forward(torch::Tensor x, torch::Tensor table, torch::Tensor res) {
    return forward_weighted(x, table, res, torch::Tensor());
}

torch::Tensor hashgrid_forward_w(torch::Tensor x, torch::Tensor table, torch::Tensor res, torch::Tensor w) {
    TORCH_CHECK(w.defined(), "hashgrid: w must be float32 [N, L] on the CPU");
    return forward_weighted(x, table, res, w);
}

torch::Tensor hashgrid_forward_aa(torch::Tensor x, torch::Tensor table, torch::Tensor res, torch::Tensor radius) {
    const Grid g(x, table, res);
    TORCH_CHECK(radius.device().is_cpu() && radius.dtype() == torch::kFloat32 && radius.numel() == x.size(0),
                "hashgrid: radius must be float32 [N] on the CPU");
    radius = radius.contiguous();
    auto out = torch::empty({g.N, g.L, g.F}, g.x.options());
    const float* ap = radius.data_ptr<float>();
    float* op = out.data_ptr<float>();
    dispatch_features(g.F, [&](auto f) {
        forward_aa_impl<decltype(f)::value>(g.x.data_ptr<float>(), g.table.data_ptr<float>(), g.res.data_ptr<int32_t>(), ap, op,
                                            g.N, g.L, g.T);
    });
    return out;
}

// lw: an undefined tensor, or the weights [N, L] the forward multiplied the features by.
static torch::Tensor backward_table(torch::Tensor x, torch::Tensor grad_out, torch::Tensor res, int64_t T, torch::Tensor lw) {
    TORCH_CHECK(grad_out.dim() == 3 && grad_out.size(0) == x.size(0), "hashgrid: grad_out must be [N, L, F]");
    const float* wp = nullptr;
    if (lw.defined()) {
        TORCH_CHECK(lw.device().is_cpu() && lw.dtype() == torch::kFloat32 && lw.dim() == 2 && lw.size(0) == x.size(0) &&
                    lw.size(1) == grad_out.size(1), "hashgrid: w must be float32 [N, L] on the CPU");
        lw = lw.contiguous();
        wp = lw.data_ptr<float>();
    }
    x = x.contiguous();
    grad_out = grad_out.contiguous().to(torch::kFloat32);
    res = res.contiguous();
    const int64_t N = x.size(0);
    const int L = (int)grad_out.size(1);
    const int F = (int)grad_out.size(2);
    auto grad_table = torch::zeros({L, T, F}, x.options());
    const float* xp = x.data_ptr<float>();
    const float* gp = grad_out.data_ptr<float>();
    const int32_t* rp = res.data_ptr<int32_t>();
    float* op = grad_table.data_ptr<float>();
    dispatch_features(F, [&](auto f) { backward_impl<decltype(f)::value>(xp, gp, rp, op, N, L, (uint32_t)T, wp); });
    return grad_table;
}

torch::Tensor hashgrid_backward(torch::Tensor x, torch::Tensor grad_out, torch::Tensor res, int64_t T) {
    return backward_table(x, grad_out, res, T, torch::Tensor());
}

torch::Tensor hashgrid_backward_w(torch::Tensor x, torch::Tensor grad_out, torch::Tensor res, torch::Tensor w, int64_t T) {
    TORCH_CHECK(w.defined(), "hashgrid: w must be float32 [N, L] on the CPU");
    return backward_table(x, grad_out, res, T, w);
}

torch::Tensor hashgrid_backward_x(torch::Tensor x, torch::Tensor table, torch::Tensor grad_out, torch::Tensor res) {
    const Grid g(x, table, res);
    TORCH_CHECK(grad_out.dim() == 3 && grad_out.size(0) == x.size(0) && grad_out.size(1) == table.size(0) &&
                grad_out.size(2) == table.size(2), "hashgrid: grad_out must be [N, L, F]");
    grad_out = grad_out.contiguous().to(torch::kFloat32);
    auto grad_x = torch::zeros({g.N, 3}, g.x.options());
    const float* gp = grad_out.data_ptr<float>();
    float* op = grad_x.data_ptr<float>();
    dispatch_features(g.F, [&](auto f) {
        backward_x_impl<decltype(f)::value>(g.x.data_ptr<float>(), g.table.data_ptr<float>(), gp, g.res.data_ptr<int32_t>(), op,
                                            g.N, g.L, g.T);
    });
    return grad_x;
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.def("forward", &hashgrid_forward, "hash-grid encoding forward (CPU)");
    m.def("forward_aa", &hashgrid_forward_aa, "hash-grid encoding forward times the anti-aliasing level weights (CPU, no gradient)");
    m.def("forward_w", &hashgrid_forward_w, "hash-grid encoding forward times per-point, per-level weights (CPU)");
    m.def("backward", &hashgrid_backward, "hash-grid encoding backward w.r.t. the table (CPU)");
    m.def("backward_w", &hashgrid_backward_w, "hash-grid encoding backward w.r.t. the table of forward_w (CPU)");
    m.def("backward_x", &hashgrid_backward_x, "hash-grid encoding backward w.r.t. the positions (CPU)");
}
