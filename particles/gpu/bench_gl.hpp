// `sandpatch bench dem --backend gl`: the GL backend's throughput on the CPU benchmark's bed
// (bench/bench_dem.cpp; docs/dem-gpu.md).
#pragma once

namespace sandpatch::gpu {

// Builds the bench_dem bed of `granules` granules (same box, lattice, seed and material),
// settles it with the CPU backend (same stopping rule: max granule speed < 0.01 m/s after
// at least 0.3 s, at most 1.5 s), copies the settled bodies into a GlSimulation, runs 20
// warm-up steps, then times `steps` steps of dt = 5e-5 s on whatever renderer EGL finds, and
// then the same steps of the CPU backend on the same settled bed (cpu_sphere_steps_per_s).
// With substeps > 1 each GL step is a frame of that many substeps of 5e-5 s (a scene's frame:
// the substeps are queued and the status read back once), `steps` of them: it times the GPU's
// work without a CPU-GPU round trip per substep. Prints sphere-steps/s and the renderer; with
// json, one JSON object on the last line with sphere_steps_per_s, spheres, dt, renderer (and
// more). With the environment variable SANDPATCH_GL_PROFILE set, also the GPU time of each
// kernel (timer queries) and their sum against the wall time.
// workgroup > 0 sets GlOptions::workgroup_size (invocations per work group; the default if 0).
// idle_sims > 0 makes that many more GlSimulations of the same capacity in the same context,
// each holding the same bed, never stepped: whether a context holding a scene's pool of slots
// makes each call of the timed simulation dearer (docs/dem-gpu.md "What is left").
// capacity > granules gives the GL simulations room for that many granules (and 4 x as many
// spheres), as a scene's pool slots have: whether the buffers' size makes each call dearer.
// Exit code 0 ok, 1 runtime failure, 2 bad input.
int run_bench_dem_gl(int granules, int steps, int substeps, int workgroup, bool json, int idle_sims = 0, int capacity = 0);

}  // namespace sandpatch::gpu
