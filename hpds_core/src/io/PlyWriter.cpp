#include "hpds/io/PlyWriter.hpp"

#include "io/FileAccess.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <set>
#include <stdexcept>
#include <vector>

namespace hpds {
namespace {

using io_detail::fail;

// The original PLY type names: every PLY reader knows them, while the sized aliases (int8, float32...) are an
// extension some readers lack.
const char *plyTypeName(FieldType type) {
  switch (type) {
    case FieldType::Int8:
      return "char";
    case FieldType::UInt8:
      return "uchar";
    case FieldType::Int16:
      return "short";
    case FieldType::UInt16:
      return "ushort";
    case FieldType::Int32:
      return "int";
    case FieldType::UInt32:
      return "uint";
    case FieldType::Float32:
      return "float";
    case FieldType::Float64:
      return "double";
  }
  return nullptr;
}

// A PLY header is ASCII text, and the readers refuse any other byte in it (PCL's tokenizer misreads them): a name is
// printable ASCII without spaces.
bool isValidPropertyName(const std::string &name) {
  if (name.empty()) return false;
  for (unsigned char c : name)
    if (c <= ' ' || c >= 0x7f) return false;
  return true;
}

// 3 for a PCL packed "rgb", 4 for "rgba" (one 4-byte float or uint field), written as colour channels, unless the
// cloud has a field of a channel's own name or both packed fields (whose channels would share names): then every
// field stays as it is. Else 0.
int packedColourChannels(const PointLayout &layout, const PointField &f) {
  const int channels = f.name == "rgb" ? 3 : f.name == "rgba" ? 4 : 0;
  if (channels == 0 || f.count != 1 || (f.type != FieldType::Float32 && f.type != FieldType::UInt32)) return 0;
  if (layout.find("rgb") && layout.find("rgba")) return 0;
  for (const char *channel : {"red", "green", "blue", "alpha"})
    if (layout.find(channel)) return 0;
  return channels;
}

// `name` with every byte outside printable ASCII shown as '?', for messages.
std::string printable(std::string name) {
  for (char &c : name)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) c = '?';
  return name;
}

constexpr const char *kEndHeader = "end_header\n";

// One contiguous byte range of a record that goes to the file unchanged.
struct Span {
  std::uint32_t offset;
  std::uint32_t bytes;
};

/// The header of `cloud`'s PLY file and the record bytes each row takes (refusing, with `path` in the message,
/// what no reader accepts before any file is touched).
struct PlyPlan {
  std::string header;
  std::vector<Span> spans;
  std::size_t out_step = 0;
};

PlyPlan planPly(const std::string &path, const PointBuffer &cloud, PlyContent content,
                const SamplingRecord *record = nullptr) {
  const PointLayout &layout = cloud.layout();
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("cannot write PLY: invalid layout: ") + e.what());
  }

  std::string header = "ply\nformat binary_little_endian 1.0\n";
  if (content == PlyContent::kSamples) header += std::string(kPlySamplesComment) + "\n";
  if (record) {
    try {
      header += samplingRecordLine(*record) + "\n";
    } catch (const std::invalid_argument &e) {
      fail(path, std::string("cannot write PLY: ") + e.what());
    }
  }
  if (cloud.height() > 1) {
    header += "obj_info num_cols " + std::to_string(cloud.width()) + "\n";
    header += "obj_info num_rows " + std::to_string(cloud.height()) + "\n";
  }
  header += "element vertex " + std::to_string(cloud.size()) + "\n";

  // A field of count N becomes N properties: refuse what no reader accepts before spending time on it (a
  // PointCloud2 may declare a count of 4e9 for a cloud of 0 points).
  for (const PointField &f : layout.fields)
    if (f.count > io_detail::kMaxFieldCount)
      fail(path, "cannot write PLY: field '" + f.name + "' has count " + std::to_string(f.count) + ", more than the " +
                     std::to_string(io_detail::kMaxFieldCount) + " elements a field may have");

  std::set<std::string> names;
  std::vector<Span> spans;
  std::size_t out_step = 0;
  auto addSpan = [&spans, &out_step](std::uint32_t offset, std::uint32_t bytes) {
    // Adjacent bytes merge into one span so that the copy loop below stays short for typical layouts.
    if (!spans.empty() && spans.back().offset + spans.back().bytes == offset)
      spans.back().bytes += bytes;
    else
      spans.push_back({offset, bytes});
    out_step += bytes;
  };
  for (const PointField &f : layout.fields) {
    if (const int channels = packedColourChannels(layout, f); channels > 0) {
      // PCL's packed colour (bytes b g r [a] of a little-endian 4-byte field) as the uchar red green blue [alpha]
      // properties that CloudCompare and MeshLab show as colours, and PCL reads back into rgb / rgba, as PCL's own
      // PLY writer does; a float named rgb would be a meaningless scalar to them.
      static constexpr const char *kChannel[4] = {"red", "green", "blue", "alpha"};
      static constexpr std::uint32_t kByte[4] = {2, 1, 0, 3};
      for (int c = 0; c < channels; ++c) {
        names.insert(kChannel[c]);
        header += std::string("property uchar ") + kChannel[c] + "\n";
        addSpan(f.offset + kByte[c], 1);
      }
      continue;
    }
    if (!isValidPropertyName(f.name))
      fail(path, "cannot write PLY: field name '" + printable(f.name) +
                     "' is not a valid PLY property name (printable ASCII without spaces)");
    const char *type = plyTypeName(f.type);
    const std::size_t elem = fieldTypeSize(f.type);
    for (std::uint32_t c = 0; c < f.count; ++c) {
      const std::string name = f.count == 1 ? f.name : f.name + "_" + std::to_string(c);
      if (!names.insert(name).second) fail(path, "cannot write PLY: property name '" + name + "' would appear twice");
      if (names.size() > io_detail::kMaxPlyProperties)
        fail(path, "cannot write PLY: more than " + std::to_string(io_detail::kMaxPlyProperties) +
                       " properties (fields with their counts), which readers refuse");
      header += std::string("property ") + type + " " + name + "\n";
      if (header.size() + std::strlen(kEndHeader) > io_detail::kMaxHeaderBytes)
        fail(path, "cannot write PLY: the header would exceed " + std::to_string(io_detail::kMaxHeaderBytes) +
                       " bytes (too many properties), which readers refuse");
    }
    addSpan(f.offset, static_cast<std::uint32_t>(elem * f.count));
  }
  header += kEndHeader;
  return PlyPlan{std::move(header), std::move(spans), out_step};
}

void writePlanned(AtomicFile &file, const PlyPlan &plan, const PointBuffer &cloud) {
  const PointLayout &layout = cloud.layout();
  const std::vector<Span> &spans = plan.spans;
  const std::size_t out_step = plan.out_step;
  file.write(plan.header.data(), plan.header.size());

  const std::size_t n = cloud.size();
  if (spans.size() == 1 && spans[0].offset == 0 && spans[0].bytes == layout.point_step) {
    // Records without padding are already the PLY rows.
    file.write(cloud.bytes().data(), cloud.bytes().size());
  } else if (out_step > 0) {
    constexpr std::size_t kChunkBytes = 1 << 20;
    const std::size_t points_per_chunk = std::max<std::size_t>(1, kChunkBytes / out_step);
    std::vector<std::uint8_t> chunk;
    chunk.reserve(points_per_chunk * out_step);
    for (std::size_t begin = 0; begin < n; begin += points_per_chunk) {
      const std::size_t end = std::min(n, begin + points_per_chunk);
      chunk.clear();
      for (std::size_t i = begin; i < end; ++i) {
        const std::uint8_t *rec = cloud.record(i);
        for (const Span &s : spans) chunk.insert(chunk.end(), rec + s.offset, rec + s.offset + s.bytes);
      }
      file.write(chunk.data(), chunk.size());
    }
  }
}

// The plan (made first: what no reader takes is refused before any file is touched) into a new file at `path`.
void writePlannedFile(const std::string &path, const PlyPlan &plan, const PointBuffer &cloud) {
  AtomicFile file(path);
  writePlanned(file, plan, cloud);
  file.commit();
}

}  // namespace

void writePly(const std::string &path, const PointBuffer &cloud, PlyContent content) {
  writePlannedFile(path, planPly(path, cloud, content), cloud);
}

void writePly(AtomicFile &file, const PointBuffer &cloud, PlyContent content) {
  writePlanned(file, planPly(file.target(), cloud, content), cloud);
}

void writePly(const std::string &path, const PointBuffer &cloud, const SamplingRecord &record) {
  writePlannedFile(path, planPly(path, cloud, PlyContent::kSamples, &record), cloud);
}

void writePly(AtomicFile &file, const PointBuffer &cloud, const SamplingRecord &record) {
  writePlanned(file, planPly(file.target(), cloud, PlyContent::kSamples, &record), cloud);
}

}  // namespace hpds
