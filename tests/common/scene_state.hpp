// Shared by the tests (tests/CMakeLists.txt puts tests/ on every test's include path): the state
// of a scene built by hand in a test, as scene_build gives a scene file's.
#pragma once

#include "loom/scene.hpp"

namespace loom_test {

/// The scene's state sized to its mesh, at the mesh's positions, at rest, nothing pinned, with
/// the masses of the scene's material and their inverses.
inline void init_state(loom::Scene& sc) {
  loom::State& st = sc.state;
  st.resize(sc.mesh.num_vertices());
  st.x = sc.mesh.positions;
  sc.material->compute_masses(st.mass);
  st.update_inverse_masses();
}

}  // namespace loom_test
