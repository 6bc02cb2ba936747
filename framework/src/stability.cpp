#include "loom/stability.hpp"

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/scene.hpp"

namespace loom {

double stable_step_factor(const std::string& integrator) {
  if (integrator == "symplectic_euler") return 2.0;
  if (integrator == "rk4") return 2.0 * std::sqrt(2.0);
  if (integrator == "harmonic_oscillation") return std::sqrt(2.0);
  return 0.0;
}

std::optional<StepLimit> estimate_step_limit(Scene& sc, const std::string& integrator) {
  const double c = stable_step_factor(integrator);
  if (c == 0.0) return std::nullopt;
  if (!sc.material || !sc.material->has_jacobian()) return std::nullopt;
  const State& s = sc.state;
  const Index n = s.size();
  std::vector<std::array<Index, 2>> pairs;
  sc.material->jacobian_pairs(pairs);
  // The pattern must outlive the material's binding: keep it for the life of the process
  // (validate builds one scene).
  static std::vector<std::unique_ptr<BsrPattern>> keep;
  keep.push_back(std::make_unique<BsrPattern>(BsrPattern::from_pairs(n, pairs)));
  const BsrPattern& P = *keep.back();
  sc.material->bind_pattern(P);
  BsrMatrix J(&P);
  sc.material->compute_jacobians(s.x, s.v, J, nullptr);

  // Power iteration on the symmetric form B = W^(1/2) K W^(1/2), W = diag(1/m) (0 on pins),
  // which has the eigenvalues of M^-1 K: the Rayleigh quotient increases monotonically
  // towards lambda_max.
  const std::size_t N = 3 * static_cast<std::size_t>(n);
  std::vector<double> w(N), x(N), y(N), bx(N);
  for (Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) w[3 * static_cast<std::size_t>(i) + k] = std::sqrt(s.inv_mass[i]);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  double norm = 0;
  for (std::size_t k = 0; k < N; ++k) {
    x[k] = u(rng) * w[k];
    norm += x[k] * x[k];
  }
  if (!(norm > 0)) return std::nullopt;  // everything pinned
  StepLimit out;
  out.factor = c;
  double lambda = 0;
  for (int it = 0; it < 200; ++it) {
    norm = 0;
    for (double v : x) norm += v * v;
    norm = std::sqrt(norm);
    for (double& v : x) v /= norm;
    for (std::size_t k = 0; k < N; ++k) y[k] = w[k] * x[k];
    J.multiply(y, bx);
    double rq = 0;  // Rayleigh quotient x . B x with |x| = 1
    for (std::size_t k = 0; k < N; ++k) {
      bx[k] = -w[k] * bx[k];
      rq += x[k] * bx[k];
    }
    x.swap(bx);
    out.iterations = it + 1;
    const bool converged = it > 10 && std::abs(rq - lambda) <= 1e-4 * std::abs(rq);
    lambda = rq;
    if (converged) break;
  }
  if (!(lambda > 0) || !std::isfinite(lambda)) return std::nullopt;
  out.lambda_max = lambda;
  out.h_max = c / std::sqrt(lambda);
  return out;
}

}  // namespace loom
