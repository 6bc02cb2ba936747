#include "self_contact.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iterator>

namespace loom {

double thread_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

namespace {
inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
// Sides of a pair: the vertex against the triangle's three, or edge against edge.
inline bool same_side(bool vt, int a, int b) { return vt ? (a == 0) == (b == 0) : (a < 2) == (b < 2); }
}  // namespace

void ImplicitSelfContact::prepare(const Mesh& mesh, double thickness, double friction) {
  thickness_ = thickness;
  friction_ = friction;
  const Index n = mesh.num_vertices();
  const auto edges = mesh.edges();
  ring_ptr_.assign(n + 1, 0);
  for (const auto& e : edges) {
    ++ring_ptr_[e[0] + 1];
    ++ring_ptr_[e[1] + 1];
  }
  for (Index i = 0; i < n; ++i) ring_ptr_[i + 1] += ring_ptr_[i] + 1;  // + the vertex itself
  ring_.assign(ring_ptr_[n], 0);
  std::vector<Index> fill(ring_ptr_.begin(), ring_ptr_.end() - 1);
  for (Index i = 0; i < n; ++i) ring_[fill[i]++] = i;
  for (const auto& e : edges) {
    ring_[fill[e[0]]++] = e[1];
    ring_[fill[e[1]]++] = e[0];
  }
  d_.assign(3 * static_cast<std::size_t>(n), 0.0);
  diag_.assign(9 * static_cast<std::size_t>(n), 0.0);
  pairs_.reserve(4 * static_cast<std::size_t>(n));
  contacts_.reserve(4 * static_cast<std::size_t>(n));
  reserve_.clear();
  extra_.clear();
  stats_ = {};
  restarts_ = 0;
}

bool ImplicitSelfContact::find(SelfCollision& sc, const State& s, const std::vector<double>& dv, double h,
                               const BsrPattern& P) {
  const double t0 = thread_seconds();
  const std::size_t N = 3 * static_cast<std::size_t>(s.size());
  for (std::size_t k = 0; k < N; ++k) d_[k] = h * (s.v[k] + dv[k]);
  sc.proximity_pairs(s.x.data(), d_.data(), pairs_);
  contacts_.clear();
  stats_ = {};
  stats_.pairs = static_cast<Index>(pairs_.size());
  stats_.pairs_seconds = thread_seconds() - t0;
  bool complete = true;
  const double th = thickness_;
  h_ = h;
  for (const ProximityPair& p : pairs_) {
    double W = 0, dn = 0;
    for (int a = 0; a < 4; ++a) {
      W += p.w[a] * p.w[a] * s.inv_mass[p.v[a]];
      dn += p.w[a] * dot3(&d_[3 * static_cast<std::size_t>(p.v[a])], p.normal);
    }
    if (!(W > 0)) continue;  // all four pinned
    // Within the thickness now, or predicted (linearised along n) to come within it.
    if (p.distance >= th && p.distance + dn >= th) continue;
    Contact c;
    c.vt = p.vt;
    for (int a = 0; a < 4; ++a) {
      c.v[a] = p.v[a];
      c.w[a] = p.w[a];
    }
    for (int k = 0; k < 3; ++k) c.n[k] = p.normal[k];
    c.gap0 = p.distance;
    c.rest = std::min(th, p.distance);
    c.k = kStiffness / (W * h * h);
    c.W = W;
    c.lambda = 0;
    c.c1 = 0;
    c.touching = p.distance < th * (1 + kTouchingTolerance);
    c.stick = false;
    c.released = false;
    c.fr = 0;
    c.len0 = 0;
    c.jn = 0;
    if (matrix_free_) {  // the solver applies the term: no blocks needed
      std::fill(std::begin(c.blk), std::end(c.blk), Index{-1});
      contacts_.push_back(c);
      continue;
    }
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const Index q = P.find(c.v[a], c.v[b]);
        c.blk[4 * a + b] = q;
        complete &= q >= 0;
      }
    contacts_.push_back(c);
  }
  stats_.contacts = static_cast<Index>(contacts_.size());
  stats_.find_seconds = thread_seconds() - t0;
  complete_ = complete;
  return !contacts_.empty();
}

const std::vector<std::array<Index, 2>>& ImplicitSelfContact::reserve_pairs(std::size_t limit) {
  fresh_.clear();
  for (const Contact& c : contacts_) {
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        if (a == b) continue;
        if (same_side(c.vt, a, b)) {  // an element's own edge: in the material's pattern, normally
          fresh_.push_back({std::min(c.v[a], c.v[b]), std::max(c.v[a], c.v[b])});
          continue;
        }
        // The vertex against the other side's one-rings: the blocks a contact sliding to a
        // neighbouring element needs.
        for (Index r = ring_ptr_[c.v[b]]; r < ring_ptr_[c.v[b] + 1]; ++r) {
          const Index u = ring_[r];
          if (u == c.v[a]) continue;
          fresh_.push_back({std::min(c.v[a], u), std::max(c.v[a], u)});
        }
      }
  }
  std::sort(fresh_.begin(), fresh_.end());
  fresh_.erase(std::unique(fresh_.begin(), fresh_.end()), fresh_.end());
  // The union with the blocks kept from earlier extensions: a contact state that comes back, or
  // a contact that slides within the one-rings kept, finds its blocks without a new extension.
  const std::size_t old = reserve_.size();
  reserve_.insert(reserve_.end(), fresh_.begin(), fresh_.end());
  std::inplace_merge(reserve_.begin(), reserve_.begin() + static_cast<std::ptrdiff_t>(old), reserve_.end());
  reserve_.erase(std::unique(reserve_.begin(), reserve_.end()), reserve_.end());
  if (reserve_.size() > limit) {  // keep the pattern from growing without bound: restart from the current contacts
    reserve_.assign(fresh_.begin(), fresh_.end());
    ++restarts_;
  }
  return reserve_;
}

bool ImplicitSelfContact::bind(const BsrPattern& P, const BsrPattern& material) {
  extra_.clear();
  for (Index i = 0; i < P.n; ++i)
    for (Index q = P.row_ptr[i]; q < P.row_ptr[i + 1]; ++q)
      if (material.find(i, P.col[q]) < 0) extra_.push_back({q, i, P.col[q]});
  bool complete = true;
  for (Contact& c : contacts_)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        c.blk[4 * a + b] = P.find(c.v[a], c.v[b]);
        complete &= c.blk[4 * a + b] >= 0;
      }
  complete_ = complete;
  return complete;
}

void ImplicitSelfContact::zero_extra_blocks(BsrMatrix& J) const {
  for (const auto& e : extra_) std::fill(J.block(e[0]), J.block(e[0]) + 9, 0.0);
}

void ImplicitSelfContact::undo_laplacian(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v,
                                         double hcd) const {
  if (hcd == 0) return;
  // The kernel added -h c_d I to A_ij and h c_d v_j to b_i (b_i = h (... - c_d (n_i v_i - sum_j v_j))).
  for (const auto& e : extra_) {
    double* a = A.block(e[0]);
    a[0] += hcd;
    a[4] += hcd;
    a[8] += hcd;
    for (int k = 0; k < 3; ++k) b[3 * static_cast<std::size_t>(e[1]) + k] -= hcd * v[3 * static_cast<std::size_t>(e[2]) + k];
  }
}

void ImplicitSelfContact::add_term(const Contact& c, BsrMatrix& A, std::vector<double>& b,
                                   const std::vector<double>& v, double h, double sign) const {
  double un = 0;
  for (int a = 0; a < 4; ++a) un += c.w[a] * dot3(&v[3 * static_cast<std::size_t>(c.v[a])], c.n);
  const double C0 = c.gap0 - c.rest;
  const double hk = sign * h * c.k;
  double nn[9];
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) nn[3 * r + q] = c.n[r] * c.n[q];
  for (int a = 0; a < 4; ++a) {
    double* ba = &b[3 * static_cast<std::size_t>(c.v[a])];
    const double fa = -hk * c.w[a] * (C0 + h * un);
    for (int k = 0; k < 3; ++k) ba[k] += fa * c.n[k];
    if (matrix_free_) continue;  // the matrix term is applied by the solver (apply_add)
    for (int bb = 0; bb < 4; ++bb) {
      double* blk = A.block(c.blk[4 * a + bb]);
      const double s = h * hk * c.w[a] * c.w[bb];
      for (int e = 0; e < 9; ++e) blk[e] += s * nn[e];
    }
  }
}

void ImplicitSelfContact::apply_add(const double* x, double* y, double scale) const {
  const double hh = scale * h_ * h_;
  for (const Contact& c : contacts_) {
    double g = 0;  // n . sum_b w_b x_b
    for (int b = 0; b < 4; ++b) g += c.w[b] * dot3(&x[3 * static_cast<std::size_t>(c.v[b])], c.n);
    const double t = hh * c.k * g;
    for (int a = 0; a < 4; ++a) {
      double* ya = &y[3 * static_cast<std::size_t>(c.v[a])];
      const double q = t * c.w[a];
      for (int k = 0; k < 3; ++k) ya[k] += q * c.n[k];
    }
    if (c.fr == 0) continue;
    // The friction damper: y_a += scale h c w_a P (sum_b w_b x_b).
    double u[3] = {0, 0, 0};
    for (int b = 0; b < 4; ++b)
      for (int k = 0; k < 3; ++k) u[k] += c.w[b] * x[3 * static_cast<std::size_t>(c.v[b]) + k];
    const double un = dot3(u, c.n);
    for (int k = 0; k < 3; ++k) u[k] = scale * c.fr * (u[k] - un * c.n[k]);
    for (int a = 0; a < 4; ++a) {
      double* ya = &y[3 * static_cast<std::size_t>(c.v[a])];
      for (int k = 0; k < 3; ++k) ya[k] += c.w[a] * u[k];
    }
  }
}

void ImplicitSelfContact::add_diagonal(double* D) const {
  const double hh = h_ * h_;
  for (const Contact& c : contacts_)
    for (int a = 0; a < 4; ++a) {
      double* Da = &D[9 * static_cast<std::size_t>(c.v[a])];
      const double s = hh * c.k * c.w[a] * c.w[a];
      const double f = c.fr * c.w[a] * c.w[a];
      for (int r = 0; r < 3; ++r)
        for (int q = 0; q < 3; ++q) Da[3 * r + q] += (s - f) * c.n[r] * c.n[q] + (r == q ? f : 0.0);
    }
}

void ImplicitSelfContact::add_terms(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v,
                                    double h) const {
  for (const Contact& c : contacts_) add_term(c, A, b, v, h, 1.0);
}

bool ImplicitSelfContact::release(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v,
                                  const std::vector<double>& dv, double h) {
  std::size_t keep = 0;
  Index released = 0;
  for (std::size_t i = 0; i < contacts_.size(); ++i) {
    Contact& c = contacts_[i];
    double u1 = 0;
    for (int a = 0; a < 4; ++a) {
      const std::size_t o = 3 * static_cast<std::size_t>(c.v[a]);
      for (int k = 0; k < 3; ++k) u1 += c.w[a] * (v[o + k] + dv[o + k]) * c.n[k];
    }
    c.c1 = c.gap0 - c.rest + h * u1;
    if (c.c1 > 0) {
      add_term(c, A, b, v, h, -1.0);
      ++released;
      continue;
    }
    contacts_[keep++] = c;
  }
  contacts_.resize(keep);
  stats_.contacts = static_cast<Index>(keep);
  stats_.released += released;
  return released > 0;
}

void ImplicitSelfContact::apply_friction(const State& s, std::vector<double>& dv, double h) {
  for (Contact& c : contacts_) {
    double vrel[3] = {0, 0, 0}, W = 0;
    for (int a = 0; a < 4; ++a) {
      const std::size_t o = 3 * static_cast<std::size_t>(c.v[a]);
      for (int k = 0; k < 3; ++k) vrel[k] += c.w[a] * (s.v[o + k] + dv[o + k]);
      W += c.w[a] * c.w[a] * s.inv_mass[c.v[a]];
    }
    c.c1 = c.gap0 - c.rest + h * dot3(vrel, c.n);
    if (!c.touching || friction_ <= 0 || c.c1 >= 0) continue;
    const double J = h * c.k * -c.c1;  // normal impulse of the spring over the step (N s)
    const double vn = dot3(vrel, c.n);
    double vt[3];
    for (int k = 0; k < 3; ++k) vt[k] = vrel[k] - vn * c.n[k];
    const double len = std::sqrt(dot3(vt, vt));
    if (!(len > 0)) continue;
    // Relative tangential velocity change: up to mu J W, never reversing it.
    const double change = std::min(len, friction_ * J * W);
    const double Jt = change / (W * len);
    for (int a = 0; a < 4; ++a) {
      const double q = -c.w[a] * s.inv_mass[c.v[a]] * Jt;
      for (int k = 0; k < 3; ++k) dv[3 * static_cast<std::size_t>(c.v[a]) + k] += q * vt[k];
    }
    ++stats_.friction;
  }
}

namespace {
// dA = dhc w_a w_b P on the contact's blocks (assembled), db_a = -dhc w_a P u0.
void add_damper(const ImplicitSelfContact::Contact& c, double dhc, const State& s, BsrMatrix& A,
                std::vector<double>& b, bool matrix_free) {
  double u0[3] = {0, 0, 0};
  for (int a = 0; a < 4; ++a)
    for (int k = 0; k < 3; ++k) u0[k] += c.w[a] * s.v[3 * static_cast<std::size_t>(c.v[a]) + k];
  const double u0n = dot3(u0, c.n);
  double pu[3];
  for (int k = 0; k < 3; ++k) pu[k] = u0[k] - u0n * c.n[k];
  for (int aa = 0; aa < 4; ++aa) {
    double* ba = &b[3 * static_cast<std::size_t>(c.v[aa])];
    for (int k = 0; k < 3; ++k) ba[k] -= dhc * c.w[aa] * pu[k];
    if (matrix_free) continue;
    for (int bb = 0; bb < 4; ++bb) {
      double* blk = A.block(c.blk[4 * aa + bb]);
      const double q = dhc * c.w[aa] * c.w[bb];
      for (int r = 0; r < 3; ++r)
        for (int p = 0; p < 3; ++p) blk[3 * r + p] += q * ((r == p ? 1.0 : 0.0) - c.n[r] * c.n[p]);
    }
  }
}
// |u_t| of the pair at v + dv.
double tangential_speed(const ImplicitSelfContact::Contact& c, const State& s, const std::vector<double>& dv,
                        double* ut = nullptr) {
  double u[3] = {0, 0, 0};
  for (int a = 0; a < 4; ++a) {
    const std::size_t o = 3 * static_cast<std::size_t>(c.v[a]);
    for (int k = 0; k < 3; ++k) u[k] += c.w[a] * (s.v[o + k] + dv[o + k]);
  }
  const double un = dot3(u, c.n);
  double t[3];
  for (int k = 0; k < 3; ++k) t[k] = u[k] - un * c.n[k];
  if (ut)
    for (int k = 0; k < 3; ++k) ut[k] = t[k];
  return std::sqrt(dot3(t, t));
}
// The pair's response to a tangential impulse along ut (|ut| = l1) with its other vertices as
// solved: D = 1 / sum_a w_a^2 / K_a, K_a = ut^T (A_aa + E_aa) ut / l1^2 less the pair's own
// damper (h c w_a^2, P ut = ut), at least m_a; pinned vertices do not move. E: the self-contact
// terms' diagonal blocks when they are matrix-free (9 per vertex), else null (they are in A).
double pair_response(const ImplicitSelfContact::Contact& c, const State& s, const BsrMatrix& A, const double* E,
                     const double* ut, double l1) {
  double sum = 0;
  for (int a = 0; a < 4; ++a) {
    const double im = s.inv_mass[c.v[a]];
    if (!(im > 0)) continue;
    double K = 1.0 / im;
    if (l1 > 0 && A.has_pattern()) {
      const double* blk = A.block(A.pattern().diag[c.v[a]]);
      const double* e = E ? E + 9 * static_cast<std::size_t>(c.v[a]) : nullptr;
      double q = 0;
      for (int r = 0; r < 3; ++r)
        for (int p = 0; p < 3; ++p) q += ut[r] * (blk[3 * r + p] + (e ? e[3 * r + p] : 0.0)) * ut[p];
      q = q / (l1 * l1) - c.fr * c.w[a] * c.w[a];
      K = std::max(K, q);
    }
    sum += c.w[a] * c.w[a] / K;
  }
  return sum > 0 ? 1.0 / sum : 1.0 / c.W;
}
}  // namespace

double ImplicitSelfContact::first_response(const Contact& c) const {
  const std::array<Index, 4> key{c.v[0], c.v[1], c.v[2], c.v[3]};
  const auto it = std::lower_bound(warm_.begin(), warm_.end(), key,
                                   [](const std::pair<std::array<Index, 4>, double>& e, const std::array<Index, 4>& k) {
                                     return e.first < k;
                                   });
  return it != warm_.end() && it->first == key ? it->second : 1.0 / c.W;
}

double* ImplicitSelfContact::matrix_free_diagonal() {
  if (!matrix_free_) return nullptr;
  double* E = diag_.data();
  for (const Contact& c : contacts_)
    for (int a = 0; a < 4; ++a) std::fill_n(E + 9 * static_cast<std::size_t>(c.v[a]), 9, 0.0);
  add_diagonal(E);
  return E;
}

bool ImplicitSelfContact::add_friction(const State& s, BsrMatrix& A, std::vector<double>& b,
                                       const std::vector<double>& dv, double h) {
  if (friction_ <= 0) return false;
  bool any = false;
  for (Contact& c : contacts_) {
    c.fr = 0;
    c.stick = false;
    c.released = false;
  }
  // Matrix-free: the self-contact terms' diagonal blocks (the springs', no damper yet) beside A.
  double* E = matrix_free_diagonal();
  // First every pair's response with the other vertices fixed, from A as the last solve had it
  // (no pair's damper in it yet, assembled or not), then the dampers.
  for (Contact& c : contacts_) {
    c.stiff = 0;
    double u1[3] = {0, 0, 0};
    for (int a = 0; a < 4; ++a) {
      const std::size_t o = 3 * static_cast<std::size_t>(c.v[a]);
      for (int k = 0; k < 3; ++k) u1[k] += c.w[a] * (s.v[o + k] + dv[o + k]);
    }
    c.c1 = c.gap0 - c.rest + h * dot3(u1, c.n);
    if (!c.touching || c.c1 >= 0 || !(c.W > 0)) continue;
    double ut[3];
    c.len0 = tangential_speed(c, s, dv, ut);
    c.stiff = pair_response(c, s, A, E, ut, c.len0);
  }
  for (Contact& c : contacts_) {
    if (!(c.stiff > 0)) continue;
    c.jn = h * c.k * -c.c1;
    const double mj = friction_ * c.jn;
    c.fr = kernels::bracketed_coulomb_damping(c.len0, first_response(c), c.stiff, mj, mj, c.stick);
    ++stats_.friction;
    any = true;
    add_damper(c, c.fr, s, A, b, matrix_free_);
  }
  warm_.clear();  // used: finish_friction records this step's
  return any;
}

bool ImplicitSelfContact::correct_friction(const State& s, BsrMatrix& A, std::vector<double>& b,
                                           const std::vector<double>& dv) {
  bool changed = false;
  // Matrix-free: the self-contact terms' diagonal blocks (with the dampers) beside A.
  double* E = matrix_free_diagonal();
  for (Contact& c : contacts_) {
    if (c.fr == 0) continue;
    double ut[3];
    const double l1 = tangential_speed(c, s, dv, ut);
    const double mj = friction_ * c.jn;
    const double impulse = c.fr * l1;  // the damper's friction impulse (N s)
    // Within the bound: a held pair (static friction may take any impulse up to mu J), or a
    // sliding one at mu J.
    if (c.stick ? impulse <= mj * (1 + kCoulombTolerance) : std::abs(impulse - mj) <= kCoulombTolerance * mj) continue;
    const double D = pair_response(c, s, A, E, ut, l1);
    double fr;  // l1 + impulse / D: the slip without this pair's damper
    bool stick;
    if (!loom::kernels::resize_damper(D, l1 + impulse / D, mj, mj, c.released, c.stick, c.fr, fr, stick)) continue;
    add_damper(c, fr - c.fr, s, A, b, matrix_free_);
    if (E)  // as add_damper changes A_aa when assembled
      for (int a = 0; a < 4; ++a) {
        double* e = E + 9 * static_cast<std::size_t>(c.v[a]);
        const double q = (fr - c.fr) * c.w[a] * c.w[a];
        for (int r = 0; r < 3; ++r)
          for (int p = 0; p < 3; ++p) e[3 * r + p] += q * ((r == p ? 1.0 : 0.0) - c.n[r] * c.n[p]);
      }
    if (c.stick && !stick) c.released = true;
    c.fr = fr;
    c.stick = stick;
    changed = true;
  }
  return changed;
}

kernels::FrictionTally<double> ImplicitSelfContact::friction_tally(const State& s, const std::vector<double>& dv) const {
  kernels::FrictionTally<double> t;
  for (const Contact& c : contacts_) {
    if (c.fr == 0) continue;
    const double mj = friction_ * c.jn;
    double excess;
    const double miss = kernels::coulomb_miss(c.fr * tangential_speed(c, s, dv), mj, mj, c.stick, excess);
    t.add(miss, excess, mj);
  }
  return t;
}

void ImplicitSelfContact::finish_friction(const State& s, std::vector<double>& dv) {
  warm_.clear();  // the pairs' responses in this step, for the next step's first dampers
  for (const Contact& c : contacts_) {
    if (c.fr == 0) continue;
    const double D = kernels::friction_response(c.fr, c.len0, tangential_speed(c, s, dv), 1.0 / c.W);
    if (D > 0) warm_.push_back({{c.v[0], c.v[1], c.v[2], c.v[3]}, D});
  }
  std::sort(warm_.begin(), warm_.end());
  for (const Contact& c : contacts_) {
    if (!c.stick) continue;
    double ut[3];
    const double len = tangential_speed(c, s, dv, ut);
    if (!(len > 0)) continue;
    const double a = friction_ * c.jn * c.W;
    const double Jt = std::min(len, a) / (c.W * len);
    for (int aa = 0; aa < 4; ++aa) {
      const double q = -c.w[aa] * s.inv_mass[c.v[aa]] * Jt;
      for (int k = 0; k < 3; ++k) dv[3 * static_cast<std::size_t>(c.v[aa]) + k] += q * ut[k];
    }
  }
}

int ImplicitSelfContact::stop_approach(State& s) {
  if (contacts_.empty()) return 0;
  double umax = 0;
  auto rel = [&](const Contact& c) {
    double u = 0;
    for (int a = 0; a < 4; ++a) u += c.w[a] * dot3(&s.v[3 * static_cast<std::size_t>(c.v[a])], c.n);
    return u;
  };
  for (Contact& c : contacts_) {
    c.lambda = 0;
    umax = std::max(umax, -rel(c));
  }
  if (!(umax > 0)) return 0;
  constexpr int kMaxPasses = 100;
  const double tol = 1e-6 * umax;  // relative normal velocity left (m/s)
  int pass = 0;
  while (pass < kMaxPasses) {
    ++pass;
    double change = 0;
    for (Contact& c : contacts_) {
      const double u = rel(c);
      const double next = std::max(0.0, c.lambda - u / c.W);
      const double d = next - c.lambda;
      if (d == 0) continue;
      c.lambda = next;
      change = std::max(change, std::abs(d) * c.W);
      for (int a = 0; a < 4; ++a) {
        const double q = c.w[a] * s.inv_mass[c.v[a]] * d;
        double* va = &s.v[3 * static_cast<std::size_t>(c.v[a])];
        for (int k = 0; k < 3; ++k) va[k] += q * c.n[k];
      }
    }
    if (change <= tol) break;
  }
  stats_.stop_passes = pass;
  return pass;
}

void ImplicitSelfContact::forces(const std::vector<double>& x, std::vector<double>& f) const {
  std::fill(f.begin(), f.end(), 0.0);
  for (const Contact& c : contacts_) {
    double gap = 0;
    for (int a = 0; a < 4; ++a) gap += c.w[a] * dot3(&x[3 * static_cast<std::size_t>(c.v[a])], c.n);
    const double C = gap - c.rest;
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) f[3 * static_cast<std::size_t>(c.v[a]) + k] += -c.k * C * c.w[a] * c.n[k];
  }
}

}  // namespace loom
