#include "hpds/io/HierarchyFile.hpp"
#include "hpds/util/Crc32.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "hpds/io/AtomicFile.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "normals/MapNormals.hpp"

// Byte layout of version 3 (little-endian, no padding; version 2 is the same without the normals' settings and the
// free slots (its samples take ids 0..n-1), version 1 also without normal_bytes and normals):
//   0  char[8] magic "HPDSMAP\0"      8  u32 version          12 u32 header_size (bytes, CRC included)
//   16 f64 cell_size                  24 u32 max_depth        28 u32 next_frame
//   32 u64 sample_count               40 u32 point_step       44 u32 field_count
//   48 per field: u32 name_len, name bytes, u32 offset, u8 datatype, u32 count
//   then u32 normal_bytes: 0, or MapNormals::kFileBytes when the entries carry the normals a map keeps
//   then, when normal_bytes is not 0, the settings those normals were estimated with (NormalParams but threads):
//        i32 level, f64 radius, i32 k, i32 min_neighbors, i32 neighborhood_level_offset, f64 max_growth,
//        f64 line_ratio, f64 max_plane_rms, f64 up[3]
//   then u64 free_count: the free slots (ids of evicted samples not reused yet)
//   header_size - 4: u32 CRC-32 of bytes [0, header_size - 4)
//   body: free_count u32 ids, the free slots in the order they are reused (Hierarchy::freeSlots); the samples
//         hold the other ids below sample_count + free_count, in increasing order. Then
//         sample_count entries of kEntryFixedBytes + point_step + normal_bytes bytes:
//         f64 x y z, u8 level, u32 frame_index, f32 to_viewpoint[3] (unit direction since the map keeps only
//         that; older files' full vectors load the same), record bytes, the kept normal (MapNormals::save)
//   last 4 bytes: u32 CRC-32 of the body (free slots and entries)

namespace hpds {
namespace {

constexpr char kMagic[8] = {'H', 'P', 'D', 'S', 'M', 'A', 'P', '\0'};
constexpr std::size_t kFixedHeaderBytes = 48;
constexpr std::size_t kEntryFixedBytes = 3 * 8 + 1 + 4 + 3 * 4;
// Memory of one sample slot besides its record, rounded up: Hierarchy's position, level, frame and view direction
// (33 bytes), a kept normal (36) and the arrays' headroom.
constexpr std::uint64_t kSlotBytes = 96;
// Far above any real layout; they keep every size computed below from overflowing and bound the header read.
constexpr std::uint32_t kMaxHeaderBytes = 1u << 24;
constexpr std::uint32_t kMaxPointStep = 1u << 24;
constexpr std::uint32_t kMaxFieldNameBytes = 1u << 12;
// Bytes per read/write chunk: few system calls, a small buffer whatever the record size (records may be 16 MiB).
constexpr std::size_t kChunkBytes = 1u << 20;

std::size_t entriesPerChunk(std::size_t entry_bytes) { return std::max<std::size_t>(1, kChunkBytes / entry_bytes); }

static_assert(std::numeric_limits<double>::is_iec559 && sizeof(double) == 8 && sizeof(float) == 4,
              "the file stores IEEE-754 doubles and floats by their bytes");

bool hostIsLittleEndian() {
  const std::uint16_t probe = 1;
  std::uint8_t first = 0;
  std::memcpy(&first, &probe, 1);
  return first == 1;
}


[[noreturn]] void fail(const std::string &path, const std::string &what) {
  throw std::runtime_error(path + ": " + what);
}

// Appends fixed-size values in file order (the host is little-endian, checked before any file is touched).
class ByteWriter {
 public:
  template <typename T>
  void put(const T &value) {
    const auto *p = reinterpret_cast<const std::uint8_t *>(&value);
    bytes.insert(bytes.end(), p, p + sizeof(T));
  }
  void putBytes(const void *data, std::size_t n) {
    const auto *p = static_cast<const std::uint8_t *>(data);
    bytes.insert(bytes.end(), p, p + n);
  }
  std::vector<std::uint8_t> bytes;
};

// Reads fixed-size values from a byte range; running past the end is reported, never read.
class ByteReader {
 public:
  ByteReader(const std::uint8_t *data, std::size_t size) : data_(data), size_(size) {}
  template <typename T>
  bool get(T &value) {
    if (size_ - pos_ < sizeof(T)) return false;
    std::memcpy(&value, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  bool getString(std::string &s, std::size_t n) {
    if (size_ - pos_ < n) return false;
    s.assign(reinterpret_cast<const char *>(data_ + pos_), n);
    pos_ += n;
    return true;
  }
  std::size_t pos() const { return pos_; }

 private:
  const std::uint8_t *data_;
  std::size_t size_;
  std::size_t pos_ = 0;
};

// Sequential byte source over either a file descriptor or memory, so one parser serves both loaders.
class Source {
 public:
  virtual ~Source() = default;
  /// Reads exactly n bytes or returns false.
  virtual bool read(std::uint8_t *dst, std::size_t n) = 0;
};

class MemorySource final : public Source {
 public:
  MemorySource(const std::uint8_t *data, std::size_t size) : data_(data), size_(size) {}
  bool read(std::uint8_t *dst, std::size_t n) override {
    if (size_ - pos_ < n) return false;
    if (n) std::memcpy(dst, data_ + pos_, n);
    pos_ += n;
    return true;
  }

 private:
  const std::uint8_t *data_;
  std::size_t size_;
  std::size_t pos_ = 0;
};

class FdSource final : public Source {
 public:
  explicit FdSource(int fd) : fd_(fd) {}
  bool read(std::uint8_t *dst, std::size_t n) override {
    while (n > 0) {
      const ::ssize_t got = ::read(fd_, dst, n);
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) return false;
      dst += got;
      n -= static_cast<std::size_t>(got);
    }
    return true;
  }

 private:
  int fd_;
};

class Fd {
 public:
  explicit Fd(int fd = -1) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd &) = delete;
  Fd &operator=(const Fd &) = delete;
  int get() const { return fd_; }
  /// Closes now and reports the result (close can be where a delayed write error surfaces).
  bool close() {
    const int fd = fd_;
    fd_ = -1;
    return fd < 0 || ::close(fd) == 0;
  }

 private:
  int fd_;
};

std::string describeConfig(double cell_size, int max_depth) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "cell_size %.17g, max_depth %d", cell_size, max_depth);
  return buf;
}

/// The settings kept normals depend on, as a map file stores them (NormalParams without threads, which changes no
/// result).
struct KeptNormalSettings {
  std::int32_t level = 0, k = 0, min_neighbors = 0, neighborhood_level_offset = 0;
  double radius = 0.0, max_growth = 0.0, line_ratio = 0.0, max_plane_rms = 0.0;
  double up[3] = {0.0, 0.0, 0.0};

  static KeptNormalSettings of(const NormalParams &p) {
    KeptNormalSettings s;
    s.level = p.level, s.k = p.k, s.min_neighbors = p.min_neighbors;
    s.neighborhood_level_offset = p.neighborhood_level_offset;
    s.radius = p.radius, s.max_growth = p.max_growth, s.line_ratio = p.line_ratio, s.max_plane_rms = p.max_plane_rms;
    for (int a = 0; a < 3; ++a) s.up[a] = p.up[a];
    return s;
  }
  // Exact: estimates from settings that differ in any bit may differ.
  bool operator==(const KeptNormalSettings &o) const {
    return level == o.level && k == o.k && min_neighbors == o.min_neighbors &&
           neighborhood_level_offset == o.neighborhood_level_offset && radius == o.radius &&
           max_growth == o.max_growth && line_ratio == o.line_ratio && max_plane_rms == o.max_plane_rms &&
           up[0] == o.up[0] && up[1] == o.up[1] && up[2] == o.up[2];
  }
  /// Each setting as "name value", in file order.
  std::vector<std::string> items() const {
    auto item = [](const char *name, double v, const char *unit = "") {
      char buf[96];
      std::snprintf(buf, sizeof buf, "%s %.9g%s", name, v, unit);
      return std::string(buf);
    };
    char up_text[128];
    std::snprintf(up_text, sizeof up_text, "up (%.9g, %.9g, %.9g)", up[0], up[1], up[2]);
    return {item("output level", level),     item("radius", radius, " m"),
            item("k", k),                     item("min_neighbors", min_neighbors),
            item("neighborhood_level_offset", neighborhood_level_offset),
            item("max_growth", max_growth),   item("line_ratio", line_ratio),
            item("max_plane_rms", max_plane_rms), up_text};
  }
  std::string describe() const {
    std::string out;
    for (const std::string &i : items()) out += (out.empty() ? "" : ", ") + i;
    return out;
  }
  /// The settings that differ from `here`'s: "map's value -> here's value", or empty.
  std::string differences(const KeptNormalSettings &here) const {
    const std::vector<std::string> a = items(), b = here.items();
    std::string out;
    for (std::size_t i = 0; i < a.size(); ++i)
      if (a[i] != b[i]) out += (out.empty() ? "" : ", ") + a[i] + " in the map, " + b[i] + " here";
    return out.empty() ? "equal to 9 digits: " + describe() : out;
  }
  void write(ByteWriter &w) const {
    w.put(level), w.put(radius), w.put(k), w.put(min_neighbors), w.put(neighborhood_level_offset);
    w.put(max_growth), w.put(line_ratio), w.put(max_plane_rms), w.put(up[0]), w.put(up[1]), w.put(up[2]);
  }
  bool read(ByteReader &r) {
    return r.get(level) && r.get(radius) && r.get(k) && r.get(min_neighbors) && r.get(neighborhood_level_offset) &&
           r.get(max_growth) && r.get(line_ratio) && r.get(max_plane_rms) && r.get(up[0]) && r.get(up[1]) &&
           r.get(up[2]);
  }
};

/// What a file says of its kept normals.
struct FileNormals {
  std::vector<std::uint8_t> bytes;  ///< MapNormals::kFileBytes per sample, in file order; empty when none
  bool has_settings = false;        ///< false: version 2, which did not record them
  KeptNormalSettings settings;
};

/// `normals`: when given, receives the entries' kept normals and their settings (bytes empty when the file holds
/// none).
LoadedHierarchy parse(Source &src, std::uint64_t total_size, const std::string &name, const HierarchyConfig *expected,
                      FileNormals *normals = nullptr) {
  if (total_size == 0) fail(name, "empty file (0 bytes), not an hpds map");
  std::array<std::uint8_t, 16> start{};
  const std::size_t got = static_cast<std::size_t>(std::min<std::uint64_t>(total_size, start.size()));
  if (!src.read(start.data(), got)) fail(name, "read failed at the start of the file");
  if (std::memcmp(start.data(), kMagic, std::min<std::size_t>(got, 8)) != 0) fail(name, "not an hpds map file (bad magic)");
  if (got < start.size())
    fail(name, "truncated: " + std::to_string(total_size) + " bytes cannot hold an hpds map header");
  std::uint32_t version = 0, header_size = 0;
  std::memcpy(&version, start.data() + 8, 4);
  std::memcpy(&header_size, start.data() + 12, 4);
  if (version < 1 || version > kHierarchyFileVersion)
    fail(name, "unsupported hpds map version " + std::to_string(version) + " (this build reads versions 1 to " +
                   std::to_string(kHierarchyFileVersion) + ")");
  if (header_size < kFixedHeaderBytes + 4 || header_size > kMaxHeaderBytes)
    fail(name, "corrupt header: header size " + std::to_string(header_size) + " is impossible");
  if (header_size + std::uint64_t(4) > total_size)
    fail(name, "truncated: the header needs " + std::to_string(header_size) + " bytes but the file holds " +
                   std::to_string(total_size));

  std::vector<std::uint8_t> header(header_size);
  std::memcpy(header.data(), start.data(), start.size());
  if (!src.read(header.data() + start.size(), header_size - start.size())) fail(name, "read failed in the header");
  std::uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, header.data() + header_size - 4, 4);
  if (crc32(header.data(), header_size - 4) != stored_crc) fail(name, "corrupt header (checksum mismatch)");

  // The checksum matched, so from here a bad value is a file written wrong, not a flipped bit.
  ByteReader r(header.data() + 16, header_size - 4 - 16);
  double cell_size = 0.0;
  std::uint32_t max_depth = 0, next_frame = 0, point_step = 0, field_count = 0;
  std::uint64_t sample_count = 0;
  r.get(cell_size);
  r.get(max_depth);
  r.get(next_frame);
  r.get(sample_count);
  r.get(point_step);
  r.get(field_count);
  if (!(cell_size > 0.0) || !std::isfinite(cell_size) || max_depth > std::uint32_t(kMaxDepthLimit))
    fail(name, "invalid hierarchy parameters (" +
                   describeConfig(cell_size, static_cast<int>(std::min<std::uint32_t>(max_depth, 1u << 30))) + ")");
  if (point_step > kMaxPointStep) fail(name, "invalid record layout: point_step " + std::to_string(point_step));
  PointLayout layout;
  layout.point_step = point_step;
  for (std::uint32_t i = 0; i < field_count; ++i) {
    std::uint32_t name_len = 0, offset = 0, count = 0;
    std::uint8_t type = 0;
    PointField f;
    if (!r.get(name_len) || name_len > kMaxFieldNameBytes || !r.getString(f.name, name_len) || !r.get(offset) ||
        !r.get(type) || !r.get(count))
      fail(name, "corrupt header: field " + std::to_string(i) + " of " + std::to_string(field_count) +
                     " runs past the header");
    if (!isValidFieldType(type))
      fail(name, "invalid record layout: field '" + f.name + "' has datatype " + std::to_string(type));
    f.offset = offset;
    f.type = static_cast<FieldType>(type);
    f.count = count;
    layout.fields.push_back(std::move(f));
  }
  std::uint32_t normal_bytes = 0;
  if (version >= 2 && !r.get(normal_bytes)) fail(name, "corrupt header: it ends before the normals' size");
  if (normal_bytes != 0 && normal_bytes != MapNormals::kFileBytes)
    fail(name, "corrupt header: kept normals of " + std::to_string(normal_bytes) + " bytes per sample (this build "
               "writes " + std::to_string(MapNormals::kFileBytes) + ")");
  KeptNormalSettings settings;
  if (version >= 3 && normal_bytes != 0) {
    if (!settings.read(r)) fail(name, "corrupt header: it ends inside the kept normals' settings");
    // Written from a validated configuration; anything else is a file written wrong.
    if (settings.level < 0 || settings.level > kMaxDepthLimit || !std::isfinite(settings.radius) ||
        !std::isfinite(settings.max_growth) || !std::isfinite(settings.line_ratio) ||
        !std::isfinite(settings.max_plane_rms))
      fail(name, "corrupt header: impossible kept normals' settings (" + settings.describe() + ")");
  }
  std::uint64_t free_count = 0;
  if (version >= 3 && !r.get(free_count)) fail(name, "corrupt header: it ends before the free slots' count");
  if (r.pos() != header_size - 4 - 16) fail(name, "corrupt header: unexpected bytes after the field list");
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(name, std::string("invalid record layout: ") + e.what());
  }

  if (expected && (expected->cell_size != cell_size || expected->max_depth != static_cast<int>(max_depth))) {
    // The configuration's cell is usually derived from output.spacing, so a map read at another spacing fails here
    // although it can be read at any spacing with its own cell given: say how, with values that round-trip.
    char keys[256];
    std::snprintf(keys, sizeof keys,
                  "to read it at another spacing, set hierarchy.cell_size: %.17g and hierarchy.max_depth: %u "
                  "(--cell-size %.17g --max-depth %u)",
                  cell_size, max_depth, cell_size, max_depth);
    fail(name, "the map was built with " + describeConfig(cell_size, static_cast<int>(max_depth)) +
                   " but the configuration has " + describeConfig(expected->cell_size, expected->max_depth) +
                   " (hierarchy.cell_size and hierarchy.max_depth must match the map's; " + keys + ")");
  }

  const std::uint64_t entry_bytes = kEntryFixedBytes + point_step + normal_bytes;
  const std::uint64_t body_bytes = total_size - header_size - 4;
  // Both counts bounded by the body before any product: no overflow, and ids stay below kNoSample.
  const bool counts_fit = free_count <= body_bytes / 4 && sample_count <= body_bytes / entry_bytes;
  if (sample_count + free_count >= kNoSample || !counts_fit ||
      free_count * 4 + sample_count * entry_bytes != body_bytes) {
    const bool fits = counts_fit && free_count * 4 <= body_bytes &&
                      sample_count <= (body_bytes - free_count * 4) / entry_bytes;
    fail(name, std::string(fits ? "unexpected trailing bytes" : "truncated") + ": the header declares " +
                   std::to_string(sample_count) + " samples of " + std::to_string(entry_bytes) + " bytes and " +
                   std::to_string(free_count) + " free slots but " + std::to_string(body_bytes) +
                   " body bytes follow it");
  }

  LoadedHierarchy out{Hierarchy(cell_size, static_cast<int>(max_depth)), next_frame};
  out.hierarchy.setRecordLayout(layout);
  if (normals) {
    *normals = FileNormals{};
    normals->has_settings = version >= 3 && normal_bytes != 0;
    normals->settings = settings;
    if (normal_bytes) normals->bytes.reserve(static_cast<std::size_t>(sample_count) * normal_bytes);
  }
  std::vector<std::uint8_t> chunk;
  std::uint32_t crc = 0;
  // A sample the hierarchy refuses is only reported once the checksum has passed: a damaged body should be called
  // damaged, not blamed on whichever sample the damage happened to hit first.
  std::string refused;
  // The free slots first: which ids the samples skip, and the order the slots are reused in. A free slot costs 4
  // bytes in the file but a record and a slot's arrays in memory. Where that would exceed 16 times the body plus
  // 64 MiB (a free slot of 16 MiB records in a small forged file; no map with records of a few dozen bytes and fewer
  // than ~50 free slots per sample), the ids are compacted instead: the same samples, continuing in another order.
  const std::uint64_t id_bound = sample_count + free_count;
  const std::uint64_t hole_budget = 16 * std::min(body_bytes, std::uint64_t(1) << 56) + (std::uint64_t(64) << 20);
  out.ids_compacted = free_count > hole_budget / (point_step + kSlotBytes);
  std::vector<SampleId> free_order;
  std::vector<std::uint8_t> is_free;
  if (free_count && !out.ids_compacted) {
    free_order.reserve(static_cast<std::size_t>(free_count));
    is_free.assign(static_cast<std::size_t>(id_bound), 0);
  }
  for (std::uint64_t done = 0; done < free_count;) {
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(kChunkBytes / 4, free_count - done));
    chunk.resize(4 * n);
    if (!src.read(chunk.data(), chunk.size())) fail(name, "read failed in the free slots (file changed while reading?)");
    crc = crc32(chunk.data(), chunk.size(), crc);
    for (std::size_t i = 0; i < n && refused.empty() && !out.ids_compacted; ++i) {
      std::uint32_t id = 0;
      std::memcpy(&id, chunk.data() + 4 * i, 4);
      if (id >= id_bound || is_free[id])
        refused = "free slot " + std::to_string(id) + (id >= id_bound ? " beyond the " + std::to_string(id_bound) + " ids" : " listed twice");
      else
        is_free[id] = 1, free_order.push_back(id);
    }
    done += n;
  }
  std::uint64_t next_id = 0;  // the id the next sample gets: the free slots before it are put back first
  auto skipFreeSlots = [&] {
    while (next_id < id_bound && !is_free.empty() && is_free[static_cast<std::size_t>(next_id)]) {
      out.hierarchy.restoreFreeSlot();
      ++next_id;
    }
  };
  for (std::uint64_t done = 0; done < sample_count;) {
    const std::size_t n =
        static_cast<std::size_t>(std::min<std::uint64_t>(entriesPerChunk(entry_bytes), sample_count - done));
    chunk.resize(n * entry_bytes);
    if (!src.read(chunk.data(), chunk.size())) fail(name, "read failed in the samples (file changed while reading?)");
    crc = crc32(chunk.data(), chunk.size(), crc);
    for (std::size_t i = 0; i < n && refused.empty(); ++i) {
      const std::uint8_t *e = chunk.data() + i * entry_bytes;
      double xyz[3];
      float to_view[3];
      std::uint32_t frame = 0;
      std::memcpy(xyz, e, 24);
      const int level = e[24];
      std::memcpy(&frame, e + 25, 4);
      std::memcpy(to_view, e + 29, 12);
      try {
        if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2]))
          throw std::invalid_argument("position is not finite");
        skipFreeSlots();
        out.hierarchy.restoreSample(xyz, level, frame, to_view, e + kEntryFixedBytes);
        ++next_id;
        if (normals && normal_bytes) {
          const std::uint8_t *kept = e + kEntryFixedBytes + point_step;
          normals->bytes.insert(normals->bytes.end(), kept, kept + normal_bytes);
        }
      } catch (const std::exception &ex) {
        refused = "sample " + std::to_string(done + i) + ": " + ex.what();
      }
    }
    done += n;
  }
  std::uint8_t tail[4];
  if (!src.read(tail, 4)) fail(name, "read failed at the body checksum");
  std::memcpy(&stored_crc, tail, 4);
  if (crc != stored_crc) fail(name, "corrupt sample data (checksum mismatch)");
  if (!refused.empty()) fail(name, "invalid map: " + refused);
  if (!out.ids_compacted) {
    try {
      skipFreeSlots();  // those after the last sample
      out.hierarchy.restoreFreeOrder(free_order);  // checked above: every free slot once
    } catch (const std::exception &ex) {  // e.g. out of memory: named like every other failure
      fail(name, std::string("cannot restore the free slots: ") + ex.what());
    }
  }
  return out;
}

}  // namespace

namespace {
/// What a map file cannot hold, refused before any file is touched.
void checkSavable(const std::string &path, const Hierarchy &hierarchy) {
  if (isOtherFormatName(path))
    fail(path, "cannot save a map under another format's extension (it could replace a point cloud, a bag or a "
               "config): name it e.g. map.hpdsmap");
  if (!hostIsLittleEndian()) fail(path, "map files are little-endian; this host is not");
  const PointLayout &layout = hierarchy.recordLayout();
  if (layout.point_step > kMaxPointStep) fail(path, "cannot save: records of more than 16 MiB");
  for (const PointField &f : layout.fields)
    if (f.name.size() > kMaxFieldNameBytes) fail(path, "cannot save: a field name longer than 4096 bytes");
}
/// saveHierarchy's bytes, with the kept normals of a map-mode pipeline, estimated with `settings`, when `normals` is
/// given.
void writeMap(AtomicFile &file, const Hierarchy &hierarchy, std::uint32_t next_frame, const MapNormals *normals,
              const KeptNormalSettings &settings = {}) {
  checkSavable(file.target(), hierarchy);
  const std::uint32_t normal_bytes = normals ? static_cast<std::uint32_t>(MapNormals::kFileBytes) : 0;
  const PointLayout &layout = hierarchy.recordLayout();

  ByteWriter h;
  h.putBytes(kMagic, sizeof kMagic);
  h.put(kHierarchyFileVersion);
  h.put(std::uint32_t(0));  // header_size, patched below
  h.put(hierarchy.cellSize());
  h.put(static_cast<std::uint32_t>(hierarchy.maxDepth()));
  h.put(next_frame);
  h.put(static_cast<std::uint64_t>(hierarchy.sampleCount()));
  h.put(layout.point_step);
  h.put(static_cast<std::uint32_t>(layout.fields.size()));
  for (const PointField &f : layout.fields) {
    h.put(static_cast<std::uint32_t>(f.name.size()));
    h.putBytes(f.name.data(), f.name.size());
    h.put(f.offset);
    h.put(static_cast<std::uint8_t>(f.type));
    h.put(f.count);
  }
  h.put(normal_bytes);
  if (normals) settings.write(h);
  const std::vector<SampleId> &free_slots = hierarchy.freeSlots();
  h.put(static_cast<std::uint64_t>(free_slots.size()));
  const auto header_size = static_cast<std::uint32_t>(h.bytes.size() + 4);
  std::memcpy(h.bytes.data() + 12, &header_size, 4);
  h.put(crc32(h.bytes.data(), h.bytes.size()));

  file.write(h.bytes.data(), h.bytes.size());
  const std::size_t step = layout.point_step;
  const std::size_t entry_bytes = kEntryFixedBytes + step + normal_bytes;
  std::vector<std::uint8_t> chunk;
  const std::size_t chunk_entries = entriesPerChunk(entry_bytes);
  chunk.reserve(chunk_entries * entry_bytes);
  std::uint32_t crc = 0;
  auto flush = [&] {
    crc = crc32(chunk.data(), chunk.size(), crc);
    file.write(chunk.data(), chunk.size());
    chunk.clear();
  };
  for (std::size_t at = 0; at < free_slots.size();) {
    const std::size_t n = std::min(kChunkBytes / 4, free_slots.size() - at);
    chunk.resize(4 * n);
    std::memcpy(chunk.data(), free_slots.data() + at, 4 * n);
    flush();
    at += n;
  }
  for (SampleId id = 0; id < hierarchy.idBound(); ++id) {
    if (!hierarchy.isLive(id)) continue;
    const std::size_t at = chunk.size();
    chunk.resize(at + entry_bytes);
    std::uint8_t *e = chunk.data() + at;
    std::memcpy(e, hierarchy.position(id), 24);
    e[24] = static_cast<std::uint8_t>(hierarchy.level(id));
    const std::uint32_t frame = hierarchy.frameIndex(id);
    std::memcpy(e + 25, &frame, 4);
    std::memcpy(e + 29, hierarchy.toViewpoint(id).data(), 12);
    if (step) std::memcpy(e + kEntryFixedBytes, hierarchy.record(id), step);
    if (normals) normals->save(id, e + kEntryFixedBytes + step);
    if (chunk.size() >= chunk_entries * entry_bytes) flush();
  }
  flush();
  std::uint8_t c[4];
  std::memcpy(c, &crc, 4);
  file.write(c, 4);
}

/// writeMap into `path` itself.
void writeMapFile(const std::string &path, const Hierarchy &hierarchy, std::uint32_t next_frame,
                  const MapNormals *normals, const KeptNormalSettings &settings = {}) {
  checkSavable(path, hierarchy);
  // Temporary file, fsync and rename (AtomicFile): a failure or a kill leaves any previous map at `path` untouched.
  AtomicFile file(path);
  writeMap(file, hierarchy, next_frame, normals, settings);
  file.commit();
}
}  // namespace

void saveHierarchy(const std::string &path, const Hierarchy &hierarchy, std::uint32_t next_frame) {
  writeMapFile(path, hierarchy, next_frame, nullptr);
}

void saveHierarchy(AtomicFile &file, const Hierarchy &hierarchy, std::uint32_t next_frame) {
  writeMap(file, hierarchy, next_frame, nullptr);
}

namespace {
/// parse() over the file at `path`; `normals` as there.
LoadedHierarchy parseFile(const std::string &path, const HierarchyConfig *expected, FileNormals *normals) {
  if (!hostIsLittleEndian()) fail(path, "map files are little-endian; this host is not");
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    if (errno == ENOENT) fail(path, "file not found");
    fail(path, std::string("cannot open: ") + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) fail(path, std::string("cannot stat: ") + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) fail(path, "not a regular file");
  FdSource src(fd.get());
  return parse(src, static_cast<std::uint64_t>(st.st_size), path, expected, normals);
}
}  // namespace

LoadedHierarchy loadHierarchy(const std::string &path, const HierarchyConfig *expected) {
  return parseFile(path, expected, nullptr);
}

LoadedHierarchy loadHierarchyBytes(const std::uint8_t *data, std::size_t size, const std::string &name,
                                   const HierarchyConfig *expected) {
  if (!hostIsLittleEndian()) fail(name, "map files are little-endian; this host is not");
  MemorySource src(data, size);
  return parse(src, size, name, expected);
}

bool isOtherFormatName(const std::string &path) {
  const std::size_t dot = path.rfind('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) return false;
  std::string ext = path.substr(dot);
  for (char &c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const char *other : {".pcd", ".ply", ".bin", ".bag", ".json", ".yaml", ".yml", ".png", ".csv", ".txt"})
    if (ext == other) return true;
  return false;
}

namespace {
/// The settings the pipeline's kept normals are estimated with (Pipeline::updateMapNormals).
KeptNormalSettings keptSettingsOf(const Pipeline &pipeline) {
  return KeptNormalSettings::of(normalParamsFor(pipeline.config(), pipeline.outputLevel()));
}
}  // namespace

namespace {
// A scan-mode pipeline holds only its last frame's samples: saved, they read as a map that loadMap then refuses.
void requireMapMode(const Pipeline &pipeline) {
  if (pipeline.config().mode != Mode::Map)
    throw std::invalid_argument("saving a map needs mode: map (scan mode keeps no map: its hierarchy holds only the "
                                "last frame's samples)");
}
}  // namespace

void saveMap(const std::string &path, const Pipeline &pipeline) {
  requireMapMode(pipeline);
  writeMapFile(path, pipeline.hierarchy(), pipeline.framesProcessed(), pipeline.map_normals_.get(),
               keptSettingsOf(pipeline));
}

void saveMap(AtomicFile &file, const Pipeline &pipeline) {
  requireMapMode(pipeline);
  writeMap(file, pipeline.hierarchy(), pipeline.framesProcessed(), pipeline.map_normals_.get(),
           keptSettingsOf(pipeline));
}

int deepestPopulatedLevel(const Hierarchy &hierarchy) {
  int deepest = -1;
  for (int l = 0; l <= hierarchy.maxDepth(); ++l)
    if (hierarchy.countAtLevel(l) > 0) deepest = l;
  return deepest;
}

std::string shallowMapWarning(const Pipeline &pipeline) {
  const int deepest = deepestPopulatedLevel(pipeline.hierarchy());
  if (deepest < 0 || deepest >= pipeline.buildDepth()) return {};
  return "the loaded map holds levels 0.." + std::to_string(deepest) + " only, and this run builds down to level " +
         std::to_string(pipeline.buildDepth()) + ": levels " + std::to_string(deepest + 1) + ".." +
         std::to_string(pipeline.buildDepth()) +
         " will hold only the new frames' samples, so their coverage does not reach the earlier frames' points; build "
         "the map with map.keep_depth " + std::to_string(pipeline.buildDepth()) +
         " to continue it at this spacing, or continue at its own";
}

std::string shallowSaveWarning(const Pipeline &pipeline, int loaded_deepest, std::uint32_t loaded_frames) {
  const int built = pipeline.buildDepth();
  // A map saved as it was loaded lost nothing, whatever this run would build.
  if (loaded_deepest <= built || pipeline.framesProcessed() <= loaded_frames) return {};
  const std::string deeper = built + 1 == loaded_deepest
                                 ? "level " + std::to_string(loaded_deepest)
                                 : "levels " + std::to_string(built + 1) + ".." + std::to_string(loaded_deepest);
  return "the loaded map holds levels down to " + std::to_string(loaded_deepest) + ", but this run built levels 0.." +
         std::to_string(built) + " only: in the saved map, " + deeper +
         " will not cover this run's frames, and a later run that reads " +
         (built + 1 == loaded_deepest ? "it" : "them") +
         " (a finer spacing, normals) gets holes there without a warning; set map.keep_depth " +
         std::to_string(loaded_deepest) + " to continue the map at its full depth";
}

std::string loadMap(const std::string &path, Pipeline &pipeline) {
  if (pipeline.config().mode != Mode::Map)
    throw std::invalid_argument("loading a map needs mode: map (scan mode starts every frame on an empty hierarchy)");
  FileNormals normals;
  LoadedHierarchy loaded = parseFile(path, &pipeline.config().hierarchy, &normals);
  // Checked before the map is replaced, so that a refused file changes nothing.
  MapNormals kept;
  const std::size_t count = loaded.hierarchy.sampleCount();
  if (!normals.bytes.empty()) {
    std::size_t i = 0;  // the file's i-th sample is the i-th live id
    for (SampleId id = 0; id < loaded.hierarchy.idBound(); ++id) {
      if (!loaded.hierarchy.isLive(id)) continue;
      if (!kept.restore(id, normals.bytes.data() + i * MapNormals::kFileBytes))
        fail(path, "invalid map: sample " + std::to_string(i) + " has an impossible kept normal");
      ++i;
    }
  }
  const bool compacted = loaded.ids_compacted;
  pipeline.replaceMap(std::move(loaded.hierarchy), loaded.next_frame);
  // A file without them (version 1, saved with normals off) leaves the samples to the map's own estimate until a
  // frame hits them; a pipeline without normals has no use for them.
  std::string warning;
  if (compacted)
    warning = "the map's free slots (ids of evicted samples) would take far more memory than the file holds (large "
              "records): its ids were compacted, so it continues with the same samples in another order than the run "
              "that saved it";
  auto joined = [&warning](const std::string &more) { return warning.empty() ? more : warning + "; " + more; };
  if (!pipeline.map_normals_ || normals.bytes.empty()) return warning;
  // Normals estimated with other settings (another output level, radius, growth...) would stay in the output next to
  // this run's until a closer frame replaced each: they are dropped, and the samples get this run's estimate (from
  // the map until a frame hits them). Version 2 files did not record their settings: taken as they are.
  const KeptNormalSettings ours = keptSettingsOf(pipeline);
  if (normals.has_settings && !(normals.settings == ours))
    return joined("the map's kept normals were estimated with other settings than this run's (" +
                  normals.settings.differences(ours) + "): they are dropped, and its " + std::to_string(count) +
                  " samples get normals estimated with this run's settings");
  *pipeline.map_normals_ = std::move(kept);
  return warning;
}

}  // namespace hpds
