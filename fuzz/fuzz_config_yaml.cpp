// loadConfigString on the fuzzer's text: only std::invalid_argument may come out (the documented error type); an
// accepted config must dump and load back unchanged, build a Pipeline and take a small frame.
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/exceptions.h>
#include <yaml-cpp/parser.h>

#include <sstream>
#include <stdexcept>

#include "FuzzSupport.hpp"
#include "hpds/ConfigYaml.hpp"
#include "hpds/Pipeline.hpp"

namespace {

struct Ignore : YAML::EventHandler {
  void OnDocumentStart(const YAML::Mark &) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark &, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark &, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark &, const std::string &, YAML::anchor_t, const std::string &) override {}
  void OnSequenceStart(const YAML::Mark &, const std::string &, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark &, const std::string &, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

// yaml-cpp 0.7's LoadAll never returns on some malformed streams (a lone ',': yaml-cpp issue 1040), and
// loadConfigString uses it: found by this target and reported. Such streams parse as more than one document, which
// the loader refuses anyway, so they are skipped here to let the fuzzer look for other problems.
bool moreThanOneDocument(const std::string &text) {
  try {
    std::istringstream in(text);
    YAML::Parser parser(in);
    Ignore ignore;
    int documents = 0;
    while (documents < 2 && parser.HandleNextDocument(ignore)) ++documents;
    return documents > 1;
  } catch (const YAML::Exception &) {
    return false;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
  const std::string text(reinterpret_cast<const char *>(data), size);
  if (moreThanOneDocument(text)) return 0;
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
