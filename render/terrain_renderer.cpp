// GL geometry-clipmap terrain; see terrain_renderer.hpp and docs/rendering.md.
#include "render/terrain_renderer.hpp"

#include <GL/glcorearb.h>

#include <algorithm>
#include <cmath>

#include "render/shaders.hpp"

namespace sandpatch::render {

namespace {

GLint loc(unsigned prog, const char* name) { return glGetUniformLocation(prog, name); }

}  // namespace

void bind_shadow(unsigned p, const ShadowMap& s) {
  glActiveTexture(GLenum(GL_TEXTURE0 + kShadowUnit));
  glBindTexture(GL_TEXTURE_2D, s.on ? s.texture : 0);
  glActiveTexture(GL_TEXTURE0);
  glUniform1i(loc(p, "u_shadow_map"), kShadowUnit);
  glUniform1i(loc(p, "u_shadow_on"), s.on ? 1 : 0);
  glUniformMatrix4fv(loc(p, "u_shadow_matrix"), 1, GL_FALSE, s.matrix.data());
  glUniform1f(loc(p, "u_shadow_bias"), s.bias);
  glUniform1f(loc(p, "u_shadow_texel"), s.texel_m);
}

Result<std::unique_ptr<TerrainRenderer>> TerrainRenderer::create(const Heightfield& hf, const ClipmapDef& def_in) {
  ClipmapDef def = def_in;
  if (def.base_spacing <= 0) def.base_spacing = hf.spacing();
  if (auto st = validate(def); !st) return st.errors();
  GLint max_layers = 0, max_size = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (def.n + 1 > max_size)
    return Error{"", "clipmap.n", std::to_string(def.n), "must be below GL_MAX_TEXTURE_SIZE = " + std::to_string(max_size)};
  if (def.levels > max_layers)
    return Error{"", "clipmap.levels", std::to_string(def.levels),
                 "must be at most GL_MAX_ARRAY_TEXTURE_LAYERS = " + std::to_string(max_layers)};
  auto prog = build_terrain_program();
  if (!prog) return prog.errors();

  std::unique_ptr<TerrainRenderer> r(new TerrainRenderer());
  r->hf_ = &hf;
  r->def_ = def;
  r->T_ = def.n + 1;
  r->program_ = std::move(prog.value());
  r->windows_.assign(std::size_t(def.levels), LevelRect{});

  // Texture arrays: elevation (nearest; texelFetch), normals and materials (linear, repeat =
  // toroidal addressing for free since T is a power of two).
  glGenTextures(3, r->tex_);
  const GLenum formats[3] = {GL_R32F, GL_RGBA16F, GL_RGBA8};
  for (int k = 0; k < 3; ++k) {
    glBindTexture(GL_TEXTURE_2D_ARRAY, r->tex_[k]);
    glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, formats[k], r->T_, r->T_, def.levels);
    const GLint filter = k == 0 ? GL_NEAREST : GL_LINEAR;
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_REPEAT);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_REPEAT);
  }
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);

  // Degenerate border sides: triangles (v_2k, v_2k+1, v_2k+2) along a line of n vertices.
  for (int axis = 0; axis < 2; ++axis) {
    std::vector<int> xy;
    std::vector<unsigned> idx;
    for (int k = 0; k < def.n; ++k) {
      xy.push_back(axis == 0 ? k : 0);
      xy.push_back(axis == 0 ? 0 : k);
    }
    for (int k = 0; k + 2 < def.n; k += 2) idx.insert(idx.end(), {unsigned(k), unsigned(k + 1), unsigned(k + 2)});
    r->degenerate_[axis] = r->make_mesh(xy, idx);
  }
  return r;
}

TerrainRenderer::~TerrainRenderer() {
  glDeleteTextures(3, tex_);
  auto del = [](Mesh& m) {
    glDeleteVertexArrays(1, &m.vao);
    glDeleteBuffers(1, &m.vbo);
    glDeleteBuffers(1, &m.ibo);
  };
  for (auto& [k, m] : meshes_) del(m);
  del(degenerate_[0]);
  del(degenerate_[1]);
}

TerrainRenderer::Mesh TerrainRenderer::make_mesh(const std::vector<int>& xy, const std::vector<unsigned>& idx) {
  Mesh m;
  glGenVertexArrays(1, &m.vao);
  glBindVertexArray(m.vao);
  glGenBuffers(1, &m.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(xy.size() * sizeof(int)), xy.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribIPointer(0, 2, GL_INT, 2 * sizeof(int), nullptr);
  glGenBuffers(1, &m.ibo);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(idx.size() * sizeof(unsigned)), idx.data(), GL_STATIC_DRAW);
  m.indices = int(idx.size());
  glBindVertexArray(0);
  return m;
}

const TerrainRenderer::Mesh& TerrainRenderer::mesh_for(const ClipmapPiece& p) {
  if (p.kind == PieceKind::DegenerateX) return degenerate_[0];
  if (p.kind == PieceKind::DegenerateZ) return degenerate_[1];
  const auto key = std::make_pair(p.cells_x, p.cells_z);
  auto it = meshes_.find(key);
  if (it != meshes_.end()) return it->second;
  // A grid of (cx+1) x (cz+1) vertices; every cell split along its (0,0)-(1,1) diagonal (the
  // coarse-surface interpolation in terrain.vert relies on this).
  const int cx = p.cells_x, cz = p.cells_z;
  std::vector<int> xy;
  std::vector<unsigned> idx;
  for (int j = 0; j <= cz; ++j)
    for (int i = 0; i <= cx; ++i) {
      xy.push_back(i);
      xy.push_back(j);
    }
  auto v = [cx](int i, int j) { return unsigned(j * (cx + 1) + i); };
  for (int j = 0; j < cz; ++j)
    for (int i = 0; i < cx; ++i) {
      idx.insert(idx.end(), {v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      idx.insert(idx.end(), {v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  return meshes_.emplace(key, make_mesh(xy, idx)).first->second;
}

std::int64_t TerrainRenderer::write_rect(int level, const LevelRect& r) {
  if (r.empty()) return 0;
  const std::size_t count = std::size_t(r.nx) * r.nz;
  elev_.resize(count);
  normal_.resize(count * 4);
  material_.resize(count * 4);
  const float s = level_spacing(def_, level);
  const bool has_materials = hf_->layer_allocated(Layer::Material0) || hf_->layer_allocated(Layer::Material1) ||
                             hf_->layer_allocated(Layer::Material2) || hf_->layer_allocated(Layer::Material3);
  const float mdefault[4] = {hf_->layer_default(Layer::Material0), hf_->layer_default(Layer::Material1),
                             hf_->layer_default(Layer::Material2), hf_->layer_default(Layer::Material3)};
  for (int j = 0; j < r.nz; ++j) {
    for (int i = 0; i < r.nx; ++i) {
      const std::size_t k = std::size_t(j) * r.nx + i;
      const float x = float(r.x0 + i) * s, z = float(r.z0 + j) * s;
      elev_[k] = hf_->sample(x, z);
      const Eigen::Vector3f nrm = hf_->normal(x, z);
      normal_[4 * k + 0] = nrm.x();
      normal_[4 * k + 1] = nrm.y();
      normal_[4 * k + 2] = nrm.z();
      normal_[4 * k + 3] = 0;
      for (int c = 0; c < 4; ++c)
        material_[4 * k + c] = has_materials ? hf_->sample_layer(Layer(int(Layer::Material0) + c), x, z) : mdefault[c];
    }
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, r.nx);
  const GLenum fmt[3] = {GL_RED, GL_RGBA, GL_RGBA};
  const float* data[3] = {elev_.data(), normal_.data(), material_.data()};
  for (const TexelRect& t : wrap_rect(r, T_)) {
    glPixelStorei(GL_UNPACK_SKIP_PIXELS, t.src_x);
    glPixelStorei(GL_UNPACK_SKIP_ROWS, t.src_z);
    for (int k = 0; k < 3; ++k) {
      glBindTexture(GL_TEXTURE_2D_ARRAY, tex_[k]);
      glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, t.tx, t.tz, level, t.nx, t.nz, 1, fmt[k], GL_FLOAT, data[k]);
    }
  }
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  glPixelStorei(GL_UNPACK_SKIP_PIXELS, 0);
  glPixelStorei(GL_UNPACK_SKIP_ROWS, 0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  texels_total_ += std::int64_t(count);
  return std::int64_t(count);
}

std::int64_t TerrainRenderer::update(const Eigen::Vector3f& viewer) {
  viewer_ = viewer;
  std::int64_t written = 0;
  for (int l = 0; l < def_.levels; ++l) {
    const LevelRect now{level_origin(def_, l, viewer.x()), level_origin(def_, l, viewer.z()), def_.n, def_.n};
    for (const LevelRect& r : toroidal_updates(windows_[std::size_t(l)], now)) written += write_rect(l, r);
    windows_[std::size_t(l)] = now;
  }
  return written;
}

std::int64_t TerrainRenderer::heightfield_changed(GridRegion dirty) {
  std::int64_t written = 0;
  for (int l = 0; l < def_.levels; ++l) {
    const LevelRect r = dirty_level_rect(def_, l, windows_[std::size_t(l)], dirty.i0, dirty.j0, dirty.ni, dirty.nj,
                                         hf_->spacing(), hf_->samples_x(), hf_->samples_z());
    written += write_rect(l, r);
  }
  return written;
}

void TerrainRenderer::invalidate() { windows_.assign(std::size_t(def_.levels), LevelRect{}); }

int TerrainRenderer::first_active_level() const {
  for (const auto& lv : selection_.levels)
    if (lv.active) return lv.level;
  return 0;
}

void TerrainRenderer::draw(const Eigen::Matrix4f& view_proj, bool cull) {
  view_proj_ = view_proj;
  ClipmapView v;
  v.viewer = viewer_;
  v.view_proj = view_proj;
  v.cull = cull;
  v.extent_x = hf_->extent_x();
  v.extent_z = hf_->extent_z();
  v.min_height = hf_->min_height();
  v.max_height = hf_->max_height();
  v.ground_height = hf_->sample(viewer_.x(), viewer_.z());
  select_clipmap(def_, v, selection_);
  draw_selection();
}

void TerrainRenderer::redraw() { draw_selection(live_, live_bands_); }

void TerrainRenderer::draw_selection(const std::vector<Eigen::Vector4f>& cuts, const std::vector<float>& bands) {
  const unsigned p = program_.id();
  glUseProgram(p);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  for (int k = 0; k < 4; ++k) glEnable(GLenum(GL_CLIP_DISTANCE0 + k));  // the terrain's edges
  for (int k = 0; k < 3; ++k) {
    glActiveTexture(GLenum(GL_TEXTURE0 + k));
    glBindTexture(GL_TEXTURE_2D_ARRAY, tex_[k]);
  }
  bind_terrain_shadow(p, 0, shadow_steps_);  // u_elevation on unit 0, u_T, u_n, u_w, u_viewer, ...
  glUniform1i(loc(p, "u_normals"), 1);
  glUniform1i(loc(p, "u_materials"), 2);
  glUniformMatrix4fv(loc(p, "u_view_proj"), 1, GL_FALSE, view_proj_.data());
  glUniform2f(loc(p, "u_extent"), hf_->extent_x(), hf_->extent_z());
  glUniform3f(loc(p, "u_sun_dir"), sun_.x(), sun_.y(), sun_.z());
  bind_shadow(p, shadow_);
  const int n_cuts = std::min(int(cuts.size()), kMaxCuts);
  glUniform1i(loc(p, "u_cut_count"), n_cuts);
  if (n_cuts > 0) {
    std::vector<float> b(std::size_t(n_cuts), 0.0f);
    for (int k = 0; k < n_cuts && k < int(bands.size()); ++k) b[std::size_t(k)] = bands[std::size_t(k)];
    glUniform4fv(loc(p, "u_cuts"), n_cuts, cuts.front().data());
    glUniform1fv(loc(p, "u_cut_band"), n_cuts, b.data());
    glEnable(GL_BLEND);
    glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ZERO, GL_ONE);  // (the frame's alpha stays 1)
  }
  const GLint l_origin = loc(p, "u_piece_origin"), l_level = loc(p, "u_level"), l_spacing = loc(p, "u_spacing"),
              l_coarser = loc(p, "u_has_coarser");
  int current = -1;
  for (const ClipmapPiece& piece : selection_.pieces) {
    if (piece.level != current) {
      current = piece.level;
      glUniform1i(l_level, current);
      glUniform1f(l_spacing, level_spacing(def_, current));
      glUniform1i(l_coarser, current + 1 < def_.levels ? 1 : 0);
    }
    const Mesh& m = mesh_for(piece);
    glUniform2i(l_origin, piece.gx, piece.gz);
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.indices, GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(0);
  glActiveTexture(GL_TEXTURE0);
  glDisable(GL_BLEND);
  for (int k = 0; k < 4; ++k) glDisable(GLenum(GL_CLIP_DISTANCE0 + k));
}

void TerrainRenderer::bind_terrain_shadow(unsigned p, int unit, int steps) const {
  glActiveTexture(GLenum(GL_TEXTURE0 + unit));
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex_[0]);
  glActiveTexture(GL_TEXTURE0);
  glUniform1i(loc(p, "u_elevation"), unit);
  glUniform1i(loc(p, "u_T"), T_);
  glUniform1i(loc(p, "u_n"), def_.n);
  glUniform1f(loc(p, "u_w"), float(transition_width(def_)));
  glUniform2f(loc(p, "u_viewer"), viewer_.x(), viewer_.z());
  glUniform1f(loc(p, "u_base_spacing"), def_.base_spacing);
  glUniform1i(loc(p, "u_levels"), def_.levels);
  glUniform1i(loc(p, "u_terrain_shadow_steps"), steps);
  if (steps > 0) glUniform1f(loc(p, "u_max_height"), hf_->max_height());  // cached per tile
  const int n_live = std::min(int(live_.size()), kMaxCuts);  // terrain_shadow.glsl's kMaxLive
  glUniform1i(loc(p, "u_live_count"), n_live);
  if (n_live > 0) glUniform4fv(loc(p, "u_live"), n_live, live_.front().data());
}

std::vector<float> TerrainRenderer::read_texture(int which, int level) const {
  const int comps = which == 0 ? 1 : 4;
  std::vector<float> all(std::size_t(T_) * T_ * def_.levels * comps);
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex_[which]);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glGetTexImage(GL_TEXTURE_2D_ARRAY, 0, which == 0 ? GL_RED : GL_RGBA, GL_FLOAT, all.data());
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  const std::size_t layer = std::size_t(T_) * T_ * comps;
  return std::vector<float>(all.begin() + std::ptrdiff_t(layer * level), all.begin() + std::ptrdiff_t(layer * (level + 1)));
}

}  // namespace sandpatch::render
