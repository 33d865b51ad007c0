#include "hpds/io/InputFolders.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <ostream>
#include <stdexcept>

#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/PoseFile.hpp"

namespace hpds {

namespace {

bool isDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

}  // namespace

bool plyMarkedAsSamples(const std::string &path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(256, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  return head.rfind("ply", 0) == 0 && head.find(std::string("\n") + kPlySamplesComment + "\n") != std::string::npos;
}

bool naturalLess(const std::string &a, const std::string &b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (isDigit(a[i]) && isDigit(b[j])) {
      // Compare the digit runs as numbers: without leading zeros, the longer is larger, else by text.
      std::size_t ie = i, je = j;
      while (ie < a.size() && isDigit(a[ie])) ++ie;
      while (je < b.size() && isDigit(b[je])) ++je;
      std::size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      if (const int c = a.compare(is, ie - is, b, js, je - js); c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;  // equal values: fewer leading zeros first
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

std::vector<std::string> expandInputFolders(const std::vector<std::string> &given, std::ostream &notes) {
  namespace fs = std::filesystem;
  std::vector<std::string> inputs;
  for (const std::string &in : given) {
    std::error_code ec;
    if (!fs::is_directory(in, ec)) {
      inputs.push_back(in);
      continue;
    }
    std::vector<std::string> files;
    for (const fs::directory_entry &e : fs::directory_iterator(in, ec)) {
      const std::string name = e.path().filename().string();
      std::string ext = e.path().extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
      if (!(ext == ".pcd" || ext == ".ply" || ext == ".bin") || !e.is_regular_file(ec)) continue;
      if (name.front() == '.') {
        notes << "hpds: note: '" << e.path().string() << "' left out of folder '" << in << "': a hidden file\n";
      } else if (ext == ".ply" && plyMarkedAsSamples(e.path().string())) {
        notes << "hpds: note: '" << e.path().string() << "' left out of folder '" << in
              << "': samples written by hpds (an output, not a frame; name it to take it)\n";
      } else {
        files.push_back(e.path().string());
      }
    }
    if (ec) throw std::invalid_argument("input folder '" + in + "': " + ec.message());
    if (files.empty()) throw std::invalid_argument("input folder '" + in + "' holds no .pcd, .ply or .bin frame");
    std::sort(files.begin(), files.end(), naturalLess);
    notes << "hpds: folder '" << in << "': " << files.size() << " input" << (files.size() == 1 ? "" : "s")
          << " in name order, '" << fs::path(files.front()).filename().string() << "' to '"
          << fs::path(files.back()).filename().string() << "'\n";
    inputs.insert(inputs.end(), files.begin(), files.end());
  }
  return inputs;
}

std::string inputOrderWarning(const std::vector<std::string> &inputs) {
  namespace fs = std::filesystem;
  // Each file against the previous one of its folder: frames of several folders may come folder after folder.
  std::map<std::string, std::string> last_in_folder;
  for (const std::string &in : inputs) {
    const fs::path path(in);
    const std::string folder = path.parent_path().string(), name = path.filename().string();
    const auto [it, first] = last_in_folder.try_emplace(folder, name);
    if (!first && naturalLess(name, it->second)) {
      const std::string shown = folder.empty() ? "." : folder;
      return "'" + (fs::path(folder) / it->second).string() + "' is given before '" + in +
             "': frames are taken in the order given, and pose line K goes to frame K (a shell glob such as " +
             (fs::path(shown) / "*.pcd").string() + " sorts names as text, f_10 before f_2); give the folder '" +
             shown + "' itself to take its frames in name order";
    }
    it->second = name;
  }
  return "";
}

std::string checkPosesMatchInputs(const std::string &poses_path, std::size_t poses,
                                  const std::vector<std::string> &inputs) {
  if (poses != inputs.size()) throw std::invalid_argument(poseCountMismatch(poses_path, poses, inputs.size()));
  const std::string order = inputOrderWarning(inputs);
  return order.empty() ? order : "--poses: " + order;
}

}  // namespace hpds
