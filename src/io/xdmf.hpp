#pragma once
// ParaView's view of a scene and its contacts (`generate --xdmf`, `detect --xdmf`): XDMF 3 files beside
// the HDF5 files that point into their datasets, one grid per file (meshio reads one grid per file;
// ParaView opens several at once):
//   <base>.spheres.xmf     spheres as points: radius (Glyph, Sphere, scale by radius, factor 2)
//   <base>.ellipsoids.xmf  ellipsoids as points: semi_axes, orientation (w, x, y, z), bounding radius and
//                          shape, the symmetric tensor R·diag(a, b, c)·Rᵀ whose eigenvalues are the
//                          semi-axes and eigenvectors the body's axes (Tensor Glyph, Sphere, factor 2)
//   <base>.xmf             contacts (detect): points at position_on_b with normal_on_b, distance,
//                          position_on_a, id_a, id_b and the optional fields present
// A grid file exists only for bodies or contacts the files hold. What the XDMF cannot point to in our
// files — the points' indices (the Polyvertex topology) and the ellipsoids' shape tensors — lies in
// <base>.xdmf.h5 beside them. Paths inside the XMF files are relative to their folder. Every file is
// written to a temporary name and renamed when complete.
#include <string>

namespace cg {

// "<dir>/name" of "<dir>/name.h5" (or .hdf5; other names are kept whole).
std::string xdmf_base(const std::string& h5_path);

// The XDMF files of the bodies of `scene` and (unless empty) of the contacts of `contacts`, as
// <base>.*.xmf + <base>.xdmf.h5. InputError when the files cannot be read, IoError when the outputs
// cannot be written.
void write_xdmf(const std::string& scene, const std::string& contacts, const std::string& base);

}  // namespace cg
