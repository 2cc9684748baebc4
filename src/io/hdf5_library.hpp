#pragma once
// The HDF5 library's process-wide settings the command line makes once, before any HDF5 call (no HDF5
// header here: main.cpp does not see HDF5).

namespace cg {

// HDF5 closes, at exit, every file still open, flushing it. A file whose write failed on a full disk
// stays open in HDF5 1.10.8 after its close failed, and that flush at exit crashes it (H5F__close_cb).
// Every output is closed before it is renamed into place and a failed one is removed, so nothing needs
// the library's cleanup at exit: the command line turns it off, first thing in main.
void skip_hdf5_cleanup_at_exit();

}  // namespace cg
