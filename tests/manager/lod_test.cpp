// tests manager/lod.cpp: predicted contacts against ballistic formulas, and request merging.
#include <gtest/gtest.h>

#include <cmath>

#include "heightfield/heightfield.hpp"
#include "manager/lod.hpp"

using namespace sandpatch;

namespace {

Heightfield flat(float h = 0.0f) {
  HeightfieldDef d;
  d.samples_x = d.samples_z = 101;
  d.spacing = 0.5f;
  d.initial_height = h;
  auto hf = Heightfield::create(d);
  EXPECT_TRUE(hf.ok());
  return std::move(*hf);
}

BodyMotion box_at(double x, double y, double z, double half, Eigen::Vector3d v = Eigen::Vector3d::Zero()) {
  return {{x - half, y - half, z - half}, {x + half, y + half, z + half}, v};
}

}  // namespace

// A body released at rest with its bottom 5 m above flat ground touches at
// t = sqrt(2·5/g) = 1.0096 s. With a 2 s horizon in 64 samples (31 ms apart) the predicted
// time is never late and at most one interval early.
TEST(Lod, FreeFallContactTimeMatchesBallistics) {
  Heightfield hf = flat();
  LodDef def;
  def.horizon = 2.0;
  def.samples = 64;
  def.margin = 0.0;
  auto rs = predict_contacts(hf, {box_at(20, 5.5, 20, 0.5)}, {0, -9.81, 0}, def);
  ASSERT_EQ(rs.size(), 1u);
  const double t = std::sqrt(2 * 5.0 / 9.81);
  EXPECT_LE(rs[0].time_to_contact, t);
  EXPECT_GE(rs[0].time_to_contact, t - def.horizon / def.samples - 1e-9);
  // The request covers the body's footprint plus the apron.
  EXPECT_LE(rs[0].x0, 19.5 - def.apron + 1e-9);
  EXPECT_GE(rs[0].x1, 20.5 + def.apron - 1e-9);
}

// A body beyond the horizon, one moving away from the terrain, and one off the terrain make
// no request.
TEST(Lod, NoRequestWhenNoContactWithinHorizon) {
  Heightfield hf = flat();
  LodDef def;  // 0.5 s: falls 1.23 m from rest
  auto rs = predict_contacts(
      hf, {box_at(20, 5.5, 20, 0.5), box_at(20, 1.0, 20, 0.1, {0, 30, 0}), box_at(-100, 0.2, 20, 0.1)},
      {0, -9.81, 0}, def);
  EXPECT_TRUE(rs.empty());
}

// A fast body (50 m/s sideways, 1 m up) heading for a 3 m wall at x >= 30: the contact is
// predicted where the wall is, not under the body now, and no earlier than the wall's
// distance allows (x reaches 29.9 at t = (29.9 - 10.1)/50 = 0.396 s) minus one interval.
TEST(Lod, FastBodyPredictedAtTheObstacle) {
  Heightfield hf = flat();
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 60; i < hf.samples_x(); ++i) hf.set_height(i, j, 3.0f);
  LodDef def;
  def.horizon = 0.5;
  def.samples = 50;
  auto rs = predict_contacts(hf, {box_at(10, 1.0, 20, 0.1, {50, 0, 0})}, {0, 0, 0}, def);
  ASSERT_EQ(rs.size(), 1u);
  EXPECT_GT(rs[0].x1, 29.5);
  EXPECT_GE(rs[0].time_to_contact, (29.5 - 10.1) / 50.0 - def.horizon / def.samples - 0.01);
  EXPECT_LE(rs[0].time_to_contact, (29.5 - 10.1) / 50.0 + 1e-9);
}

// Overlapping requests merge into their bounding box unless it would exceed the slot's
// largest patch; disjoint ones stay apart; order: soonest first, then fastest.
TEST(Lod, MergeOverlappingWithinCapacity) {
  PatchRequest a{0, 0, 4, 4, 0.3, 2, {0}}, b{3, 3, 6, 6, 0.1, 5, {1}}, c{20, 20, 22, 22, 0.1, 9, {2}};
  auto m = merge_requests({a, b, c}, 10.0);
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0].bodies, std::vector<int>{2});  // same time, faster
  EXPECT_EQ(m[1].bodies, (std::vector<int>{0, 1}));
  EXPECT_DOUBLE_EQ(m[1].x1, 6.0);
  EXPECT_DOUBLE_EQ(m[1].time_to_contact, 0.1);
  auto small = merge_requests({a, b}, 5.0);  // union is 6 m: too big to merge
  EXPECT_EQ(small.size(), 2u);
}

TEST(Lod, MaxHeightUnderBracketsTheRectangle) {
  Heightfield hf = flat(1.0f);
  hf.set_height(10, 10, 4.0f);  // at (5, 5)
  EXPECT_DOUBLE_EQ(max_height_under(hf, 4.8, 4.8, 4.9, 4.9), 4.0);   // inside a cell touching the peak
  EXPECT_DOUBLE_EQ(max_height_under(hf, 6.0, 6.0, 7.0, 7.0), 1.0);
  EXPECT_TRUE(std::isinf(max_height_under(hf, -5, -5, -4, -4)));
}
