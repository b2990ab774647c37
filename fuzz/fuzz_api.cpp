// The public API as a game could call it, decoded from bytes: a small terrain (patches off),
// then a sequence of add / remove body (fuzzed definitions, out-of-range enums included),
// set transform / velocity, step and read_heights with fuzzed regions. Every call must return
// a value or errors; bodies that were accepted must stay finite.
#include <cmath>
#include <cstdint>
#include <vector>

#include "fuzz/fuzz_util.hpp"
#include "sandpatch/sandpatch.hpp"

using namespace sandpatch::api;

namespace {

// A fresh terrain per input (a few milliseconds), so that every crash reproduces from its file.
Terrain make_terrain() {
  TerrainDef d;
  d.samples_x = d.samples_z = 17;
  d.heights.assign(17 * 17, 0.0f);
  for (int j = 0; j < 17; ++j)
    for (int i = 0; i < 17; ++i) d.heights[std::size_t(j * 17 + i)] = 0.05f * float((i * 7 + j * 3) % 5);
  d.spacing = 0.5;
  d.granular_patches = false;
  auto r = Terrain::create(d);
  if (!r) __builtin_trap();
  return std::move(*r);
}

// A float that is often ordinary and sometimes extreme.
float fval(sandpatch::fuzz::Bytes& b) {
  const std::uint8_t k = b.byte();
  if (k < 200) return float(int(k) - 100) * 0.05f;
  return b.take<float>();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sandpatch::fuzz::Bytes b{data, size};
  Terrain t = make_terrain();
  std::vector<BodyHandle> mine;
  for (int op = 0; op < 64 && !b.empty(); ++op) {
    switch (b.byte() % 7) {
      case 0:
      case 1: {
        BodyDef d;
        d.shape.kind = static_cast<ShapeKind>(int(b.byte() % 7) - 1);  // -1 and 5 are out of range
        if (d.shape.kind == ShapeKind::Mesh && (b.byte() & 1)) {
          d.shape.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
          d.shape.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
          d.shape.vertices[std::size_t(b.byte() % 12)] = fval(b);
        }
        d.shape.radius = fval(b);
        d.shape.height = fval(b);
        d.shape.half_extents = {fval(b), fval(b), fval(b)};
        d.mass = fval(b);
        d.position = {4.0 + fval(b), 2.0 + fval(b), 4.0 + fval(b)};
        d.orientation = {fval(b), fval(b), fval(b), fval(b)};
        d.linear_velocity = {fval(b), fval(b), fval(b)};
        d.angular_velocity = {fval(b), fval(b), fval(b)};
        auto h = t.add_body(d);
        if (h) mine.push_back(*h);
        else if (h.errors().empty()) __builtin_trap();
        break;
      }
      case 2:
        if (!mine.empty()) {
          const std::size_t k = b.byte() % mine.size();
          (void)t.remove_body(mine[k]);
          (void)t.remove_body(mine[k]);  // stale the second time: an error, not a crash
          mine.erase(mine.begin() + long(k));
        }
        break;
      case 3:
        if (!mine.empty()) {
          const BodyHandle h = mine[b.byte() % mine.size()];
          (void)t.set_body_transform(h, {4.0 + fval(b), 2.0 + fval(b), 4.0 + fval(b)}, {fval(b), fval(b), fval(b), fval(b)});
          (void)t.set_body_velocity(h, {fval(b), fval(b), fval(b)}, {fval(b), fval(b), fval(b)});
        }
        break;
      case 4: {
        const double dt = (b.byte() & 1) ? double(fval(b)) : 1.0 / 60.0;
        (void)t.step(dt, 1 + b.byte() % 3);
        break;
      }
      case 5: {
        GridRegion r{b.take<int>(), b.take<int>(), b.take<int>(), b.take<int>()};
        if (b.byte() & 1) r = {r.i0 & 15, r.j0 & 15, r.ni & 31, r.nj & 31};
        std::vector<float> out;
        auto s = t.read_heights(r, out);
        if (s && out.size() != std::size_t(r.ni) * std::size_t(r.nj)) __builtin_trap();
        break;
      }
      case 6:
        (void)t.height_at(double(fval(b)), double(fval(b)));
        (void)t.normal_at(double(fval(b)), double(fval(b)));
        break;
    }
  }
  for (BodyHandle h : mine)
    if (!t.body_state(h)) __builtin_trap();  // an accepted, not removed body is alive
  return 0;
}
