// tests particles/gpu/gl_pool.cpp: fill in chunks within the per-frame upload budget,
// sleep and wake, exhaustion errors naming the capacity, release and refill, no GL leaks.
#include "particles/gpu/gl_pool.hpp"

#include <GL/glcorearb.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "gl/context.hpp"

namespace sandpatch::gpu {
namespace {

GlPoolDef pool_def() {
  GlPoolDef d;
  d.slots = 2;
  d.capacity.max_bodies = 64;
  d.capacity.max_particles = 256;
  d.capacity.bounds_min = {0, 0, 0};
  d.capacity.bounds_max = {0.13f, 0.08f, 0.13f};
  d.capacity.side_walls = true;
  d.upload_bytes_per_frame = 4096;
  return d;
}

// One layer of 5 x 5 granules just above the floor of a slot's box.
void add_layer(GlSimulation& s, float y) {
  const float r = s.def().particle_radius;
  for (int k = 0; k < 5; ++k)
    for (int i = 0; i < 5; ++i)
      ASSERT_TRUE(s.add_granule({0.012f + i * 4.8f * r, y, 0.012f + k * 4.8f * r},
                                Quat{0.3f * float(i), 0.2f * float(k), 0.1f, 1.0f})
                      .ok());
}

TEST(GlPool, FillsInBoundedChunksSleepsWakesReleasesAndRefills) {
  auto ctx = gl::Context::create();
  ASSERT_TRUE(ctx.ok()) << ctx.message();
  std::vector<unsigned> bufs;
  {
    auto pool = GlPool::create(pool_def());
    ASSERT_TRUE(pool.ok()) << pool.message();
    std::printf("%s\n", pool->report().c_str());
    for (int k = 0; k < 2; ++k) {
      // the pool holds the same memory whatever is live
      EXPECT_GT(pool->gpu_bytes(), 0u);
    }
    const std::size_t held = pool->gpu_bytes();

    // acquire a slot with its own scale and sleep settings; fill it
    SimulationDef a = pool_def().capacity;
    a.max_bodies = 40;
    a.sleep_speed = 0.01f;
    a.sleep_time = 0.05f;
    auto sa = pool->acquire(a);
    ASSERT_TRUE(sa.ok()) << sa.message();
    GlSimulation& s = pool->sim(*sa);
    add_layer(s, 0.012f);
    EXPECT_EQ(s.body_count(), 25);
    EXPECT_EQ(s.uploaded_body_count(), 0);
    const std::size_t total = s.pending_upload_bytes();
    // frames: each uploads at most upload_bytes_per_frame, the fill completes over several
    int frames_to_fill = 0;
    const double dt = 1.0 / 600;
    while (s.pending_upload_bytes() > 0) {
      ASSERT_TRUE(pool->step(dt).ok());
      EXPECT_LE(pool->last_frame_upload_bytes(), pool_def().upload_bytes_per_frame);
      EXPECT_GT(pool->last_frame_upload_bytes(), 0u);
      ++frames_to_fill;
      ASSERT_LT(frames_to_fill, 100);
    }
    std::printf("fill: %zu bytes in %d frames of <= %zu bytes\n", total, frames_to_fill,
                pool_def().upload_bytes_per_frame);
    EXPECT_GT(frames_to_fill, 1);
    EXPECT_EQ(s.uploaded_body_count(), 25);
    EXPECT_EQ(pool->gpu_bytes(), held);

    // settle until asleep, then a slept frame changes nothing, wake() wakes it
    int frames = 0;
    while (!s.asleep() && frames < 600) {
      ASSERT_TRUE(pool->step(dt).ok());
      ++frames;
    }
    ASSERT_TRUE(s.asleep()) << "max granule speed " << s.max_granule_speed();
    std::printf("asleep after %d frames (%.2f s)\n", frames, frames * dt);
    const auto before = s.state_hash();
    ASSERT_TRUE(pool->step(dt).ok());
    EXPECT_TRUE(s.last_step().slept);
    EXPECT_EQ(s.state_hash(), before);
    s.wake();
    EXPECT_FALSE(s.asleep());
    ASSERT_TRUE(pool->step(dt).ok());
    EXPECT_FALSE(s.last_step().slept);
    for (int b = 0; b < 25; ++b) EXPECT_GT(s.body_position({b}).y, 0.004f);  // resting on the floor

    // exhaustion: a def larger than the slot capacity; then every slot in use
    SimulationDef big = pool_def().capacity;
    big.max_particles = 1000;
    auto over = pool->acquire(big);
    ASSERT_FALSE(over.ok());
    EXPECT_NE(over.message().find("GlPoolDef.capacity.max_particles"), std::string::npos) << over.message();
    auto sb = pool->acquire(pool_def().capacity);
    ASSERT_TRUE(sb.ok()) << sb.message();
    auto none = pool->acquire(pool_def().capacity);
    ASSERT_FALSE(none.ok());
    EXPECT_NE(none.message().find("GlPoolDef.slots"), std::string::npos) << none.message();
    // the slot's own capacity (its def) is reported when it is full
    for (int k = 0; k < 15; ++k) ASSERT_TRUE(s.add_granule({0.06f, 0.03f + 0.012f * k, 0.06f}).ok());
    auto full = s.add_granule({0.1f, 0.07f, 0.1f});
    ASSERT_FALSE(full.ok());
    EXPECT_NE(full.message().find("max_bodies"), std::string::npos) << full.message();

    // release and refill: the slot comes back empty, with a new definition (another scale)
    ASSERT_TRUE(pool->release(*sa).ok());
    EXPECT_FALSE(pool->release(*sa).ok());
    SimulationDef c = pool_def().capacity;
    auto scale = ParticleScale::create(0.5);
    ASSERT_TRUE(scale.ok());
    c.scale = *scale;
    auto sc = pool->acquire(c);
    ASSERT_TRUE(sc.ok()) << sc.message();
    EXPECT_EQ(*sc, *sa);
    GlSimulation& s2 = pool->sim(*sc);
    EXPECT_EQ(s2.body_count(), 0);
    EXPECT_EQ(s2.time(), 0.0);
    add_layer(s2, 0.025f);
    for (int f = 0; f < 60; ++f) ASSERT_TRUE(pool->step(dt).ok());
    EXPECT_EQ(s2.uploaded_body_count(), 25);
    // gravity is scaled into the sim (g / 0.5): the layer fell from 0.025 m and rests on the floor
    for (int b = 0; b < 25; ++b) {
      EXPECT_LT(s2.body_position({b}).y, 0.0125f);
      EXPECT_GT(s2.body_position({b}).y, 0.0045f);
    }
    EXPECT_EQ(pool->gpu_bytes(), held);
    for (int k = 0; k < pool->slots(); ++k)
      if (pool->in_use(k))
        for (unsigned b : pool->sim(k).gl_buffers()) bufs.push_back(b);
  }
  ASSERT_EQ(bufs.size(), 16u);
  for (unsigned b : bufs) EXPECT_FALSE(glIsBuffer(b)) << b;
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

}  // namespace
}  // namespace sandpatch::gpu
