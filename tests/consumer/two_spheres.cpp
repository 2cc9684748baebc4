// A caller outside the project, built against the installed package (tests/consumer/CMakeLists.txt):
// two spheres of radius 1 whose centres are 1.5 apart overlap by 0.5. The region between the markers
// is the README's C++ example (tests/python/test_readme.py checks that it appears there verbatim).
#include <cmath>
#include <cstdio>

// EXAMPLE-BEGIN
#include <contactgrid/engine.hpp>  // find_package(contactgrid) + contactgrid::contactgrid

// Two spheres of radius 1 whose centres are 1.5 apart: one contact, overlap 0.5.
cg::Contacts<double> two_spheres() {
  std::vector<cg::Vec3<double>> centre{{0, 0, 0}, {1.5, 0, 0}};
  std::vector<double> radius{1, 1};
  cg::Engine<double> engine({.backend = cg::Backend::cpu});      // keep it: buffers are reused
  return engine.detect(cg::BodiesView{centre, radius, {}, {}});  // ids 0, 1; all pairs
  // id_a[0] == 0, id_b[0] == 1, distance[0] == -0.5, normal_on_b[0] == (-1, 0, 0)
}
// EXAMPLE-END

int main() {
  const cg::Contacts<double> contacts = two_spheres();
  if (contacts.size() != 1) {
    std::printf("expected 1 contact, got %zu\n", contacts.size());
    return 1;
  }
  std::printf("contact %lld-%lld distance %g normal (%g, %g, %g)\n", static_cast<long long>(contacts.id_a[0]),
              static_cast<long long>(contacts.id_b[0]), contacts.distance[0], contacts.normal_on_b[0].x,
              contacts.normal_on_b[0].y, contacts.normal_on_b[0].z);
  const bool ok =
      contacts.id_a[0] == 0 && contacts.id_b[0] == 1 && std::abs(contacts.distance[0] + 0.5) < 1e-12 &&
      std::abs(contacts.normal_on_b[0].x + 1) < 1e-12 && std::abs(contacts.position_on_a[0].x - 1) < 1e-12 &&
      std::abs(contacts.position_on_b[0].x - 0.5) < 1e-12;
  return ok ? 0 : 1;
}
