#pragma once
// A text copy of a contact file's rows (detect --csv): a header, then one line per contact, every
// field the run produced in kContactFields order (a vector field is three columns, name_x, _y, _z).
// Written to a temporary name, then renamed: no partial file after an error (IoError).
#include <string>

#include "contacts.hpp"

namespace cg {

template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& contacts);

}  // namespace cg
