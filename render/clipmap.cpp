// Geometry-clipmap selection (Asirvatham & Hoppe 2005); formulas in clipmap.hpp.
#include "render/clipmap.hpp"

#include <Eigen/LU>
#include <cmath>
#include <string>

namespace sandpatch::render {

namespace {

Error def_error(const std::string& field, const std::string& value, const std::string& allowed) {
  return Error{"", "clipmap." + field, value, allowed};
}

int mod_pos(int a, int b) { return ((a % b) + b) % b; }

}  // namespace

Status validate(const ClipmapDef& d) {
  std::vector<Error> es;
  bool pow2 = false;
  for (int k = 3; k <= 12; ++k) pow2 = pow2 || d.n == (1 << k) - 1;
  if (!pow2) es.push_back(def_error("n", std::to_string(d.n), "must be 2^k - 1 with k in [3, 12] (7, 15, 31, ..., 4095)"));
  if (d.levels < 1 || d.levels > 24) es.push_back(def_error("levels", std::to_string(d.levels), "must be in [1, 24]"));
  if (!(d.base_spacing > 0) || !std::isfinite(d.base_spacing))
    es.push_back(def_error("base_spacing", std::to_string(d.base_spacing), "must be > 0 and finite (m)"));
  if (pow2 && d.transition != 0 && (d.transition < 1 || d.transition > (d.n - 1) / 2 - 2))
    es.push_back(def_error("transition", std::to_string(d.transition),
                           "must be 0 (= n/10) or in [1, " + std::to_string((d.n - 1) / 2 - 2) + "] vertices"));
  if (!(d.height_factor >= 0) || !std::isfinite(d.height_factor))
    es.push_back(def_error("height_factor", std::to_string(d.height_factor), "must be >= 0 and finite"));
  if (!es.empty()) return es;
  return Ok{};
}

std::int64_t ClipmapPiece::triangles() const {
  if (kind == PieceKind::DegenerateX) return cells_x / 2;
  if (kind == PieceKind::DegenerateZ) return cells_z / 2;
  return 2 * std::int64_t(cells_x) * cells_z;
}

LevelRect ClipmapLevel::vertices() const { return {origin_x, origin_z, n, n}; }

int level_origin(const ClipmapDef& def, int level, double v) {
  const double s2 = 2.0 * double(level_spacing(def, level));
  const int c = int(std::floor(v / s2));
  return 2 * c - 2 * block_size(def) + 2;
}

std::array<Eigen::Vector4f, 6> frustum_planes(const Eigen::Matrix4f& m) {
  const Eigen::Vector4f r0 = m.row(0).transpose(), r1 = m.row(1).transpose(), r2 = m.row(2).transpose(),
                        r3 = m.row(3).transpose();
  std::array<Eigen::Vector4f, 6> p = {r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2, r3 - r2};
  for (auto& q : p) {
    const float len = q.head<3>().norm();
    if (len > 0) q /= len;
  }
  return p;
}

bool box_outside(const std::array<Eigen::Vector4f, 6>& planes, const Eigen::Vector3f& lo,
                 const Eigen::Vector3f& hi) {
  for (const auto& p : planes) {
    // The box corner furthest along the plane normal.
    const float x = p.x() >= 0 ? hi.x() : lo.x();
    const float y = p.y() >= 0 ? hi.y() : lo.y();
    const float z = p.z() >= 0 ? hi.z() : lo.z();
    if (p.x() * x + p.y() * y + p.z() * z + p.w() < 0) return true;
  }
  return false;
}

std::array<Eigen::Vector3f, 8> frustum_corners(const Eigen::Matrix4f& view_proj) {
  const Eigen::Matrix4f inv = view_proj.inverse();
  std::array<Eigen::Vector3f, 8> c;
  int k = 0;
  for (float z : {-1.0f, 1.0f})
    for (float y : {-1.0f, 1.0f})
      for (float x : {-1.0f, 1.0f}) {
        const Eigen::Vector4f p = inv * Eigen::Vector4f(x, y, z, 1.0f);
        c[std::size_t(k++)] = p.head<3>() / p.w();
      }
  return c;
}

bool box_outside(const std::array<Eigen::Vector4f, 6>& planes, const std::array<Eigen::Vector3f, 8>& corners,
                 const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  if (box_outside(planes, lo, hi)) return true;
  // The other separating axes that matter for big boxes: the box's own faces.
  for (int a = 0; a < 3; ++a) {
    bool all_below = true, all_above = true;
    for (const auto& c : corners) {
      all_below = all_below && c[a] < lo[a];
      all_above = all_above && c[a] > hi[a];
    }
    if (all_below || all_above) return true;
  }
  return false;
}

void select_clipmap(const ClipmapDef& def, const ClipmapView& view, ClipmapSelection& out) {
  assert(validate(def).ok());
  out.levels.clear();
  out.pieces.clear();
  out.triangles = 0;
  out.culled_pieces = 0;
  const int n = def.n, m = block_size(def);
  const auto planes = frustum_planes(view.view_proj);
  const auto corners = frustum_corners(view.view_proj);

  // Active levels: a level is too fine when its extent is below height_factor * height above
  // the terrain (the coarsest level is always active).
  const float h_above = std::fabs(view.viewer.y() - view.ground_height);
  int finest = def.levels - 1;
  for (int l = 0; l < def.levels; ++l) {
    if (float(n - 1) * level_spacing(def, l) >= def.height_factor * h_above) {
      finest = l;
      break;
    }
  }
  for (int l = 0; l < def.levels; ++l) {
    ClipmapLevel lv;
    lv.level = l;
    lv.n = n;
    lv.spacing = level_spacing(def, l);
    lv.origin_x = level_origin(def, l, view.viewer.x());
    lv.origin_z = level_origin(def, l, view.viewer.z());
    lv.active = l >= finest;
    lv.finest = l == finest;
    out.levels.push_back(lv);
  }

  // Cell boundaries of the 5 segments per axis: block, block, fix-up, block, block.
  const int b[6] = {0, m - 1, 2 * m - 2, 2 * m, 3 * m - 1, 4 * m - 2};
  auto emit = [&](const ClipmapLevel& lv, PieceKind kind, int cx0, int cz0, int ncx, int ncz) {
    ClipmapPiece p{lv.level, kind, lv.origin_x + cx0, lv.origin_z + cz0, ncx, ncz};
    const float s = lv.spacing;
    const float x0 = float(p.gx) * s, x1 = float(p.gx + ncx) * s;
    const float z0 = float(p.gz) * s, z1 = float(p.gz + ncz) * s;
    const bool off_terrain = x1 < 0 || z1 < 0 || x0 > view.extent_x || z0 > view.extent_z;
    const bool off_view = view.cull && box_outside(planes, corners, {x0, view.min_height, z0}, {x1, view.max_height, z1});
    if (off_terrain || off_view) {
      ++out.culled_pieces;
      return;
    }
    out.triangles += p.triangles();
    out.pieces.push_back(p);
  };
  for (const auto& lv : out.levels) {
    if (!lv.active) continue;
    for (int i : {0, 1, 3, 4}) {
      for (int j : {0, 1, 3, 4}) {
        const bool ring = i == 0 || i == 4 || j == 0 || j == 4;
        if (ring || lv.finest) emit(lv, PieceKind::Block, b[i], b[j], m - 1, m - 1);
      }
    }
    // Ring fix-ups (m x 3 vertices) in the middle of each side.
    for (int j : {0, 4}) emit(lv, PieceKind::FixupX, b[2], b[j], 2, m - 1);
    for (int i : {0, 4}) emit(lv, PieceKind::FixupZ, b[i], b[2], m - 1, 2);
    if (lv.finest) {
      // The fix-up cross through the middle.
      for (int j : {1, 3}) emit(lv, PieceKind::FixupX, b[2], b[j], 2, m - 1);
      for (int i : {1, 3}) emit(lv, PieceKind::FixupZ, b[i], b[2], m - 1, 2);
      emit(lv, PieceKind::FixupX, b[2], b[2], 2, 2);
    } else {
      // Interior trim: the coarse cell level l-1 leaves on the high side (C even) or low side.
      const ClipmapLevel& inner = out.levels[std::size_t(lv.level - 1)];
      const bool x_high = mod_pos(inner.origin_x + 2 * m - 2, 4) == 0;  // C_{l-1} = (O + 2m - 2) / 2 even
      const bool z_high = mod_pos(inner.origin_z + 2 * m - 2, 4) == 0;
      const int tx = x_high ? 3 * m - 2 : m - 1;
      const int tz = z_high ? 3 * m - 2 : m - 1;
      emit(lv, PieceKind::TrimX, tx, m - 1, 1, 2 * m);
      emit(lv, PieceKind::TrimZ, x_high ? m - 1 : m, tz, 2 * m - 1, 1);
    }
    emit(lv, PieceKind::DegenerateX, 0, 0, n - 1, 0);
    emit(lv, PieceKind::DegenerateX, 0, n - 1, n - 1, 0);
    emit(lv, PieceKind::DegenerateZ, 0, 0, 0, n - 1);
    emit(lv, PieceKind::DegenerateZ, n - 1, 0, 0, n - 1);
  }
}

std::vector<LevelRect> toroidal_updates(const LevelRect& before, const LevelRect& now) {
  std::vector<LevelRect> r;
  if (now.empty()) return r;
  const int bx1 = before.x0 + before.nx, bz1 = before.z0 + before.nz;
  const int nx1 = now.x0 + now.nx, nz1 = now.z0 + now.nz;
  const int ix0 = std::max(before.x0, now.x0), ix1 = std::min(bx1, nx1);
  const int iz0 = std::max(before.z0, now.z0), iz1 = std::min(bz1, nz1);
  if (before.empty() || ix0 >= ix1 || iz0 >= iz1) {
    r.push_back(now);
    return r;
  }
  // Full-width rows of `now` outside before's z range, then the columns of the shared rows.
  if (now.z0 < iz0) r.push_back({now.x0, now.z0, now.nx, iz0 - now.z0});
  if (nz1 > iz1) r.push_back({now.x0, iz1, now.nx, nz1 - iz1});
  if (now.x0 < ix0) r.push_back({now.x0, iz0, ix0 - now.x0, iz1 - iz0});
  if (nx1 > ix1) r.push_back({ix1, iz0, nx1 - ix1, iz1 - iz0});
  return r;
}

std::vector<TexelRect> wrap_rect(const LevelRect& r, int T) {
  assert(r.nx <= T && r.nz <= T);
  std::vector<TexelRect> out;
  if (r.empty()) return out;
  struct Span { int t, n, src; };
  auto split = [T](int g0, int len) {
    std::vector<Span> s;
    const int t0 = mod_pos(g0, T);
    const int first = std::min(len, T - t0);
    s.push_back({t0, first, 0});
    if (len > first) s.push_back({0, len - first, first});
    return s;
  };
  for (const Span& z : split(r.z0, r.nz))
    for (const Span& x : split(r.x0, r.nx)) out.push_back({x.t, z.t, x.n, z.n, x.src, z.src});
  return out;
}

LevelRect dirty_level_rect(const ClipmapDef& def, int level, const LevelRect& lr, int i0, int j0, int ni,
                           int nj, float hf_spacing, int samples_x, int samples_z) {
  if (ni <= 0 || nj <= 0 || lr.empty()) return {};
  const double s = double(level_spacing(def, level)), h = double(hf_spacing);
  // Positions whose bilinear value or normal reads a sample in [i0, i0+ni): [(i0-1) h, (i0+ni) h];
  // an edge sample also stands for everything beyond the edge.
  auto range = [&](int a0, int na, int samples, int l0, int ln, int& g0, int& g1) {
    const double lo = a0 <= 0 ? -1e300 : double(a0 - 1) * h;
    const double hi = a0 + na >= samples ? 1e300 : double(a0 + na) * h;
    const double glo = std::max(double(l0), std::ceil(lo / s));
    const double ghi = std::min(double(l0 + ln - 1), std::floor(hi / s));
    g0 = int(glo);
    g1 = int(ghi);
  };
  int x0, x1, z0, z1;
  range(i0, ni, samples_x, lr.x0, lr.nx, x0, x1);
  range(j0, nj, samples_z, lr.z0, lr.nz, z0, z1);
  if (x1 < x0 || z1 < z0) return {};
  return {x0, z0, x1 - x0 + 1, z1 - z0 + 1};
}

}  // namespace sandpatch::render
