// std430 layout of the GPU granule DEM's state, generated from the field lists of
// particles/fields.hpp (each field declared once, as MuJoCo's mjxmacro.h does).
//
// The GPU keeps the same structure-of-arrays as the CPU backend: one shader storage block
// per kind (particles, bodies) whose members are the field arrays, each sized by the
// simulation's fixed capacity:
//
//   layout(std430, binding = 0) buffer ParticlesA { vec4 pos[CAP]; vec4 vel[CAP]; ...
//                                                   int body[CAP]; int id[CAP]; } P;
//
// std430 rules for these members (every field is a 4-byte scalar or a 4-vector of them):
//   array of vec4/ivec4/uvec4: base alignment 16, stride 16
//   array of float/int/uint:   base alignment 4,  stride 4
//   member offset = previous member's end rounded up to the member's base alignment
// The C++ offsets below follow those rules (checked by static_assert for a sample capacity)
// and the GLSL declarations are generated from the same list, so they cannot drift apart;
// GlSimulation::create also asks the driver for the offsets it actually used
// (glGetProgramResourceiv GL_OFFSET) and refuses to run on a mismatch.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <type_traits>

#include "particles/fields.hpp"

namespace sandpatch::gpu {

// One member of a generated std430 block.
struct Std430Field {
  std::string_view name;      // the field name of fields.hpp (also the GLSL member name)
  std::string_view glsl;      // GLSL element type: float, int, uint, vec4, ivec4, uvec4
  int components = 1;         // 1 or 4
  std::size_t stride = 4;     // bytes per element (4 or 16)
  std::size_t align = 4;      // std430 base alignment of the array (4 or 16)
};

template <class T, int N>
constexpr std::string_view glsl_type() {
  static_assert(sizeof(T) == 4, "fields.hpp: every field type must be 4 bytes (std430 scalar)");
  static_assert(N == 1 || N == 4, "fields.hpp: a field has 1 or 4 components (vec3 padded to 4)");
  if constexpr (std::is_same_v<T, float>) return N == 4 ? "vec4" : "float";
  else if constexpr (std::is_same_v<T, std::int32_t>) return N == 4 ? "ivec4" : "int";
  else if constexpr (std::is_same_v<T, std::uint32_t>) return N == 4 ? "uvec4" : "uint";
  else static_assert(sizeof(T) == 0, "fields.hpp: field type must be float, int32_t or uint32_t");
}

// (the GL backend's fields only: SANDPATCH_FIELD_ON(GL, ...))
#define SP_GPU_FIELD(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(GL, backend, Std430Field{#name, glsl_type<type, n>(), n, std::size_t(4 * (n)), std::size_t((n) == 4 ? 16 : 4)},)
inline constexpr std::array kParticleFields{SANDPATCH_PARTICLE_FIELDS(SP_GPU_FIELD)};
inline constexpr std::array kBodyFields{SANDPATCH_BODY_FIELDS(SP_GPU_FIELD)};
#undef SP_GPU_FIELD

// Field indices, generated: kParticle_pos, kParticle_vel, ..., kBody_pos, ...
enum ParticleField : int {
#define SP_GPU_PIDX(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, kParticle_##name,)
  SANDPATCH_PARTICLE_FIELDS(SP_GPU_PIDX)
#undef SP_GPU_PIDX
  kParticleFieldCount
};
enum BodyField : int {
#define SP_GPU_BIDX(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, kBody_##name,)
  SANDPATCH_BODY_FIELDS(SP_GPU_BIDX)
#undef SP_GPU_BIDX
  kBodyFieldCount
};

constexpr std::size_t round_up(std::size_t v, std::size_t a) { return (v + a - 1) / a * a; }

// Byte offset of member `field` in a block of `fields` whose arrays hold `capacity` elements.
template <std::size_t N>
constexpr std::size_t std430_offset(const std::array<Std430Field, N>& fields, int field, std::size_t capacity) {
  std::size_t off = 0;
  for (int k = 0; k < field; ++k) off = round_up(off, fields[k].align) + fields[k].stride * capacity;
  return round_up(off, fields[field].align);
}
// Size of the whole block (the buffer's size), rounded to 16 bytes.
template <std::size_t N>
constexpr std::size_t std430_size(const std::array<Std430Field, N>& fields, std::size_t capacity) {
  std::size_t off = 0;
  for (const auto& f : fields) off = round_up(off, f.align) + f.stride * capacity;
  return round_up(off, 16);
}

// Compile-time checks of the generated layout at a sample capacity: members are in list
// order, aligned, do not overlap, and the block ends after the last one.
template <std::size_t N>
constexpr bool layout_is_consistent(const std::array<Std430Field, N>& fields, std::size_t capacity) {
  std::size_t end = 0;
  for (std::size_t k = 0; k < N; ++k) {
    std::size_t off = std430_offset(fields, int(k), capacity);
    if (off % fields[k].align != 0 || off < end) return false;
    if (fields[k].stride != 4u * std::size_t(fields[k].components)) return false;
    end = off + fields[k].stride * capacity;
  }
  return std430_size(fields, capacity) >= end && std430_size(fields, capacity) < end + 16;
}
static_assert(layout_is_consistent(kParticleFields, 1) && layout_is_consistent(kParticleFields, 1001));
static_assert(layout_is_consistent(kBodyFields, 1) && layout_is_consistent(kBodyFields, 1001));
static_assert(kParticleFields[kParticle_pos].components == 4 && kParticleFields[kParticle_vel].components == 4,
              "the shaders read pos.w (radius) and vel.w (inverse mass)");
static_assert(kParticleFieldCount == int(kParticleFields.size()) && kBodyFieldCount == int(kBodyFields.size()));

// GLSL text of one generated block, e.g.
//   layout(std430, binding = 0) buffer ParticlesA { vec4 pos[100]; ...; int id[100]; } P;
template <std::size_t N>
std::string glsl_block(const std::array<Std430Field, N>& fields, std::string_view block, std::string_view instance,
                       int binding, std::size_t capacity) {
  std::string s = "layout(std430, binding = " + std::to_string(binding) + ") buffer " + std::string(block) + " {\n";
  for (const auto& f : fields)
    s += "  " + std::string(f.glsl) + " " + std::string(f.name) + "[" + std::to_string(capacity) + "];\n";
  s += "} " + std::string(instance) + ";\n";
  return s;
}

// GLSL statements copying every field of element `src` of block `from` to element `dst` of
// block `to` (the permutation of the grid's counting sort), generated from the list.
template <std::size_t N>
std::string glsl_copy_all(const std::array<Std430Field, N>& fields, std::string_view to, std::string_view dst,
                          std::string_view from, std::string_view src) {
  std::string s;
  for (const auto& f : fields)
    s += std::string(to) + "." + std::string(f.name) + "[" + std::string(dst) + "] = " + std::string(from) + "." +
         std::string(f.name) + "[" + std::string(src) + "]; ";
  return s;
}

}  // namespace sandpatch::gpu
