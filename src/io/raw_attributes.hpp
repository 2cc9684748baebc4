#pragma once
// Internal to src/io: the root group's attributes, decoded by our own bounds-checked reads of the
// file instead of libhdf5.
//
// Why: libhdf5 1.10.8 (Debian 12) trusts what it reads. On damaged files, listing attributes
// (H5Aiterate2: a failed decode, then H5A__attr_release_table → H5A__close on a half-built attribute)
// and reading variable-length strings (H5Aread → H5T__conv_vlen → H5HG_read: a heap index past the
// collection's objects, an object longer than the string's stored length, a free-space object of
// size 0 on which H5HG__cache_heap_deserialize never advances) segfault or loop. Newer releases
// check some of this; this one does not. The attributes other than radius_low/radius_high mean
// nothing to the readers (docs/FORMAT.md §1), so HDF5 is never asked for them.
//
// What is decoded (HDF5 File Format Specification 3.0, IV.A object headers v1/v2 with continuation
// chunks, IV.A.2.d datatype, IV.A.2.m attribute, III.E global heap): one-element attributes of
// integers (1, 2, 4, 8 bytes, either byte order), IEEE float32/float64, fixed-length strings and
// variable-length strings whose global heap object lies inside its collection with exactly the
// stored length (≤ 1 MiB; the collection walked as HDF5 walks it). Other attributes are only named.
#include <hdf5.h>

#include <set>
#include <string>

#include "scene/scene.hpp"

namespace cg::h5 {

struct RawAttributes {
  // ok: every attribute message was decoded (values holds those of a kind we read); unsupported: the
  // header uses what we do not follow (dense storage, shared messages, offsets other than 8 bytes);
  // damaged: the header or an attribute message overruns itself or the file.
  enum class Status { ok, unsupported, damaged };
  Status status = Status::ok;
  std::set<std::string> names;  // every attribute (ok only)
  Attributes values;            // one-element attributes of a kind we read (ok only)
};

// The attributes of `object` (an open group or dataset of `file`, whose path is `path`).
RawAttributes raw_attributes(const std::string& path, hid_t file, hid_t object);

// Checks the parts of a group's object header that libhdf5 1.10.8 follows without checking before a
// link lookup in it (H5Lexists → H5G__stab_lookup → H5HL_protect segfaults on an undefined or
// out-of-file local heap address; H5HL__fl_deserialize grows memory without end on a looping free
// list): the symbol table message's B-tree and local heap must carry their signatures, the heap's
// data must lie inside the file and its free list must end. "" when sound (or not a symbol-table
// group), else what is wrong.
std::string damaged_group(const std::string& path, hid_t file, hid_t group);

// Checks the object header of `name` (a hard link of `file`, read before HDF5 opens the object):
// the header's chunks inside the file, and every message flagged "shared" decodable and resolvable
// (libhdf5 1.10.8's H5O_shared_decode → H5SM_get_fheap_addr reads through an undefined table
// address, a segfault, when the file has no shared-message table; a committed message must point to
// another sound header). "" when sound (or not followed: a soft or external link, offsets other than
// 8 bytes), else what is wrong.
std::string damaged_object(const std::string& path, hid_t file, const std::string& name);

}  // namespace cg::h5
