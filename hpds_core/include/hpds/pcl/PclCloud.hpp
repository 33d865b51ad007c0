// PointBuffer -> pcl::PCLPointCloud2, the form pcl_conversions and PCL's writers take (implemented in hpds_io_pcl).
//
// Contract
// - Fields are listed in offset order (PCL's PCD header writer derives its "_" padding from the gaps); names,
//   datatypes and counts are kept, the records' bytes are copied as they are. Fields that overlap in the record
//   (allowed in a PointBuffer, not expressible in PCL) are repacked each into its own bytes, in layout order.
// - width x height is kept when it matches the point count, else the cloud is one row. Little-endian, not dense.
// - PCL types appear here only: include this header from PCL-side code (the adapter, benchmarks), never from the
//   core's headers.
#pragma once

#include <pcl/PCLPointCloud2.h>

#include "hpds/points/PointBuffer.hpp"

namespace hpds {

[[nodiscard]] pcl::PCLPointCloud2 toPclCloud2(const PointBuffer &cloud);

}  // namespace hpds
