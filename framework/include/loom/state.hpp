// The simulation state, a structure of arrays.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "loom/common.hpp"

namespace loom {

/// Positions and velocities are flat arrays of 3 * n doubles (x0 y0 z0 x1 y1 z1 ...),
/// so that they map directly onto the 3n vectors of the linear algebra.
/// Pinned vertices have inverse mass 0; their motion is prescribed by the scene's pin groups
/// (Scene::pins, loom/pins.hpp); a fixed pin never moves, bit for bit.
struct State {
  std::vector<double> x;          ///< positions, 3n
  std::vector<double> v;          ///< velocities, 3n
  std::vector<double> mass;       ///< lumped masses, n (kg), > 0
  std::vector<double> inv_mass;   ///< 1/mass for free vertices, 0 for pinned ones
  std::vector<std::uint8_t> pinned;   ///< 1 = pinned
  std::vector<Index> pin_list;        ///< indices of pinned vertices (sorted)
  double time = 0;                ///< simulated time (s)
  std::int64_t step = 0;          ///< steps taken

  Index size() const { return static_cast<Index>(mass.size()); }
  void resize(Index n);
  /// Pin vertex i (inverse mass 0, velocity zero). Keeps pin_list sorted and unique.
  void pin(Index i);
  /// Recompute inv_mass from mass and pinned.
  void update_inverse_masses();

  std::span<double> xs() { return x; }
  std::span<double> vs() { return v; }
};

/// Energies of a state, for the stats CSV and the tests.
double kinetic_energy(const State& s);
/// Gravitational potential energy -sum m_i g . x_i (zero at the origin).
double gravitational_energy(const State& s, const double gravity[3]);

}  // namespace loom
