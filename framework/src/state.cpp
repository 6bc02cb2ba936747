#include "loom/state.hpp"

#include <algorithm>

namespace loom {

void State::resize(Index n) {
  x.assign(3 * static_cast<std::size_t>(n), 0.0);
  v.assign(3 * static_cast<std::size_t>(n), 0.0);
  mass.assign(n, 0.0);
  inv_mass.assign(n, 0.0);
  pinned.assign(n, 0);
  pin_list.clear();
}

void State::pin(Index i) {
  pinned[i] = 1;
  inv_mass[i] = 0.0;
  v[3 * i] = v[3 * i + 1] = v[3 * i + 2] = 0.0;
  auto it = std::lower_bound(pin_list.begin(), pin_list.end(), i);
  if (it == pin_list.end() || *it != i) pin_list.insert(it, i);
}

void State::update_inverse_masses() {
  for (std::size_t i = 0; i < mass.size(); ++i) inv_mass[i] = pinned[i] ? 0.0 : 1.0 / mass[i];
}

double kinetic_energy(const State& s) {
  double e = 0;
  const Index n = s.size();
#pragma omp parallel for reduction(+ : e) schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i) {
    const double* v = &s.v[3 * i];
    e += 0.5 * s.mass[i] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  }
  return e;
}

double gravitational_energy(const State& s, const double g[3]) {
  double e = 0;
  const Index n = s.size();
#pragma omp parallel for reduction(+ : e) schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i) {
    const double* x = &s.x[3 * i];
    e -= s.mass[i] * (g[0] * x[0] + g[1] * x[1] + g[2] * x[2]);
  }
  return e;
}

}  // namespace loom
