// The terramechanics validation whole (docs/validation.md "Terramechanics"): `sandpatch bench
// terra` with its defaults (two plates, three normal stresses, five slips; about 15 minutes on
// two cores). Asserts the fitted soil and the wheel's curve against the ranges stated there.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bench/terra.hpp"

namespace sandpatch::terra {
namespace {

TEST(TerraHeavy, SoilParametersAndTheWheelAgainstTheModel) {
  BenchTerraArgs a;
  a.scene = std::string(SANDPATCH_SOURCE_DIR) + "/scenes/wheel_on_sand.json";
  a.out = (std::filesystem::temp_directory_path() / "sandpatch_terra_heavy").string();
  ASSERT_EQ(run_bench_terra(a), 0);
  std::ifstream f(std::filesystem::path(a.out) / "terra.json");
  const nlohmann::json js = nlohmann::json::parse(f);
  // Bekker: an exponent of the order of real soils' (0.5 to 1.5), measured to +-0.1
  const double n = js["bekker"]["n"];
  EXPECT_GT(n, 0.5);
  EXPECT_LT(n, 2.0);
  EXPECT_LT(js["bekker"]["n_se"].get<double>(), 0.1);
  // Janosi-Hanamoto: a friction angle between loose sand's and a dense interlocked packing's
  const double phi = js["janosi_hanamoto"]["phi_deg"];
  EXPECT_GT(phi, 20.0);
  EXPECT_LT(phi, 65.0);
  EXPECT_GT(js["janosi_hanamoto"]["K_m"].get<double>(), 0.002);
  // the wheel: drawbar pull rises with slip (first to last by more than 10 % of the load)
  const auto& w = js["wheel"];
  ASSERT_EQ(w.size(), 5u);
  const double load = w[0]["load"];
  EXPECT_GT(w[4]["drawbar_pull"].get<double>() - w[0]["drawbar_pull"].get<double>(), 0.1 * load);
  // saturating: the second half of the slips adds less than the first (measured 265 N against 933 N)
  EXPECT_LT(w[4]["drawbar_pull"].get<double>() - w[2]["drawbar_pull"].get<double>(),
            w[2]["drawbar_pull"].get<double>() - w[0]["drawbar_pull"].get<double>());
  // slip sinkage: deeper at 60 % than at 0 % (measured 9.9 and 7.6 cm)
  EXPECT_GT(w[4]["sinkage"].get<double>(), w[0]["sinkage"].get<double>() + 0.01);
  for (const auto& p : w) {
    EXPECT_NEAR(p["vertical"].get<double>(), load, 0.1 * load);
    EXPECT_TRUE(p["model_ok"].get<bool>());
  }
}

}  // namespace
}  // namespace sandpatch::terra
