#include "CliOptions.hpp"

#include "hpds/config/ConfigYaml.hpp"

namespace hpds::cli {

void addSamplingOptions(CLI::App &app, SamplingOptions &o) {
  app.add_option("--config", o.config_file, "YAML config (see config/hpds.yaml); flags override it");
  app.add_option("--cell-size", o.cell_size, "[m] level-0 cell edge (hierarchy.cell_size)");
  app.add_option("--max-depth", o.max_depth, "finest level 0..21 (hierarchy.max_depth)");
  auto *lvl = app.add_option("--level", o.level, "write levels 0..D (output.level)");
  auto *sp = app.add_option("--spacing", o.spacing, "[m] coarsest level with r_D <= S (output.spacing)");
  lvl->excludes(sp);
  app.add_flag("--normals", o.normals, "estimate PCA normals and curvature (normals.enabled)");
  app.add_option("--order", o.order, "random | input | sphericity | surface_variation (order.type)");
  app.add_option("--seed", o.seed, "seed of the random order (order.seed)");
  app.add_option("--mode", o.mode, "scan | map (mode)");
  app.add_option("--threads", o.threads, "worker threads, 0 = all cores (threads)");
}

HpdsConfig resolveConfig(const SamplingOptions &o) {
  HpdsConfig c = o.config_file.empty() ? HpdsConfig{} : loadConfigFile(o.config_file);
  if (o.cell_size) c.hierarchy.cell_size = *o.cell_size;
  if (o.max_depth) c.hierarchy.max_depth = *o.max_depth;
  if (o.level) {
    c.output.level = *o.level;
  } else if (o.spacing) {
    c.output.level = -1;
    c.output.spacing = *o.spacing;
  }
  if (o.normals) c.normals.enabled = true;
  if (o.order) c.order.type = parseInsertionOrder(*o.order, "--order");
  if (o.seed) c.order.seed = *o.seed;
  if (o.mode) c.mode = parseMode(*o.mode, "--mode");
  if (o.threads) c.threads = *o.threads;
  validateConfig(c);
  return c;
}

}  // namespace hpds::cli
