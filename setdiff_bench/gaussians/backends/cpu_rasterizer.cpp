// Tile rasteriser for 3D Gaussians on the CPU: forward compositing and its exact backward pass.
//
// The maths is the one of torch_ref.py (3DGS / gsplat "classic" conventions), evaluated per pixel
// with early termination instead of over padded (tiles x pixels x Gaussians) tensors:
//   sigma = 0.5 (a dx^2 + c dy^2) + b dx dy,  dx = px - mx,  dy = py - my  (pixel centres at +0.5)
//   alpha = min(0.99, o exp(-sigma)), skipped when sigma < 0 or alpha < 1/255
//   w_i = alpha_i T_i,  T_i = prod_{j<i} (1 - alpha_j)
//   a pixel stops at the Gaussian whose inclusion would bring T below 1e-4 (that one excluded).
// Outputs: features sum_i w_i f_i and alpha sum_i w_i.
//
// Layouts (all row-major, contiguous):
//   means2d (N, 2) pixels, conics (N, 3) = (a, b, c), opacities (N), features (N, C)
//   sorted_ids (M) Gaussian ids sorted by (tile, depth); tile_starts, tile_counts (tiles_y * tiles_x)
//   image (H, W, C), alpha (H, W), final_t (H, W), stop (H, W) = list position after the last
//   Gaussian that a pixel composited (the backward pass walks positions stop-1 .. 0).
//
// Parallelism: OpenMP over tiles.  The forward pass writes disjoint pixels.  The backward pass
// accumulates per-Gaussian gradients into kSlices buffers, one per contiguous range of tiles (a fixed
// partition, whatever the thread count), and sums the buffers in slice order, so its results are the
// same bits for any thread count.  Compiled without fused multiply-adds (-ffp-contract=off), every
// float operation is rounded alone, so the bits do not depend on the CPU either.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace {

constexpr float kAlphaMax = 0.99f;
constexpr float kAlphaMin = 1.0f / 255.0f;
constexpr float kTransmittanceMin = 1e-4f;
// Backward gradient buffers: a fixed partition of the tiles, so gradients do not depend on the thread
// count (the parallelism of the backward pass is at most this; memory is kSlices x N x (6 + C) floats).
constexpr int64_t kSlices = 8;

struct Tiling {
    int width, height, tile_size, tiles_x, tiles_y;

    // Calls fn(x, y, pixel) for every image pixel of a tile, row by row (pixel = y * width + x).
    template <typename Fn>
    void for_each_pixel(int64_t tile, Fn&& fn) const {
        const int x0 = static_cast<int>(tile % tiles_x) * tile_size, y0 = static_cast<int>(tile / tiles_x) * tile_size;
        const int x1 = std::min(x0 + tile_size, width), y1 = std::min(y0 + tile_size, height);
        for (int y = y0; y < y1; ++y) {
            for (int x = x0; x < x1; ++x) fn(x, y, static_cast<int64_t>(y) * width + x);
        }
    }
};

// One Gaussian of a tile's list, gathered contiguously so the per-pixel loops read memory in order.
struct Splat {
    float mx, my, a, b, c, opacity;
    float sigma_cut;  // beyond this sigma, alpha < 1/255 for sure (the exact test runs below it)
    int64_t id;
};

// Gathers the tile's list; sigma_cut = ln(255 o) plus a margin that covers float rounding of exp.
void gather_tile(const float* means2d, const float* conics, const float* opacities, const int64_t* ids,
                 int64_t count, std::vector<Splat>& splats) {
    splats.resize(count);
    for (int64_t k = 0; k < count; ++k) {
        const int64_t g = ids[k];
        const float o = opacities[g];
        splats[k] = Splat{means2d[2 * g], means2d[2 * g + 1], conics[3 * g], conics[3 * g + 1], conics[3 * g + 2],
                          o, o > 0.0f ? std::log(255.0f * o) + 1e-3f : -1.0f, g};
    }
}

// alpha of a splat at pixel centre (px, py); 0 when skipped.  raw_alpha is o exp(-sigma).
inline float splat_alpha(const Splat& s, float px, float py, float* dx_out, float* dy_out, float* sigma_out,
                         float* raw_alpha_out) {
    const float dx = px - s.mx;
    const float dy = py - s.my;
    const float sigma = 0.5f * (s.a * dx * dx + s.c * dy * dy) + s.b * dx * dy;
    *dx_out = dx;
    *dy_out = dy;
    *sigma_out = sigma;
    if (sigma < 0.0f || sigma > s.sigma_cut) {
        *raw_alpha_out = 0.0f;
        return 0.0f;
    }
    const float raw = s.opacity * std::exp(-sigma);
    *raw_alpha_out = raw;
    const float alpha = std::min(kAlphaMax, raw);
    return alpha < kAlphaMin ? 0.0f : alpha;
}

int thread_count(int requested) {
#ifdef _OPENMP
    return std::max(1, requested);
#else
    (void)requested;
    return 1;
#endif
}

}  // namespace

extern "C" {

int setdiff_rasterize_forward(int64_t num_gaussians, int channels, const float* means2d, const float* conics,
                              const float* opacities, const float* features, const int64_t* sorted_ids,
                              const int64_t* tile_starts, const int64_t* tile_counts, int width, int height,
                              int tile_size, int tiles_x, int tiles_y, float* image, float* alpha_out,
                              float* final_t, int32_t* stop, int num_threads) {
    (void)num_gaussians;
    const Tiling tiling{width, height, tile_size, tiles_x, tiles_y};
    const int64_t num_tiles = static_cast<int64_t>(tiles_x) * tiles_y;
    const int threads = thread_count(num_threads);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int64_t tile = 0; tile < num_tiles; ++tile) {
        const int64_t start = tile_starts[tile], count = tile_counts[tile];
        std::vector<float> acc(channels);
        std::vector<Splat> splats;
        gather_tile(means2d, conics, opacities, sorted_ids + start, count, splats);
        tiling.for_each_pixel(tile, [&](int x, int y, int64_t pixel) {
            const float px = x + 0.5f, py = y + 0.5f;
            std::fill(acc.begin(), acc.end(), 0.0f);
            float transmittance = 1.0f;
            int32_t position_after_last = 0;
            for (int64_t k = 0; k < count; ++k) {
                float dx, dy, sigma, raw;
                const float alpha = splat_alpha(splats[k], px, py, &dx, &dy, &sigma, &raw);
                if (alpha == 0.0f) continue;
                const float next_t = transmittance * (1.0f - alpha);
                if (next_t < kTransmittanceMin) break;
                const float weight = alpha * transmittance;
                const float* f = features + splats[k].id * channels;
                for (int ch = 0; ch < channels; ++ch) acc[ch] += weight * f[ch];
                transmittance = next_t;
                position_after_last = static_cast<int32_t>(k + 1);
            }
            float* out = image + pixel * channels;
            for (int ch = 0; ch < channels; ++ch) out[ch] = acc[ch];
            alpha_out[pixel] = 1.0f - transmittance;
            final_t[pixel] = transmittance;
            stop[pixel] = position_after_last;
        });
    }
    return 0;
}

int setdiff_rasterize_backward(int64_t num_gaussians, int channels, const float* means2d, const float* conics,
                               const float* opacities, const float* features, const int64_t* sorted_ids,
                               const int64_t* tile_starts, const int64_t* tile_counts, int width, int height,
                               int tile_size, int tiles_x, int tiles_y, const float* final_t, const int32_t* stop,
                               const float* grad_image, const float* grad_alpha, float* grad_means2d,
                               float* grad_conics, float* grad_opacities, float* grad_features, int num_threads) {
    (void)tile_counts;  // stop[] bounds each pixel's walk
    const Tiling tiling{width, height, tile_size, tiles_x, tiles_y};
    const int64_t num_tiles = static_cast<int64_t>(tiles_x) * tiles_y;
    const int threads = thread_count(num_threads);
    // Per-slice gradient rows: means2d (2), conic (3), opacity (1), features (C).
    const int64_t row = 6 + channels;
    const int64_t slices = std::min<int64_t>(kSlices, std::max<int64_t>(num_tiles, 1));
    std::vector<std::vector<float>> buffers(slices);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int64_t slice = 0; slice < slices; ++slice) {
        std::vector<float>& grad = buffers[slice];
        grad.assign(num_gaussians * row, 0.0f);
        std::vector<float> behind(channels);  // sum over Gaussians behind of w_j f_j
        std::vector<Splat> splats;
        const int64_t first_tile = num_tiles * slice / slices, end_tile = num_tiles * (slice + 1) / slices;
        for (int64_t tile = first_tile; tile < end_tile; ++tile) {
            const int64_t start = tile_starts[tile];
            int64_t longest = 0;  // only the part of the list that some pixel composited
            tiling.for_each_pixel(tile, [&](int, int, int64_t pixel) { longest = std::max<int64_t>(longest, stop[pixel]); });
            gather_tile(means2d, conics, opacities, sorted_ids + start, longest, splats);
            tiling.for_each_pixel(tile, [&](int x, int y, int64_t pixel) {
                const float px = x + 0.5f, py = y + 0.5f;
                const float* g_image = grad_image + pixel * channels;
                const float g_alpha = grad_alpha[pixel];
                std::fill(behind.begin(), behind.end(), 0.0f);
                float behind_alpha = 0.0f;  // sum over Gaussians behind of w_j
                float transmittance_after = final_t[pixel];
                for (int64_t k = static_cast<int64_t>(stop[pixel]) - 1; k >= 0; --k) {
                    const Splat& splat = splats[k];
                    const int64_t g = splat.id;
                    float dx, dy, sigma, raw;
                    const float alpha = splat_alpha(splat, px, py, &dx, &dy, &sigma, &raw);
                    if (alpha == 0.0f) continue;
                    const float one_minus = 1.0f - alpha;
                    const float transmittance = transmittance_after / one_minus;  // T_i, before Gaussian i
                    const float weight = alpha * transmittance;
                    const float* f = features + g * channels;
                    float* gr = grad.data() + g * row;
                    float d_alpha = 0.0f;
                    for (int ch = 0; ch < channels; ++ch) {
                        gr[6 + ch] += weight * g_image[ch];
                        d_alpha += g_image[ch] * (transmittance * f[ch] - behind[ch] / one_minus);
                        behind[ch] += weight * f[ch];
                    }
                    d_alpha += g_alpha * (transmittance - behind_alpha / one_minus);
                    behind_alpha += weight;
                    transmittance_after = transmittance;
                    if (raw <= kAlphaMax) {  // alpha = o exp(-sigma) here (not clamped)
                        const float expo = raw / splat.opacity;  // exp(-sigma)
                        const float d_sigma = -d_alpha * alpha;
                        gr[0] += -d_sigma * (splat.a * dx + splat.b * dy);
                        gr[1] += -d_sigma * (splat.b * dx + splat.c * dy);
                        gr[2] += d_sigma * 0.5f * dx * dx;
                        gr[3] += d_sigma * dx * dy;
                        gr[4] += d_sigma * 0.5f * dy * dy;
                        gr[5] += d_alpha * expo;
                    }
                }
            });
        }
    }
    for (int64_t g = 0; g < num_gaussians; ++g) {
        float sums[6] = {0, 0, 0, 0, 0, 0};
        for (int64_t slice = 0; slice < slices; ++slice) {
            const float* gr = buffers[slice].data() + g * row;
            for (int i = 0; i < 6; ++i) sums[i] += gr[i];
            for (int ch = 0; ch < channels; ++ch) grad_features[g * channels + ch] += gr[6 + ch];
        }
        grad_means2d[2 * g] += sums[0];
        grad_means2d[2 * g + 1] += sums[1];
        grad_conics[3 * g] += sums[2];
        grad_conics[3 * g + 1] += sums[3];
        grad_conics[3 * g + 2] += sums[4];
        grad_opacities[g] += sums[5];
    }
    return 0;
}

}  // extern "C"
