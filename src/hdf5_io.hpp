#pragma once
// Umbrella header, kept so that `#include "hdf5_io.hpp"` elsewhere still compiles: the HDF5 I/O of
// CONTRACT §1 and §2 lives in src/io/ (scene_file, contact_file, inspect; hdf5_handle is the RAII layer).
#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
