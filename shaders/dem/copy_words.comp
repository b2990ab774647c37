// The host's writes into the kernels' blocks (particles/gpu/gl_impl.hpp write()): u_words
// 32-bit words from the staging buffer (binding 9, from u_src_word) into the block bound at
// binding 10 (from u_dst_word). A kernel rather than glCopyBufferSubData: on NVIDIA's driver a
// buffer copy into or out of a large block cost 50-450 us of host time each, a dispatch a few
// (docs/BENCHMARKS.md "GL backend on a GPU"). Compiled alone, after #version and SP_WG
// (particles/gpu/gl_programs.cpp): it declares no DEM block.
layout(local_size_x = SP_WG) in;

layout(std430, binding = 9) readonly buffer CopySrc { uint src[]; } CS;
layout(std430, binding = 10) writeonly buffer CopyDst { uint dst[]; } CD;
uniform uint u_src_word;
uniform uint u_dst_word;
uniform uint u_words;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i < u_words) CD.dst[u_dst_word + i] = CS.src[u_src_word + i];
}
