// loadConfigString on the fuzzer's text: only std::invalid_argument may come out (the documented error type); an
// accepted config must dump and load back unchanged, build a Pipeline and take a small frame.
#include <stdexcept>

#include "FuzzSupport.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/pipeline/Pipeline.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  const std::string text(reinterpret_cast<const char *>(data), size);
  hpds::HpdsConfig config;
  try {
    config = hpds::loadConfigString(text);
  } catch (const std::invalid_argument &) {
    return 0;
  }
  const std::string dumped = hpds::dumpConfigYaml(config);
  const hpds::HpdsConfig back = hpds::loadConfigString(dumped);
  if (hpds::dumpConfigYaml(back) != dumped) hpds::fuzz::violated("dump/load round trip changed the config");

  // Accepted configs are usable ones. A few points keep every config fast (a fine max_depth on few points is cheap).
  config.threads = 1;
  hpds::Pipeline pipeline(config);
  hpds::PointLayout layout;
  for (const char *n : {"x", "y", "z"}) layout.append(n, hpds::FieldType::Float32);
  hpds::Frame frame;
  frame.points = hpds::PointBuffer(layout, 16);
  for (std::size_t i = 0; i < 16; ++i)
    for (int a = 0; a < 3; ++a)
      hpds::writeFromDouble(frame.points.record(i), layout.fields[a], 0.37 * double(i) + a + (i % 3) * 1.5);
  pipeline.addFrame(frame);
  (void)pipeline.makeCloud(pipeline.outputSamples(), false);
  return 0;
}
