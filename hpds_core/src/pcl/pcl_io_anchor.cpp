// Keeps hpds_io_pcl a valid library while it has no PCL sources of its own (CMake refuses empty libraries).
namespace hpds {
int pclIoAnchor() { return 0; }
}  // namespace hpds
