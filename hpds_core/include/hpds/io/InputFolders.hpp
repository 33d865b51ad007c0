// Input lists as the command-line tool and the tiled map build take them: folders of frames and the order of
// frames that poses are matched to.
//
// Contract
// - Paths are used as given (relative to the working directory); nothing is read but folder listings and the
//   first 256 bytes of each PLY file in a folder.
// - Errors: std::invalid_argument naming the folder.
// - Thread-safety: reentrant.
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

namespace hpds {

/// `given` with every folder replaced by its .pcd/.ply/.bin files (any case; not its subfolders) in natural name
/// order (digit runs compared as numbers: frame_2 before frame_10), so that unpadded frame numbers meet their pose
/// lines. Left out, each said on `notes`: hidden files (a leading '.') and PLY files hpds wrote as a sampling's
/// output (kPlySamplesComment: an earlier run's output saved beside the frames, which would come back as a frame).
/// Files named one by one are kept as given. std::invalid_argument for a folder that cannot be read or holds no
/// such file.
[[nodiscard]] std::vector<std::string> expandInputFolders(const std::vector<std::string> &given, std::ostream &notes);

/// Whether a < b in natural name order (see expandInputFolders).
[[nodiscard]] bool naturalLess(const std::string &a, const std::string &b);

/// "" when the files of `inputs` that share a folder come in natural name order; otherwise a warning naming the
/// first pair that does not (a shell glob such as frames/*.pcd sorts names as text: f_10 before f_2), for callers
/// that match frames to pose lines by order.
[[nodiscard]] std::string inputOrderWarning(const std::vector<std::string> &inputs);

/// The check of every caller that matches the `poses` poses of the file `poses_path` to `inputs` by order (the CLI's
/// --poses, the tiled map build): std::invalid_argument (poseCountMismatch) when the counts differ; else "" or the
/// warning of inputOrderWarning, prefixed "--poses: ".
[[nodiscard]] std::string checkPosesMatchInputs(const std::string &poses_path, std::size_t poses,
                                                const std::vector<std::string> &inputs);

/// Whether the PLY file at `path` carries kPlySamplesComment in its first 256 bytes: a sampling's output, which
/// expandInputFolders leaves out of a folder.
[[nodiscard]] bool plyMarkedAsSamples(const std::string &path);

}  // namespace hpds
