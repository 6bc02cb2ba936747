// A 3x3 block-sparse (BSR) matrix with a fixed pattern, for Jacobians and the implicit
// system. The pattern is built once from the elements' vertex pairs; steps only write
// values. Storage is full (both triangles of a symmetric matrix), block rows sorted by
// column, each block row-major (9 doubles).
#pragma once

#include <array>
#include <span>
#include <vector>

#include "loom/common.hpp"

namespace loom {

struct BsrPattern {
  Index n = 0;                    ///< block rows = block columns = vertices
  std::vector<Index> row_ptr;     ///< n + 1
  std::vector<Index> col;         ///< nnz blocks, sorted within each row
  std::vector<Index> diag;        ///< n: position of block (i, i) in col

  /// Pattern holding the diagonal plus both (i, j) and (j, i) for every pair.
  static BsrPattern from_pairs(Index n, std::span<const std::array<Index, 2>> pairs);
  Index nnz_blocks() const { return static_cast<Index>(col.size()); }
  /// Position of block (i, j) in col/values, or -1 when it is not in the pattern.
  Index find(Index i, Index j) const;
};

class BsrMatrix {
 public:
  BsrMatrix() = default;
  explicit BsrMatrix(const BsrPattern* pattern);  ///< values zeroed; the pattern must outlive this

  const BsrPattern& pattern() const { return *pattern_; }
  bool has_pattern() const { return pattern_ != nullptr; }
  Index rows() const { return pattern_ ? pattern_->n : 0; }  ///< block rows

  std::vector<double>& values() { return values_; }
  const std::vector<double>& values() const { return values_; }
  double* block(Index k) { return values_.data() + 9 * static_cast<std::size_t>(k); }
  const double* block(Index k) const { return values_.data() + 9 * static_cast<std::size_t>(k); }

  void set_zero();  ///< parallel
  /// y = A x (parallel over block rows; x and y have 3n entries and must not alias).
  void multiply(std::span<const double> x, std::span<double> y) const;
  /// Copy to a dense row-major (3n x 3n) matrix (tests and small debugging only).
  std::vector<double> to_dense() const;
  /// max |A - A^T| / max |A| (0 for a symmetric matrix).
  double asymmetry() const;

 private:
  const BsrPattern* pattern_ = nullptr;
  std::vector<double> values_;
};

/// The Baraff-Witkin constraint filter S (NUMERICS.md 3.3): per vertex an orthogonal
/// projector onto its free directions, S_i = I (3 free DOF), I - p p^T (2), I - p p^T - q q^T
/// (1) or 0 (0 free DOF). z holds the prescribed velocity change of the constrained DOFs.
class Filter {
 public:
  void reset(Index n);                       ///< all vertices free
  void constrain_all(Index i);               ///< S_i = 0 (pinned)
  void constrain_direction(Index i, const double p[3]);  ///< removes direction p (unit) from S_i
  Index size() const { return static_cast<Index>(free_dofs_.size()); }
  int free_dofs(Index i) const { return free_dofs_[i]; }
  const std::array<double, 9>& projector(Index i) const { return S_[i]; }
  bool all_free() const { return constrained_.empty(); }
  const std::vector<Index>& constrained() const { return constrained_; }

  /// y <- S y (only constrained vertices are touched).
  void apply(std::span<double> y) const;
  /// y <- (I - S) y.
  void apply_complement(std::span<double> y) const;

 private:
  std::vector<std::uint8_t> free_dofs_;
  std::vector<std::array<double, 9>> S_;  // per vertex (identity for free ones)
  std::vector<Index> constrained_;        // sorted, unique
};

}  // namespace loom
