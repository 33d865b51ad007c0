#include "hpds/tiling/TileBucket.hpp"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>

#include "hpds/pipeline/FramePoints.hpp"
#include "hpds/util/Crc32.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "io/FileAccess.hpp"

namespace hpds {

namespace {

constexpr char kMagic[8] = {'H', 'P', 'D', 'S', 'B', 'K', 'T', '\0'};
constexpr std::uint32_t kVersion = 2;  // 2: a viewpoint per frame
// Far above any real layout; they keep the sizes computed while reading from overflowing.
constexpr std::uint32_t kMaxPointStep = 1u << 24;
constexpr std::uint32_t kMaxFields = 1u << 16;
constexpr std::uint32_t kMaxNameBytes = 1u << 12;

[[noreturn]] void fail(const std::string &path, const std::string &what) { throw std::runtime_error(path + ": " + what); }

template <typename T>
void put(std::vector<std::uint8_t> &out, const T &v) {
  const auto *p = reinterpret_cast<const std::uint8_t *>(&v);
  out.insert(out.end(), p, p + sizeof v);
}

// Reads fixed-size values; running past the end is reported as a truncated file.
class Reader {
 public:
  Reader(const std::vector<std::uint8_t> &bytes, std::size_t end, const std::string &path)
      : data_(bytes.data()), end_(end), path_(path) {}
  template <typename T>
  T get() {
    T v;
    std::memcpy(&v, take(sizeof v), sizeof v);
    return v;
  }
  const std::uint8_t *take(std::size_t n) {
    if (end_ - pos_ < n) fail(path_, "truncated or corrupt bucket file");
    const std::uint8_t *p = data_ + pos_;
    pos_ += n;
    return p;
  }
  [[nodiscard]] std::size_t left() const { return end_ - pos_; }

 private:
  const std::uint8_t *data_;
  std::size_t end_;
  std::size_t pos_ = 0;
  const std::string &path_;
};

}  // namespace

TileBucketer::TileBucketer(const HpdsConfig &config, const TileGrid &grid) : config_(config), grid_(grid) {}

FrameCounters TileBucketer::addFrame(const Frame &frame, std::uint32_t frame_index) {
  const PointLayout &layout = frame.points.layout();
  if (have_frame_ && frame_index <= last_frame_)
    throw std::invalid_argument("frame " + std::to_string(frame_index) + " added after frame " +
                                std::to_string(last_frame_) + ": frames go in increasing index order");
  // A frame without points files no record: it neither fixes the layout nor has to match it (map mode's rule;
  // drivers publish empty clouds of other fields, e.g. before the first scan).
  const bool files_records = !frame.points.empty();
  if (files_records && have_layout_ && layout != layout_)
    throw std::invalid_argument("frame " + std::to_string(frame_index) + "'s point fields or their layout differ from "
                                "those of the first frame with points (a tiled build needs one layout, byte for byte)");
  const PointField *fx = layout.find("x"), *fy = layout.find("y"), *fz = layout.find("z");
  if (!fx || !fy || !fz) throw std::invalid_argument("frame has no x/y/z fields");
  if (fx->count != 1 || fy->count != 1 || fz->count != 1) throw std::invalid_argument("x/y/z fields must have count 1");
  layout.validate();
  if (!frame.sensor_to_fixed.matrix().allFinite()) throw std::invalid_argument("frame pose is not finite");
  if (!frame.viewpoint.allFinite()) throw std::invalid_argument("frame viewpoint is not finite");

  FrameCounters c;
  c.input = frame.points.size();
  SkippedPoints skipped;
  poseFramePoints(frame, config_.input, xyz_, candidates_, skipped);
  c.skipped_invalid = skipped.invalid;
  c.skipped_zero = skipped.zero;
  c.skipped_range = skipped.range;

  // Tile of every kept point; consecutive points mostly share one, so the last lookup is kept.
  std::map<TileKey, std::vector<std::uint32_t>> members;
  std::vector<std::uint32_t> *last = nullptr;
  TileKey last_key{};
  for (std::uint32_t i : candidates_) {
    TileKey key;
    if (!grid_.tileOf(&xyz_[3 * std::size_t(i)], key)) {
      ++c.out_of_range;
      continue;
    }
    if (!last || key != last_key) {
      last = &members[key];
      last_key = key;
    }
    last->push_back(i);
  }
  const std::uint32_t step = layout.point_step;
  for (const auto &[key, idx] : members) {
    BucketFrame f;
    f.frame_index = frame_index;
    f.sensor_to_fixed = frame.sensor_to_fixed;
    f.viewpoint = frame.viewpoint;
    f.points = PointBuffer(layout, idx.size());
    for (std::size_t t = 0; t < idx.size(); ++t) std::memcpy(f.points.record(t), frame.points.record(idx[t]), step);
    bytes_ += f.points.bytes().size();
    buckets_[key].push_back(std::move(f));
  }
  if (files_records && !have_layout_) {
    layout_ = layout;
    have_layout_ = true;
  }
  have_frame_ = true;
  last_frame_ = frame_index;
  return c;
}

std::vector<std::pair<TileKey, std::uint64_t>> TileBucketer::tiles() const {
  std::vector<std::pair<TileKey, std::uint64_t>> out;
  for (const auto &[key, frames] : buckets_) {
    std::uint64_t n = 0;
    for (const BucketFrame &f : frames) n += f.points.size();
    out.emplace_back(key, n);
  }
  return out;
}

const std::vector<BucketFrame> &TileBucketer::framesOf(const TileKey &key) const {
  static const std::vector<BucketFrame> kNone;
  const auto it = buckets_.find(key);
  return it == buckets_.end() ? kNone : it->second;
}

void writeTileBucket(const std::string &path, const PointLayout &layout, const std::vector<BucketFrame> &frames) {
  layout.validate();
  std::vector<std::uint8_t> head;
  head.insert(head.end(), kMagic, kMagic + sizeof kMagic);
  put(head, kVersion);
  put(head, layout.point_step);
  put(head, static_cast<std::uint32_t>(layout.fields.size()));
  for (const PointField &f : layout.fields) {
    put(head, static_cast<std::uint32_t>(f.name.size()));
    head.insert(head.end(), f.name.begin(), f.name.end());
    put(head, f.offset);
    put(head, static_cast<std::uint8_t>(f.type));
    put(head, f.count);
  }
  put(head, static_cast<std::uint32_t>(frames.size()));

  {
    AtomicFile out(path);
    std::uint32_t crc = crc32(head.data(), head.size());
    out.write(head.data(), head.size());
    for (const BucketFrame &f : frames) {
      if (f.points.layout() != layout) fail(path, "a frame's point fields differ from the bucket's");
      std::vector<std::uint8_t> fh;
      put(fh, f.frame_index);
      for (int r = 0; r < 3; ++r)
        for (int col = 0; col < 4; ++col) put(fh, f.sensor_to_fixed.matrix()(r, col));
      for (int a = 0; a < 3; ++a) put(fh, f.viewpoint[a]);
      put(fh, static_cast<std::uint64_t>(f.points.size()));
      crc = crc32(fh.data(), fh.size(), crc);
      out.write(fh.data(), fh.size());
      const std::vector<std::uint8_t> &bytes = f.points.bytes();
      crc = crc32(bytes.data(), bytes.size(), crc);
      out.write(bytes.data(), bytes.size());
    }
    out.write(&crc, sizeof crc);
    out.commit();
  }
}

std::vector<BucketFrame> readTileBucket(const std::string &path) {
  io_detail::requireRegularFile(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open for reading");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) fail(path, "read failed");
  if (bytes.size() < sizeof kMagic + 4 || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    fail(path, "not a tile bucket file");
  std::uint32_t stored_crc;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  if (crc32(bytes.data(), bytes.size() - 4) != stored_crc) fail(path, "corrupt bucket file (checksum mismatch)");

  Reader r(bytes, bytes.size() - 4, path);
  r.take(sizeof kMagic);
  const auto version = r.get<std::uint32_t>();
  if (version != kVersion && version != 1) fail(path, "unsupported bucket file version " + std::to_string(version));
  PointLayout layout;
  layout.point_step = r.get<std::uint32_t>();
  const auto fields = r.get<std::uint32_t>();
  if (layout.point_step == 0 || layout.point_step > kMaxPointStep || fields > kMaxFields)
    fail(path, "corrupt bucket file (layout)");
  for (std::uint32_t k = 0; k < fields; ++k) {
    PointField f;
    const auto len = r.get<std::uint32_t>();
    if (len > kMaxNameBytes) fail(path, "corrupt bucket file (field name)");
    const std::uint8_t *name = r.take(len);
    f.name.assign(reinterpret_cast<const char *>(name), len);
    f.offset = r.get<std::uint32_t>();
    const auto type = r.get<std::uint8_t>();
    if (!isValidFieldType(type)) fail(path, "corrupt bucket file (field type)");
    f.type = static_cast<FieldType>(type);
    f.count = r.get<std::uint32_t>();
    layout.fields.push_back(std::move(f));
  }
  try {
    layout.validate();
  } catch (const std::invalid_argument &e) {
    fail(path, std::string("corrupt bucket file (layout: ") + e.what() + ")");
  }
  const auto count = r.get<std::uint32_t>();
  std::vector<BucketFrame> frames;
  for (std::uint32_t k = 0; k < count; ++k) {
    BucketFrame f;
    f.frame_index = r.get<std::uint32_t>();
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 4; ++col) m(row, col) = r.get<double>();
    f.sensor_to_fixed.matrix() = m;
    if (version >= 2)
      for (int a = 0; a < 3; ++a) f.viewpoint[a] = r.get<double>();
    const auto n = r.get<std::uint64_t>();
    if (n > r.left() / layout.point_step) fail(path, "truncated or corrupt bucket file");
    f.points = PointBuffer(layout, static_cast<std::size_t>(n));
    if (n) std::memcpy(f.points.bytes().data(), r.take(n * layout.point_step), n * layout.point_step);
    frames.push_back(std::move(f));
  }
  if (r.left() != 0) fail(path, "corrupt bucket file (trailing bytes)");
  return frames;
}

}  // namespace hpds
