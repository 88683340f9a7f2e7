#pragma once
// A mesh as text, for the `mesh` and `tile` commands and for shared/bench's checker.
#include "core/mesh.hpp"

#include <string>

namespace tb::tiler {

// A mesh in grid coordinates as text: OBJ ("v column row height", 1-based "f i j k") or JSON
// ({"vertices":[x,y,z,...],"triangles":[i,j,k,...]}, 0-based), heights as the float the mesher
// used, widened to double and written with 17 significant digits, so a reader parsing doubles
// gets exactly that float's value. The formats shared/bench's linf_check reads.
std::string mesh_to_obj(const core::Mesh& mesh);
std::string mesh_to_json(const core::Mesh& mesh);

} // namespace tb::tiler
