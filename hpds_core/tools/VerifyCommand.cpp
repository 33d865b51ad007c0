// `hpds verify SAMPLING.ply --cell-size C | --spacing S [--input INPUT]`: an independent check of a written sampling (k-d trees,
// not the sampler's grids). Prints a per-level table; exit code 1 on any violation.
#include <iostream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "Commands.hpp"
#include "hpds/eval/SamplingVerifier.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds::cli {

namespace {
struct VerifyArgs {
  std::string sampling;
  CellSizeOptions cell;
  std::string input;
  int threads = 1;
};
}  // namespace

void addVerifyCommand(CLI::App &app) {
  auto a = std::make_shared<VerifyArgs>();
  CLI::App *cmd = app.add_subcommand("verify", "check a sampling: one sample per cell, additive spacing, coverage");
  cmd->add_option("sampling", a->sampling, "sampling written by hpds sample (needs x y z level)")->required();
  addCellSizeOptions(*cmd, a->cell);
  cmd->add_option("--input", a->input, "input cloud, same frame as the sampling: also check coverage <= 2 r_D");
  cmd->add_option("--threads", a->threads, "worker threads, 0 = all cores")->capture_default_str()->check(integerIn(0, 1024));
  cmd->callback([a] {
    const double cell_size = resolveCellSize(a->cell);
    const PointBuffer sampling = readPointCloud(a->sampling);
    PointBuffer input;
    if (!a->input.empty()) input = readPointCloud(a->input);
    const VerifyReport report = verifySampling(sampling, cell_size, a->input.empty() ? nullptr : &input, a->threads);
    std::cout << formatReport(report);
    const std::size_t bad = report.total_violations();
    if (bad > 0) {
      std::cout << "FAILED: " << bad << " violations\n";
      throw CLI::RuntimeError(1);
    }
    std::cout << "OK: no violations\n";
  });
}

}  // namespace hpds::cli
