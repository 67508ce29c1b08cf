// SPDX-License-Identifier: Apache-2.0
// cpm table3: Elkady's Table 3 under the reference conditions of docs/model.md.
#include <cstdio>

#include "cli.hpp"
#include "cpm/sim/table3.hpp"

namespace cpm::cli {
namespace {

int run(const std::optional<std::string>& json_path) {
  const auto rows = sim::reproduce_table3();
  std::printf("Elkady Table 3, paper's circle, 1 kHz ZOH, RK4 x10, RMSE over 4000 samples\n\n");
  std::printf("%-16s %9s %6s | %-28s | %-20s | %s\n", "controller", "Kp", "Kd",
              "position RMSE (mm)", "velocity RMSE (mm/s)", "saturated");
  std::printf("%-16s %9s %6s | %8s %8s %10s | %8s %10s | %s\n", "", "", "", "ours", "paper",
              "indep.", "ours", "paper", "samples");
  bool all_ok = true;
  for (const auto& r : rows) {
    if (!r.fault) all_ok = false;
    std::printf("%-16s %9.2f %6.0f | %8.4f %8.4f %10.4f | %8.3f %10.3f | %ld%s\n",
                ctl::law_name(r.law), r.gains.kp.x(), r.gains.kd.x(),
                r.metrics.position_rmse * 1e3, r.paper_position_rmse * 1e3,
                r.independent_position_rmse * 1e3, r.metrics.velocity_rmse * 1e3,
                r.paper_velocity_rmse * 1e3, r.metrics.saturated_samples,
                r.fault ? "" : ("  FAILED: " + describe(r.fault)).c_str());
  }
  std::printf("\ndeviation from the independent figures:");
  for (const auto& r : rows)
    std::printf(" %s %+.3f %%", ctl::law_name(r.law),
                100.0 * (r.metrics.position_rmse / r.independent_position_rmse - 1.0));
  std::printf("\n");
  if (json_path) {
    Json controllers = Json::array();
    for (const auto& r : rows)
      controllers.push_back({{"name", ctl::law_name(r.law)},
                             {"kp", r.gains.kp.x()},
                             {"kd", r.gains.kd.x()},
                             {"position_rmse", r.metrics.position_rmse},
                             {"velocity_rmse", r.metrics.velocity_rmse},
                             {"position_max", r.metrics.position_max},
                             {"saturated_samples", r.metrics.saturated_samples},
                             {"paper_position_rmse", r.paper_position_rmse},
                             {"paper_velocity_rmse", r.paper_velocity_rmse},
                             {"independent_position_rmse", r.independent_position_rmse},
                             {"ok", static_cast<bool>(r.fault)}});
    write_json(*json_path, Json{{"conditions",
                                 {{"rate_hz", 1000},
                                  {"rk4_substeps", 10},
                                  {"samples", 4000},
                                  {"trajectory", "elkady_circle"},
                                  {"force_limit", 120}}},
                                {"controllers", controllers}});
  }
  return all_ok ? 0 : 1;
}

const Command reg{"table3", "reproduce Elkady's Table 3 (four controllers on the paper's circle)", [](CLI::App& app) {
                    auto json = std::make_shared<std::optional<std::string>>();
                    app.add_option("--json", *json, "also write the table as JSON to FILE (SI units: m, m/s)")
                        ->type_name("FILE");
                    app.footer("Exit status 1 when a controller stops on a fault before the end of the circle.");
                    return [json] { return run(*json); };
                  }};

}  // namespace
}  // namespace cpm::cli
