// 3x3 Gaussian smoothing and border-band stitching, after Leach & Marais §5.2 (particles
// to heightfield: smooth the rendered height map, write it, smooth along its border).
// Edge rule and kernel: filter.hpp.
#include "heightfield/filter.hpp"

#include <algorithm>
#include <cassert>

namespace sandpatch {

std::vector<float> gaussian3x3_values(const Heightfield& hf, GridRegion r, Layer l) {
  assert(hf.contains(r));
  if (r.empty()) return {};
  // ---- padded copy of r plus one ring of neighbours: (ni+2) x (nj+2), P(c, d) is sample
  // (i0-1+c, j0-1+d) ----
  const int pw = r.ni + 2, ph = r.nj + 2;
  std::vector<float> p(std::size_t(pw) * ph, 0.0f);
  auto P = [&](int c, int d) -> float& { return p[std::size_t(d) * pw + c]; };
  const GridRegion avail = intersect({r.i0 - 1, r.j0 - 1, pw, ph}, hf.whole());
  std::vector<float> buf(std::size_t(avail.ni) * avail.nj);
  hf.read(avail, buf.data(), l);
  const int c0 = avail.i0 - (r.i0 - 1), d0 = avail.j0 - (r.j0 - 1);  // 0 or 1
  for (int d = 0; d < avail.nj; ++d)
    std::copy_n(&buf[std::size_t(d) * avail.ni], avail.ni, &P(c0, d0 + d));
  // ---- beyond the grid edge: linear extrapolation, columns first, then whole rows ----
  const int c1 = c0 + avail.ni, d1 = d0 + avail.nj;  // one past the last available column/row
  for (int d = d0; d < d1; ++d) {
    if (c0 == 1) P(0, d) = 2 * P(1, d) - P(2, d);
    if (c1 == pw - 1) P(pw - 1, d) = 2 * P(pw - 2, d) - P(pw - 3, d);
  }
  for (int c = 0; c < pw; ++c) {
    if (d0 == 1) P(c, 0) = 2 * P(c, 1) - P(c, 2);
    if (d1 == ph - 1) P(c, ph - 1) = 2 * P(c, ph - 2) - P(c, ph - 3);
  }
  // ---- separable [1 2 1]/4 along x (rows 0..ph-1), then along z ----
  std::vector<float> hx(std::size_t(r.ni) * ph);
  for (int d = 0; d < ph; ++d)
    for (int c = 1; c <= r.ni; ++c)
      hx[std::size_t(d) * r.ni + (c - 1)] = 0.25f * (P(c - 1, d) + 2 * P(c, d) + P(c + 1, d));
  std::vector<float> out(std::size_t(r.ni) * r.nj);
  for (int d = 1; d <= r.nj; ++d)
    for (int c = 0; c < r.ni; ++c)
      out[std::size_t(d - 1) * r.ni + c] =
          0.25f * (hx[std::size_t(d - 1) * r.ni + c] + 2 * hx[std::size_t(d) * r.ni + c] +
                   hx[std::size_t(d + 1) * r.ni + c]);
  return out;
}

void gaussian3x3(Heightfield& hf, GridRegion r, Layer l) {
  const std::vector<float> v = gaussian3x3_values(hf, r, l);
  hf.write(r, v.data(), l);
}

void smooth_border_band(Heightfield& hf, GridRegion r, int width, Layer l) {
  assert(width >= 1);
  assert(hf.contains(r));
  if (r.empty()) return;
  // Band = (r grown by width) minus (r shrunk by width), clipped to the grid, cut into
  // at most four disjoint strips: bottom and top over the full grown width, left and right
  // between them.
  const GridRegion outer = intersect({r.i0 - width, r.j0 - width, r.ni + 2 * width, r.nj + 2 * width}, hf.whole());
  const int in_i0 = r.i0 + width, in_i1 = r.i0 + r.ni - width;  // inner hole [in_i0, in_i1)
  const int in_j0 = r.j0 + width, in_j1 = r.j0 + r.nj - width;
  std::vector<GridRegion> strips;
  if (in_i1 <= in_i0 || in_j1 <= in_j0) {
    strips.push_back(outer);  // r is thinner than two bands: the band is all of it
  } else {
    const int o_i1 = outer.i0 + outer.ni, o_j1 = outer.j0 + outer.nj;
    strips.push_back({outer.i0, outer.j0, outer.ni, in_j0 - outer.j0});            // bottom (small z)
    strips.push_back({outer.i0, in_j1, outer.ni, o_j1 - in_j1});                   // top
    strips.push_back({outer.i0, in_j0, in_i0 - outer.i0, in_j1 - in_j0});          // left (small x)
    strips.push_back({in_i1, in_j0, o_i1 - in_i1, in_j1 - in_j0});                 // right
  }
  // All strips are filtered from the original values before any is written.
  std::vector<std::vector<float>> values;
  for (const GridRegion& s : strips) values.push_back(gaussian3x3_values(hf, s, l));
  for (std::size_t k = 0; k < strips.size(); ++k)
    if (!strips[k].empty()) hf.write(strips[k], values[k].data(), l);
}

}  // namespace sandpatch
