// tests bench/bench_dem.cpp: `--repeat K` times K blocks of `--steps` steps on the one settled
// bed (the state hash after K x S steps is the hash after one block of K x S steps, the rate
// reported is the median block's), and bad arguments are refused with exit code 2 naming the
// option. (The rates themselves are a program, `sandpatch bench dem`, never a test.)
#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bench/bench.hpp"

using namespace sandpatch;

namespace {

// Runs the bench with --json and returns its last stdout line parsed.
nlohmann::json run_json(BenchDemArgs a) {
  a.json = true;
  testing::internal::CaptureStdout();
  const int rc = run_bench_dem(a);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(rc, 0) << out;
  std::istringstream lines(out);
  std::string line, last;
  while (std::getline(lines, line))
    if (!line.empty()) last = line;
  return nlohmann::json::parse(last);
}

}  // namespace

TEST(BenchDem, RepeatTimesBlocksOfOneSettledBed) {
  BenchDemArgs one;
  one.granules = 40;
  one.steps = 30;
  one.threads = 1;
  BenchDemArgs three = one;
  three.steps = 10;
  three.repeat = 3;
  const nlohmann::json a = run_json(one), b = run_json(three);
  // the same bed after the same 30 steps, however they were timed
  EXPECT_EQ(a["state_hash"], b["state_hash"]);
  EXPECT_EQ(b["repeat"], 3);
  ASSERT_EQ(b["block_sphere_steps_per_s"].size(), 3u);
  std::vector<double> r = b["block_sphere_steps_per_s"].get<std::vector<double>>();
  std::sort(r.begin(), r.end());
  EXPECT_DOUBLE_EQ(b["sphere_steps_per_s"].get<double>(), r[1]);  // the median of 3
  EXPECT_DOUBLE_EQ(b["best_sphere_steps_per_s"].get<double>(), r[2]);
  EXPECT_EQ(a["block_sphere_steps_per_s"].size(), 1u);
}

TEST(BenchDem, BadArgumentsAreRefusedNamingTheOption) {
  BenchDemArgs a;
  a.granules = 10;
  a.repeat = 0;
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_bench_dem(a), 2);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("--repeat = 0"), std::string::npos);
  a.repeat = 1;
  a.steps = 0;
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_bench_dem(a), 2);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("--steps = 0"), std::string::npos);
}

TEST(BenchDem, AlternateThreadsTimesBothCountsOnOneBed) {
  BenchDemArgs one;
  one.granules = 40;
  one.steps = 40;
  one.threads = 1;
  BenchDemArgs alt = one;
  alt.steps = 10;
  alt.repeat = 4;
  alt.alternate_threads = 2;
  const nlohmann::json a = run_json(one), b = run_json(alt);
  // blocks 1 and 3 with 1 thread, 2 and 4 with 2: the state does not depend on the threads
  EXPECT_EQ(a["state_hash"], b["state_hash"]);
  EXPECT_EQ(b["alternate_threads"], 2);
  EXPECT_EQ(b["block_sphere_steps_per_s"].size(), 2u);
  ASSERT_EQ(b["alternate_block_sphere_steps_per_s"].size(), 2u);
  std::vector<double> r = b["alternate_block_sphere_steps_per_s"].get<std::vector<double>>();
  EXPECT_DOUBLE_EQ(b["alternate_sphere_steps_per_s"].get<double>(), 0.5 * (r[0] + r[1]));  // median of 2
  EXPECT_EQ(a["alternate_block_sphere_steps_per_s"].size(), 0u);
}

TEST(BenchDem, AlternateThreadsNeedTwoBlocks) {
  BenchDemArgs a;
  a.granules = 10;
  a.alternate_threads = 2;
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_bench_dem(a), 2);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("--alternate-threads = 2"), std::string::npos);
}
