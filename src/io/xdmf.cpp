// XDMF 3 beside the HDF5 files (xdmf.hpp): grids that point into the scene's and the contact file's
// datasets, and the sidecar <base>.xdmf.h5 with the points' indices and the ellipsoids' shape tensors.
#include "io/xdmf.hpp"

#include <filesystem>
#include <optional>
#include <vector>

#include "core/quat.hpp"
#include "io/hdf5_handle.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "io/text_file.hpp"

namespace cg {

namespace fs = std::filesystem;
using namespace h5;

std::string xdmf_base(const std::string& h5_path) {
  const fs::path p(h5_path);
  if (p.extension() == ".h5" || p.extension() == ".hdf5") return (p.parent_path() / p.stem()).string();
  return h5_path;
}

namespace {

constexpr std::size_t kBlockRows = std::size_t(1) << 20;  // ellipsoids per read of the shape tensors

// One dataset an XDMF DataItem points to: "<file relative to the XMF's folder>:<dataset>".
struct Item {
  std::string file, dataset;
  std::vector<std::uint64_t> dims;
  std::string number_type = "Float";  // Float | Int
  int precision = 8;                  // bytes
};

std::string dims_text(const std::vector<std::uint64_t>& dims) {
  std::string s;
  for (std::uint64_t d : dims) {
    if (!s.empty()) s += ' ';
    s += std::to_string(d);
  }
  return s;
}

std::string data_item(const Item& item, const char* indent) {
  return fmt::format(
      "{}<DataItem Dimensions=\"{}\" NumberType=\"{}\" Precision=\"{}\" Format=\"HDF\">{}:{}</DataItem>\n",
      indent, dims_text(item.dims), item.number_type, item.precision, item.file, item.dataset);
}

// An Item for `dataset` of `file` as stored (its element type decides NumberType and Precision).
Item stored(const std::string& file, const std::string& relative, const std::string& dataset) {
  const std::optional<DatasetInfo> info = inspect_dataset(file, dataset);
  if (!info) throw InputError(file + ": " + dataset + " is missing");
  Item item{relative, dataset, info->dims};
  if (info->type.rfind("float", 0) != 0) item.number_type = "Int";
  item.precision = info->type.ends_with("32") ? 4 : 8;
  return item;
}

struct Attribute {
  std::string name, type;  // type: Scalar | Vector | Tensor | Matrix
  Item item;
};

// One Polyvertex grid: `points` rows of xyz, vertex indices 0 … n-1, the attributes on its points.
std::string grid_file(const std::string& name, const Item& points, const Item& vertex,
                      const std::vector<Attribute>& attributes) {
  std::string s = "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n  <Domain>\n";
  s += fmt::format("    <Grid Name=\"{}\" GridType=\"Uniform\">\n", name);
  s += fmt::format(
      "      <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{}\" NodesPerElement=\"1\">\n",
      vertex.dims.at(0));
  s += data_item(vertex, "        ");
  s += "      </Topology>\n      <Geometry GeometryType=\"XYZ\">\n";
  s += data_item(points, "        ");
  s += "      </Geometry>\n";
  for (const Attribute& a : attributes) {
    s += fmt::format("      <Attribute Name=\"{}\" AttributeType=\"{}\" Center=\"Node\">\n", a.name, a.type);
    s += data_item(a.item, "        ");
    s += "      </Attribute>\n";
  }
  return s + "    </Grid>\n  </Domain>\n</Xdmf>\n";
}

// The sidecar <base>.xdmf.h5, written as the grids are planned and committed at the end.
class Sidecar {
 public:
  explicit Sidecar(const std::string& path) : m_where(path, true), m_temp(path) {
    LibraryLock lock;
    m_file = create_file(m_where, m_temp.temp());
  }
  // /<group>/vertex: 0 … n-1 (int32 below 2^31 points, else int64).
  Item vertex(const std::string& group, const std::string& relative, std::uint64_t n) {
    const bool wide = n >= (std::uint64_t(1) << 31);
    const std::string name = "/" + group + "/vertex";
    LibraryLock lock;
    create_group(m_where, m_file, "/" + group);
    Handle d = create_dataset(m_where, m_file, name, wide ? H5T_STD_I64LE : H5T_STD_I32LE, {hsize_t(n)});
    std::vector<std::int64_t> block;
    for (std::uint64_t first = 0; first < n; first += kBlockRows) {
      const std::uint64_t count = std::min<std::uint64_t>(kBlockRows, n - first);
      block.resize(count);
      for (std::uint64_t i = 0; i < count; ++i) block[i] = std::int64_t(first + i);
      write_rows(m_where, d, name, first, count, 0, H5T_NATIVE_INT64, block.data());
    }
    d.close(m_where, name);
    return Item{relative, name, {n, 1}, "Int", wide ? 8 : 4};
  }
  // /ellipsoids/shape (M, 9): R·diag(a, b, c)·Rᵀ per ellipsoid, row-major, from the scene's rows read in
  // blocks (validated by the scene reader).
  Item shapes(const std::string& scene, std::uint64_t first_id, std::uint64_t m,
              const std::string& relative) {
    const std::string name = "/ellipsoids/shape";
    Handle d;
    {
      LibraryLock lock;
      d = create_dataset(m_where, m_file, name, H5T_IEEE_F64LE, {hsize_t(m), 9});
    }
    std::vector<double> tensor;
    for (std::uint64_t first = 0; first < m; first += kBlockRows) {
      const std::uint64_t count = std::min<std::uint64_t>(kBlockRows, m - first);
      const Scene block = read_scene_rows(scene, first_id + first, count);
      tensor.resize(9 * count);
      for (std::uint64_t i = 0; i < count; ++i) {
        const auto& q = block.ellipsoid_orientation[i];
        const Mat3<double> r = rotation_matrix(Quat<double>{q[0], q[1], q[2], q[3]});
        const Vec3<double> s = block.ellipsoid_semi_axes[i];
        const double row[3][3] = {
            {r.r0.x, r.r0.y, r.r0.z}, {r.r1.x, r.r1.y, r.r1.z}, {r.r2.x, r.r2.y, r.r2.z}};
        const double axis[3] = {s.x, s.y, s.z};
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) {
            double t = 0;
            for (int k = 0; k < 3; ++k) t += row[a][k] * axis[k] * row[b][k];
            tensor[9 * i + 3 * a + b] = t;
          }
      }
      LibraryLock lock;
      write_rows(m_where, d, name, first, count, 9, H5T_NATIVE_DOUBLE, tensor.data());
    }
    LibraryLock lock;
    d.close(m_where, name);
    return Item{relative, name, {m, 9}};
  }
  void commit() {
    {
      LibraryLock lock;
      m_file.close(m_where, "cannot close the file");
    }
    m_temp.commit();
  }

 private:
  Where m_where;
  TempOutput m_temp;
  Handle m_file;
};

// `target` relative to the folder of `from` (a file path), for the references inside XMF files.
std::string relative_to(const std::string& target, const std::string& from) {
  const fs::path folder = fs::absolute(fs::path(from)).parent_path();
  return fs::absolute(fs::path(target))
      .lexically_normal()
      .lexically_relative(folder.lexically_normal())
      .string();
}

}  // namespace

void write_xdmf(const std::string& scene, const std::string& contacts, const std::string& base) {
  const std::string sidecar_path = base + ".xdmf.h5";
  const std::string sidecar = relative_to(sidecar_path, base);
  const std::string scene_ref = relative_to(scene, base);
  const SceneShape shape = read_scene_shape(scene);
  Sidecar side(sidecar_path);
  std::vector<std::pair<std::string, std::string>> files;  // (path, text)

  if (shape.spheres > 0) {
    const Item vertex = side.vertex("spheres", sidecar, shape.spheres);
    files.emplace_back(base + ".spheres.xmf",
                       grid_file("spheres", stored(scene, scene_ref, "/spheres/position"), vertex,
                                 {{"radius", "Scalar", stored(scene, scene_ref, "/spheres/radius")}}));
  }
  if (shape.ellipsoids > 0) {
    const Item vertex = side.vertex("ellipsoids", sidecar, shape.ellipsoids);
    const Item tensor = side.shapes(scene, shape.spheres, shape.ellipsoids, sidecar);
    files.emplace_back(
        base + ".ellipsoids.xmf",
        grid_file("ellipsoids", stored(scene, scene_ref, "/ellipsoids/position"), vertex,
                  {{"semi_axes", "Vector", stored(scene, scene_ref, "/ellipsoids/semi_axes")},
                   {"orientation", "Matrix", stored(scene, scene_ref, "/ellipsoids/orientation")},
                   {"shape", "Tensor", tensor}}));
  }
  if (!contacts.empty()) {
    const std::string ref = relative_to(contacts, base);
    const Item points = stored(contacts, ref, "/contacts/position_on_b");
    const Item vertex = side.vertex("contacts", sidecar, points.dims.at(0));
    std::vector<Attribute> attributes;
    for (const ContactField& f : kContactFields) {
      if (std::string(f.name()) == "position_on_b" || !inspect_dataset(contacts, f.path)) continue;
      attributes.push_back(
          {f.name(), f.kind == FieldKind::vector ? "Vector" : "Scalar", stored(contacts, ref, f.path)});
    }
    files.emplace_back(base + ".xmf", grid_file("contacts", points, vertex, attributes));
  }
  side.commit();
  for (const auto& [path, text] : files) write_text_file(path, text);
}

}  // namespace cg
