// Folders given as inputs (`hpds sample DIR`, `hpds verify --input DIR`): the point-cloud files they hold.
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

namespace hpds::cli {

/// `given` with every folder replaced by its .pcd/.ply/.bin files (any case; not its subfolders) in natural name
/// order (digit runs compared as numbers: frame_2 before frame_10), so that unpadded frame numbers meet their pose
/// lines. Left out, each said on `notes`: hidden files (a leading '.') and PLY files written by hpds (an earlier
/// run's output saved beside the frames, which would come back as a frame). Files named one by one are kept as
/// given. std::invalid_argument for a folder that cannot be read or holds no such file.
[[nodiscard]] std::vector<std::string> expandInputFolders(const std::vector<std::string> &given, std::ostream &notes);

/// Whether a < b in natural name order (see expandInputFolders).
[[nodiscard]] bool naturalLess(const std::string &a, const std::string &b);

}  // namespace hpds::cli
