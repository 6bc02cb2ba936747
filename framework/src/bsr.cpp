#include "loom/bsr.hpp"

#include <algorithm>
#include <cmath>

namespace loom {

BsrPattern BsrPattern::from_pairs(Index n, std::span<const std::array<Index, 2>> pairs) {
  BsrPattern p;
  p.n = n;
  std::vector<Index> count(n + 1, 1);  // the diagonal
  for (const auto& e : pairs) {
    if (e[0] == e[1]) continue;
    ++count[e[0]];
    ++count[e[1]];
  }
  p.row_ptr.assign(n + 1, 0);
  for (Index i = 0; i < n; ++i) p.row_ptr[i + 1] = p.row_ptr[i] + count[i];
  std::vector<Index> fill(p.row_ptr.begin(), p.row_ptr.end() - 1);
  p.col.assign(p.row_ptr[n], 0);
  for (Index i = 0; i < n; ++i) p.col[fill[i]++] = i;
  for (const auto& e : pairs) {
    if (e[0] == e[1]) continue;
    p.col[fill[e[0]]++] = e[1];
    p.col[fill[e[1]]++] = e[0];
  }
  // sort and deduplicate each row, then compact
  std::vector<Index> new_ptr(n + 1, 0);
  Index out = 0;
  for (Index i = 0; i < n; ++i) {
    auto b = p.col.begin() + p.row_ptr[i], e = p.col.begin() + p.row_ptr[i + 1];
    std::sort(b, e);
    auto last = std::unique(b, e);
    new_ptr[i] = out;
    for (auto it = b; it != last; ++it) p.col[out++] = *it;
  }
  new_ptr[n] = out;
  p.col.resize(out);
  p.row_ptr = std::move(new_ptr);
  p.diag.resize(n);
  for (Index i = 0; i < n; ++i) p.diag[i] = p.find(i, i);
  return p;
}

Index BsrPattern::find(Index i, Index j) const {
  if (i < 0 || i >= n) return -1;
  auto b = col.begin() + row_ptr[i], e = col.begin() + row_ptr[i + 1];
  auto it = std::lower_bound(b, e, j);
  return (it != e && *it == j) ? static_cast<Index>(it - col.begin()) : -1;
}

BsrMatrix::BsrMatrix(const BsrPattern* pattern) : pattern_(pattern) {
  values_.assign(9 * static_cast<std::size_t>(pattern->nnz_blocks()), 0.0);
}

void BsrMatrix::set_zero() {
  const std::size_t m = values_.size();
  double* v = values_.data();
#pragma omp parallel for schedule(static) if (m >= 9 * static_cast<std::size_t>(kParallelMinVertices))
  for (std::size_t k = 0; k < m; ++k) v[k] = 0.0;
}

void BsrMatrix::multiply(std::span<const double> x, std::span<double> y) const {
  const BsrPattern& p = *pattern_;
  const Index n = p.n;
  const double* vals = values_.data();
  const Index* rp = p.row_ptr.data();
  const Index* cl = p.col.data();
  const double* xp = x.data();
  double* yp = y.data();
#pragma omp parallel for schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i) {
    double s0 = 0, s1 = 0, s2 = 0;
    for (Index k = rp[i]; k < rp[i + 1]; ++k) {
      const double* B = vals + 9 * static_cast<std::size_t>(k);
      const double* xj = xp + 3 * static_cast<std::size_t>(cl[k]);
      s0 += B[0] * xj[0] + B[1] * xj[1] + B[2] * xj[2];
      s1 += B[3] * xj[0] + B[4] * xj[1] + B[5] * xj[2];
      s2 += B[6] * xj[0] + B[7] * xj[1] + B[8] * xj[2];
    }
    yp[3 * i] = s0;
    yp[3 * i + 1] = s1;
    yp[3 * i + 2] = s2;
  }
}

std::vector<double> BsrMatrix::to_dense() const {
  const BsrPattern& p = *pattern_;
  const std::size_t N = 3 * static_cast<std::size_t>(p.n);
  std::vector<double> d(N * N, 0.0);
  for (Index i = 0; i < p.n; ++i)
    for (Index k = p.row_ptr[i]; k < p.row_ptr[i + 1]; ++k)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) d[(3 * i + r) * N + 3 * p.col[k] + c] = block(k)[3 * r + c];
  return d;
}

double BsrMatrix::asymmetry() const {
  const BsrPattern& p = *pattern_;
  double maxa = 0, maxd = 0;
  for (Index i = 0; i < p.n; ++i)
    for (Index k = p.row_ptr[i]; k < p.row_ptr[i + 1]; ++k) {
      const Index j = p.col[k];
      const Index kt = p.find(j, i);
      const double* B = block(k);
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          maxa = std::max(maxa, std::abs(B[3 * r + c]));
          const double t = kt >= 0 ? block(kt)[3 * c + r] : 0.0;
          maxd = std::max(maxd, std::abs(B[3 * r + c] - t));
        }
    }
  return maxa > 0 ? maxd / maxa : 0.0;
}

// ---- Filter ----

namespace {
constexpr std::array<double, 9> kIdentity{1, 0, 0, 0, 1, 0, 0, 0, 1};
}

void Filter::reset(Index n) {
  free_dofs_.assign(n, 3);
  S_.assign(n, kIdentity);
  constrained_.clear();
}

static void insert_sorted(std::vector<Index>& v, Index i) {
  auto it = std::lower_bound(v.begin(), v.end(), i);
  if (it == v.end() || *it != i) v.insert(it, i);
}

void Filter::constrain_all(Index i) {
  free_dofs_[i] = 0;
  S_[i].fill(0.0);
  insert_sorted(constrained_, i);
}

void Filter::constrain_direction(Index i, const double p_in[3]) {
  if (free_dofs_[i] == 0) return;
  // Remove the component of p already constrained, then normalise.
  auto& S = S_[i];
  double p[3];
  for (int r = 0; r < 3; ++r) p[r] = S[3 * r] * p_in[0] + S[3 * r + 1] * p_in[1] + S[3 * r + 2] * p_in[2];
  const double len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
  if (len < 1e-12) return;  // already constrained along p
  for (double& c : p) c /= len;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) S[3 * r + c] -= p[r] * p[c];
  free_dofs_[i] -= 1;
  if (free_dofs_[i] == 0) S.fill(0.0);
  insert_sorted(constrained_, i);
}

void Filter::apply(std::span<double> y) const {
  for (const Index i : constrained_) {
    double* yi = &y[3 * static_cast<std::size_t>(i)];
    if (free_dofs_[i] == 0) {
      yi[0] = yi[1] = yi[2] = 0.0;
      continue;
    }
    const auto& S = S_[i];
    const double a = yi[0], b = yi[1], c = yi[2];
    yi[0] = S[0] * a + S[1] * b + S[2] * c;
    yi[1] = S[3] * a + S[4] * b + S[5] * c;
    yi[2] = S[6] * a + S[7] * b + S[8] * c;
  }
}

void Filter::apply_complement(std::span<double> y) const {
  const std::size_t n = free_dofs_.size();
  std::size_t next = 0;
  for (std::size_t i = 0; i < n; ++i) {
    double* yi = &y[3 * i];
    if (next < constrained_.size() && static_cast<std::size_t>(constrained_[next]) == i) {
      ++next;
      if (free_dofs_[i] == 0) continue;  // (I - 0) y = y
      const auto& S = S_[i];
      const double a = yi[0], b = yi[1], c = yi[2];
      yi[0] = a - (S[0] * a + S[1] * b + S[2] * c);
      yi[1] = b - (S[3] * a + S[4] * b + S[5] * c);
      yi[2] = c - (S[6] * a + S[7] * b + S[8] * c);
    } else {
      yi[0] = yi[1] = yi[2] = 0.0;
    }
  }
}

}  // namespace loom
