// The measured-fabric library (materials/wang2011/, README there): a scene names a fabric
// instead of a material file, `material: {type: gnatv, fabric: 11oz-black-denim}`, and gets
// its membrane curves and, unless the scene gives its own `bending` block, its bending data.
#pragma once

#include <string>
#include <vector>

#include "loom/params.hpp"

namespace loom {

/// Folders searched for fabric files <name>.yaml: $LOOM_FABRIC_PATH (colon separated), the
/// source tree's materials/wang2011, then <prefix>/share/loom/materials/wang2011 next to the
/// running executable's install tree.
std::vector<std::string> fabric_search_path();

/// Fabric names found on the search path (file stems), sorted, without duplicates.
std::vector<std::string> list_fabrics();

/// Path of the fabric file named by `name_node`; fails on that node (file:line) listing every
/// fabric that exists, with a "did you mean", when there is none of that name.
std::string resolve_fabric(const Params& name_node);

/// The scene hook for a material section: when it has `fabric`, check the combination (type
/// gnatv, no material_file), set material_file to the fabric's file for the plugin and return
/// the file's `bending` block (an invalid Params when it has none, or when there is no fabric).
Params apply_fabric(const Params& material, const std::string& type);

}  // namespace loom
