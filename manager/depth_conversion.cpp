// Particles -> heightfield (Leach & Marais §5.2); see depth_conversion.hpp.
#include "manager/depth_conversion.hpp"

#include <GL/glcorearb.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "gl/context.hpp"
#include "gl/program.hpp"
#include "heightfield/filter.hpp"
#include "shaders/shaders.hpp"

namespace sandpatch {

namespace {
// A width × height image over [x0, x1] × [z0, z1] (m), every texel `fill` (m).
HeightImage blank_image(int width, int height, float x0, float z0, float x1, float z1, float fill) {
  HeightImage img;
  img.width = width;
  img.height = height;
  img.x0 = x0;
  img.z0 = z0;
  img.x1 = x1;
  img.z1 = z1;
  img.h.assign(std::size_t(width) * std::size_t(height), fill);
  return img;
}
}  // namespace

float HeightImage::box_mean(float x, float z, float hx, float hz) const {
  const float du = (x1 - x0) / float(width), dv = (z1 - z0) / float(height);
  // Texels with centres in [x - hx, x + hx]: u from ceil((x - hx - x0)/du - ½) to floor((x + hx - x0)/du - ½).
  int u0 = int(std::ceil((x - hx - x0) / du - 0.5f)), u1 = int(std::floor((x + hx - x0) / du - 0.5f));
  int v0 = int(std::ceil((z - hz - z0) / dv - 0.5f)), v1 = int(std::floor((z + hz - z0) / dv - 0.5f));
  u0 = std::clamp(u0, 0, width - 1);
  u1 = std::clamp(u1, 0, width - 1);
  v0 = std::clamp(v0, 0, height - 1);
  v1 = std::clamp(v1, 0, height - 1);
  if (u1 < u0 || v1 < v0) {  // footprint smaller than a texel: nearest texel
    const int u = std::clamp(int((x - x0) / du), 0, width - 1), v = std::clamp(int((z - z0) / dv), 0, height - 1);
    return at(u, v);
  }
  double sum = 0;
  for (int v = v0; v <= v1; ++v)
    for (int u = u0; u <= u1; ++u) sum += at(u, v);
  return float(sum / double((u1 - u0 + 1) * (v1 - v0 + 1)));
}

float HeightImage::hat_mean(float x, float z, float sp) const {
  const float du = (x1 - x0) / float(width), dv = (z1 - z0) / float(height);
  // Texels with centres strictly inside (x − sp, x + sp) × (z − sp, z + sp).
  const int u0 = std::max(0, int(std::floor((x - sp - x0) / du - 0.5f)) + 1);
  const int u1 = std::min(width - 1, int(std::ceil((x + sp - x0) / du - 0.5f)) - 1);
  const int v0 = std::max(0, int(std::floor((z - sp - z0) / dv - 0.5f)) + 1);
  const int v1 = std::min(height - 1, int(std::ceil((z + sp - z0) / dv - 0.5f)) - 1);
  double sum = 0, wsum = 0;
  // the columns' weights, the same in every row (computed once: the same values as inline)
  std::vector<double> wx(std::size_t(std::max(0, u1 - u0 + 1)));
  for (int u = u0; u <= u1; ++u) wx[std::size_t(u - u0)] = 1.0 - std::abs(double(x0) + (u + 0.5) * du - x) / sp;
  for (int v = v0; v <= v1; ++v) {
    const double wz = 1.0 - std::abs(double(z0) + (v + 0.5) * dv - z) / sp;
    if (wz <= 0) continue;
    const float* row = &h[std::size_t(v) * width];
    for (int u = u0; u <= u1; ++u) {
      const double w = wz * wx[std::size_t(u - u0)];
      if (w <= 0) continue;
      sum += w * row[u];
      wsum += w;
    }
  }
  if (wsum <= 0) return box_mean(x, z, 0.5f * sp, 0.5f * sp);  // hat narrower than a texel: nearest
  return float(sum / wsum);
}

Result<std::unique_ptr<ParticleDepthRenderer>> ParticleDepthRenderer::create(const DepthConversionDef& def) {
  if (def.resolution < 16 || def.resolution > 8192) {
    return Error{"", "depth_conversion.resolution", std::to_string(def.resolution), "must be in [16, 8192] texels"};
  }
  auto prog = gl::Program::graphics("convert/particle_depth", std::string(shaders::source("convert/particle_depth.vert")),
                                    std::string(shaders::source("convert/particle_depth.frag")));
  if (!prog) return prog.errors();
  std::unique_ptr<ParticleDepthRenderer> r(new ParticleDepthRenderer());
  r->resolution_ = def.resolution;
  r->program_ = std::move(*prog);
  glGenFramebuffers(1, &r->fbo_);
  glGenTextures(1, &r->depth_tex_);
  glBindTexture(GL_TEXTURE_2D, r->depth_tex_);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_DEPTH_COMPONENT32F, def.resolution, def.resolution);
  glBindFramebuffer(GL_FRAMEBUFFER, r->fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, r->depth_tex_, 0);
  glDrawBuffer(GL_NONE);
  glReadBuffer(GL_NONE);
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    return Error{"", "depth_conversion", "", "depth framebuffer incomplete (status " + std::to_string(status) + ")"};
  }
  glGenVertexArrays(1, &r->vao_);
  glGenBuffers(1, &r->ssbo_);
  return r;
}

ParticleDepthRenderer::~ParticleDepthRenderer() {
  if (fbo_) glDeleteFramebuffers(1, &fbo_);
  if (depth_tex_) glDeleteTextures(1, &depth_tex_);
  if (vao_) glDeleteVertexArrays(1, &vao_);
  if (ssbo_) glDeleteBuffers(1, &ssbo_);
}

Result<HeightImage> ParticleDepthRenderer::render(const float* s, std::size_t n, float x0, float z0, float x1, float z1,
                                                  float floor_y, float top_y, int resolution) {
  return render(s, n, x0, z0, x1, z1, floor_y, top_y, resolution, resolution);
}

Result<HeightImage> ParticleDepthRenderer::render(const float* s, std::size_t n, float x0, float z0, float x1, float z1,
                                                  float floor_y, float top_y, int width, int height) {
  const int w = width > 0 ? std::min(width, resolution_) : resolution_;
  const int h = height > 0 ? std::min(height, resolution_) : resolution_;
  if (!(x1 > x0) || !(z1 > z0) || !(top_y > floor_y) || !std::isfinite(x0 + x1 + z0 + z1 + floor_y + top_y)) {
    return Error{"", "depth render rectangle", "", "needs finite x1 > x0, z1 > z0, top_y > floor_y"};
  }
  // Camera at y_c = top_y looking down, near n = 0, far f = top_y - floor_y.
  const float yc = top_y, near_m = 0.0f, far_m = top_y - floor_y;
  const std::size_t bytes = std::max<std::size_t>(n, 1) * 4 * sizeof(float);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, ssbo_);
  if (bytes > ssbo_bytes_) {
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(bytes), nullptr, GL_STREAM_DRAW);
    ssbo_bytes_ = bytes;
  }
  if (n > 0) glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(n * 4 * sizeof(float)), s);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, ssbo_);

  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, w, h);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glDisable(GL_CULL_FACE);
  glClearDepth(1.0);  // the far plane: the patch floor
  glClear(GL_DEPTH_BUFFER_BIT);
  if (n > 0) {
    glUseProgram(program_.id());
    glUniform4f(glGetUniformLocation(program_.id(), "u_region"), x0, z0, x1, z1);
    glUniform3f(glGetUniformLocation(program_.id(), "u_camera"), yc, near_m, far_m);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLES, 0, GLsizei(6 * n));
    glBindVertexArray(0);
    glUseProgram(0);
  }
  HeightImage img = blank_image(w, h, x0, z0, x1, z1, 0.0f);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT, img.h.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  const std::string errs = gl::Context::drain_errors();
  if (!errs.empty()) return Error{"", "depth render", "", "OpenGL error " + errs};
  // height = y_c − n − z (f − n); row v of the image is z = z0 + (v + ½) dz (NDC y ↔ z).
  for (float& z : img.h) z = yc - near_m - z * (far_m - near_m);
  return img;
}

HeightImage render_heights_cpu(const float* s, std::size_t n, int res, float x0, float z0, float x1, float z1,
                               float floor_y) {
  return render_heights_cpu(s, n, res, res, x0, z0, x1, z1, floor_y);
}

HeightImage render_heights_cpu(const float* s, std::size_t n, int width, int height, float x0, float z0, float x1,
                               float z1, float floor_y) {
  HeightImage img = blank_image(width, height, x0, z0, x1, z1, floor_y);
  render_heights_cpu_rows(s, n, img, 0, height);
  return img;
}

void render_heights_cpu_rows(const float* s, std::size_t n, HeightImage& img, int rows0, int rows1) {
  const int res = img.width;
  const float x0 = img.x0, z0 = img.z0;
  const float du = (img.x1 - x0) / float(res), dv = (img.z1 - z0) / float(img.height);
  rows0 = std::max(rows0, 0), rows1 = std::min(rows1, img.height);
  if (rows1 <= rows0) return;
  // The rows in strips of 16, drawn in parallel: each strip draws the spheres that reach it
  // (listed first, in sphere order). A texel keeps the highest top whichever order the spheres
  // come in, so the image does not depend on the threads.
  constexpr int kStrip = 16;
  const int strips = (rows1 - rows0 + kStrip - 1) / kStrip;
  std::vector<std::vector<std::uint32_t>> reach(static_cast<std::size_t>(strips));
  for (std::size_t k = 0; k < n; ++k) {
    const float cz = s[4 * k + 2], r = s[4 * k + 3];
    const int v0 = std::max(rows0, int(std::ceil((cz - r - z0) / dv - 0.5f)));
    const int v1 = std::min(rows1 - 1, int(std::floor((cz + r - z0) / dv - 0.5f)));
    if (v1 < v0) continue;
    for (int b = (v0 - rows0) / kStrip; b <= (v1 - rows0) / kStrip; ++b) reach[std::size_t(b)].push_back(std::uint32_t(k));
  }
#pragma omp parallel for schedule(dynamic, 1) if (strips > 1 && n * std::size_t(rows1 - rows0) >= 65536)
  for (int b = 0; b < strips; ++b) {
    const int row0 = rows0 + b * kStrip, row1 = std::min(rows1, row0 + kStrip);
    for (const std::uint32_t k : reach[std::size_t(b)]) {
      const float cx = s[4 * k], cy = s[4 * k + 1], cz = s[4 * k + 2], r = s[4 * k + 3];
      const int u0 = std::max(0, int(std::ceil((cx - r - x0) / du - 0.5f)));
      const int u1 = std::min(res - 1, int(std::floor((cx + r - x0) / du - 0.5f)));
      const int v0 = std::max(row0, int(std::ceil((cz - r - z0) / dv - 0.5f)));
      const int v1 = std::min(row1 - 1, int(std::floor((cz + r - z0) / dv - 0.5f)));
      const float r2 = r * r;
      for (int v = v0; v <= v1; ++v) {
        const float z = z0 + (v + 0.5f) * dv - cz, z2 = z * z;
        if (z2 > r2) continue;  // (then x² + z² > r² for every x)
        // Branch-free along the row, so that it vectorises (sqrt without errno and selects
        // without traps: manager/CMakeLists.txt): a texel outside the circle (a < 0) keeps its
        // height. Each texel's operations are those of one texel at a time, in the same order:
        // the same image bit for bit.
        float* row = img.h.data() + std::size_t(v) * res;
        for (int u = u0; u <= u1; ++u) {
          const float x = x0 + (float(u) + 0.5f) * du - cx;
          const float a = r2 - (x * x + z2);
          const float top = a >= 0.0f ? cy + std::sqrt(a > 0.0f ? a : 0.0f) : -std::numeric_limits<float>::infinity();
          const float h = row[u];
          row[u] = h < top ? top : h;
        }
      }
    }
  }
}

void lower_by_probe(HeightImage& image, float floor_y, float probe) {
  for (float& h : image.h) h = probe_lowered(h, floor_y, probe);
}

std::vector<float> hat_means(const HeightImage& img, GridRegion r, float sp) {
  const std::size_t n = std::size_t(std::max(0, r.ni)) * std::size_t(std::max(0, r.nj));
  std::vector<float> h(n);
  if (n == 0) return h;
  // The hat is a tent in x times a tent in z, so each sample's sum is taken in two passes
  // (about half the work of one texel at a time, each texel read once a row): every row's
  // texels weighted by each sample column's tent (`rows`), then those sums weighted by each
  // sample row's tent. The texels and weights are HeightImage::hat_mean's (texel centres
  // strictly inside the tent, clipped to the image); only the order of the double sums
  // differs, and the floats agree with it (test DepthConversion.HatMeansAgreeWithHatMean).
  const float du = (img.x1 - img.x0) / float(img.width), dv = (img.z1 - img.z0) / float(img.height);
  struct Tent {
    int t0 = 0, t1 = -1;    // texels [t0, t1]
    std::vector<double> w;  // their weights (> 0; those at or below 0 left out, as hat_mean)
    double sum = 0;         // Σ w
  };
  auto tent = [&](float c, float o, float d, int texels) {
    Tent t;
    const int a = std::max(0, int(std::floor((c - sp - o) / d - 0.5f)) + 1);
    const int b = std::min(texels - 1, int(std::ceil((c + sp - o) / d - 0.5f)) - 1);
    for (int k = a; k <= b; ++k) {
      const double w = 1.0 - std::abs(double(o) + (k + 0.5) * d - c) / sp;
      if (t.t1 < t.t0) t.t0 = k;
      t.t1 = k;
      t.w.push_back(w > 0 ? w : 0.0);
      t.sum += w > 0 ? w : 0.0;
    }
    return t;
  };
  std::vector<Tent> tx(std::size_t(r.ni)), tz(std::size_t(r.nj));
  for (int i = 0; i < r.ni; ++i) tx[std::size_t(i)] = tent(float(r.i0 + i) * sp, img.x0, du, img.width);
  for (int j = 0; j < r.nj; ++j) tz[std::size_t(j)] = tent(float(r.j0 + j) * sp, img.z0, dv, img.height);
  // (the texel rows any sample row reads)
  int v_lo = img.height, v_hi = -1;
  for (const Tent& t : tz)
    if (t.t1 >= t.t0) v_lo = std::min(v_lo, t.t0), v_hi = std::max(v_hi, t.t1);
  const int rows_n = std::max(0, v_hi - v_lo + 1);
  std::vector<double> rows(std::size_t(rows_n) * std::size_t(r.ni), 0.0);
  // (rows in parallel: each row's sums are its own, so the results do not depend on the threads)
#pragma omp parallel for schedule(static) if (rows_n >= 64)
  for (int v = v_lo; v <= v_hi; ++v) {
    const float* row = &img.h[std::size_t(v) * img.width];
    double* out = &rows[std::size_t(v - v_lo) * r.ni];
    for (int i = 0; i < r.ni; ++i) {
      const Tent& t = tx[std::size_t(i)];
      double sum = 0;
      for (int u = t.t0; u <= t.t1; ++u) sum += t.w[std::size_t(u - t.t0)] * row[u];
      out[i] = sum;
    }
  }
#pragma omp parallel for schedule(static) if (n >= 64)
  for (int j = 0; j < r.nj; ++j) {
    const Tent& t = tz[std::size_t(j)];
    for (int i = 0; i < r.ni; ++i) {
      double sum = 0;
      for (int v = t.t0; v <= t.t1; ++v) sum += t.w[std::size_t(v - t.t0)] * rows[std::size_t(v - v_lo) * r.ni + i];
      const double wsum = t.sum * tx[std::size_t(i)].sum;
      h[std::size_t(j) * r.ni + i] = wsum > 0 ? float(sum / wsum) : img.hat_mean(float(r.i0 + i) * sp, float(r.j0 + j) * sp, sp);
    }
  }
  return h;
}

void write_to_heightfield(const HeightImage& image, GridRegion r, Heightfield& hf, int border_width,
                          const RenderBaseline* base, WriteStages* stages, HatMeans means) {
  const float sp = hf.spacing();
  const std::size_t n = std::size_t(r.ni) * r.nj;
  const std::vector<float> p = means.image && means.image->size() == n ? *means.image : hat_means(image, r, sp);
  hf.write(r, p.data());
  if (stages) stages->hat = p;
  if (base && base->image && base->heights && base->heights->size() == n) {
    std::vector<float> a = gaussian3x3_values(hf, r);
    const std::vector<float> p0 =
        means.baseline && means.baseline->size() == n ? *means.baseline : hat_means(*base->image, r, sp);
    if (stages) stages->hat_baseline = p0, stages->weight.assign(n, 0.0f);
    // G(P − P₀) with the change zero outside the region: [1 2 1]/4 along x, then along z.
    std::vector<float> d(n), dx(n), gd(n);
    for (std::size_t k = 0; k < n; ++k) d[k] = p[k] - p0[k] - base->rise;
    auto at = [&](const std::vector<float>& v, int i, int j) {
      return i < 0 || j < 0 || i >= r.ni || j >= r.nj ? 0.0f : v[std::size_t(j) * r.ni + i];
    };
    for (int j = 0; j < r.nj; ++j)
      for (int i = 0; i < r.ni; ++i)
        dx[std::size_t(j) * r.ni + i] = 0.25f * (at(d, i - 1, j) + 2.0f * at(d, i, j) + at(d, i + 1, j));
    for (int j = 0; j < r.nj; ++j)
      for (int i = 0; i < r.ni; ++i)
        gd[std::size_t(j) * r.ni + i] = 0.25f * (at(dx, i, j - 1) + 2.0f * at(dx, i, j) + at(dx, i, j + 1));
    std::vector<float> h(n);
    for (std::size_t k = 0; k < n; ++k) {
      const float w = base->tolerance > 0 ? std::max(0.0f, 1.0f - std::abs(gd[k]) / base->tolerance) : 0.0f;
      h[k] = w * ((*base->heights)[k] + gd[k]) + (1.0f - w) * a[k];
      if (stages) stages->weight[k] = w;
    }
    hf.write(r, h.data());
  } else {
    gaussian3x3(hf, r);
  }
  if (stages) {
    stages->blended.resize(n);
    hf.read(r, stages->blended.data());
  }
  if (border_width > 0) smooth_border_band(hf, r, border_width);
}

}  // namespace sandpatch
