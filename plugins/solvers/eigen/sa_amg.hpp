// sa_amg: a smoothed-aggregation algebraic multigrid preconditioner for the filtered 3x3-block
// Baraff-Witkin system (NUMERICS.md 3.6), used by eigen_pcg (`preconditioner: sa_amg`).
//
// The hierarchy is built for the prefiltered matrix A~ = S A S + (I - S) (Tamstorf, Jones &
// McCormick 2015), so constrained DOFs are decoupled, with the rigid-body near-null space
// (3 translations + 3 rotations about the aggregate centroid, filtered by S) per aggregate.
// One V-cycle: block Gauss-Seidel (over-relaxed: block SOR, smoothing_relaxation) forward
// sweeps before the coarse correction (the rows are
// split into contiguous parts: the interior rows of the parts are swept lexicographically,
// the parts in parallel, then the rows coupled to another part by colour), the same sweeps
// in exactly the reverse order after it (so the cycle is symmetric), a dense Cholesky solve
// on the coarsest level. Symbolic set-up (aggregates, colourings, the patterns of P, R = P^T, A P and
// P^T A P) runs once per sparsity pattern; refresh() recomputes only values.
//
// The apply is a handful of kernels over block-sparse matrices with 3x3, 3x6 and 6x6 blocks
// (SpMV, block-row Gauss-Seidel per colour, restriction R r, prolongation x += P xc, a dense
// triangular solve pair), each a loop over block rows that writes only its own rows.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/common.hpp"
#include "half.hpp"
#include "huge_pages.hpp"

namespace loom::amg {

struct SaAmgOptions {
  int near_null_modes = 6;        ///< 6: translations + rotations (needs coordinates), 3: translations
  double strength_threshold = 0;  ///< block (i,j) strong if |A_ij|_F > theta sqrt(|A_ii|_F |A_jj|_F)
  int smoothing_sweeps = 1;       ///< Gauss-Seidel sweeps before and after the coarse correction
  /// Gauss-Seidel sweeps on the levels below the finest; 0 = smoothing_sweeps. The coarse
  /// levels of the rigid-body hierarchy are 6x6-block and denser than level 0, so a second
  /// sweep there costs about as much as one on level 0 (NUMERICS.md 3.6).
  int coarse_smoothing_sweeps = 0;
  /// Relaxation weight w of the block Gauss-Seidel smoother: x_i += w D_i^-1 (b - A x)_i,
  /// i.e. block SOR, in both sweeps (the backward sweep stays the adjoint of the forward one).
  /// The V-cycle stays SPD for 0 < w < 2 (W + W^T - W^T A W = W^T (2/w - 1) D W > 0 with
  /// W = (D/w + L)^-1; NUMERICS.md 3.6). 1 (default): Gauss-Seidel (the same bits as without
  /// it). 1.5 cut the contact-free wool hang's iterations by a fifth at every size (40 -> 32
  /// at 512^2) for the same bytes per iteration, but raised them by 28% on the shipped drapes
  /// with contacts (draped_ball_gnatv_bw, draped_mesh_sphere_gnatv_bw), so it is not the default.
  double smoothing_relaxation = 1.0;
  /// The same on the levels below the finest; 0 = smoothing_relaxation.
  double coarse_smoothing_relaxation = 0;
  Index coarse_dofs = 300;        ///< levels are added until a level has at most this many DOFs
  int max_levels = 10;
  /// Rebuild T, P every k refreshes (the Galerkin product always): measured, rebuilding every
  /// step saves no iterations on the wool hang and costs a quarter of the refresh.
  int prolongator_refresh_steps = 10;
  /// Recompute the coarse levels (Galerkin products, coarsest factor) every k refreshes; in
  /// between only level 0 (A~ and its diagonal blocks) follows the new matrix. Any k keeps the
  /// V-cycle SPD (NUMERICS.md 3.6); a changed S always refreshes everything.
  int hierarchy_refresh_steps = 1;
  /// Levels (from the finest) that aggregate on the distance-2 strength graph (aggregates of
  /// about 19 instead of 7 vertices on a triangle grid): a coarser, sparser next level, so a
  /// cheaper V-cycle and Galerkin product for possibly more iterations (NUMERICS.md 3.6).
  int aggressive_levels = 0;
  double prolongator_damping = 4.0 / 3.0;  ///< omega = damping / lambda_max(D^-1 A)
  /// The V-cycle reads float copies of the level matrices and transfer operators (set-up and
  /// all arithmetic stay double): half the memory traffic of the bandwidth-bound V-cycle. The
  /// V-cycle is still exactly symmetric (the smoother and residual use the same rounded
  /// matrix, R is the exact transpose of P, the smoother's diagonal inverses are symmetrised
  /// before rounding; NUMERICS.md 3.6).
  bool float_storage = true;
  /// With float_storage: the smoother's diagonal inverses in float too (symmetrised, then
  /// rounded; 2 of the ~12 MB that level 0 streams per V-cycle at 256^2). false: double, the
  /// previous default (the benchmark's `_before` variant).
  bool float_diagonal = true;
  /// With float_storage: level 0's transfer operators P and R (3x6 and 6x3 blocks, the
  /// rigid-body hierarchy) read as IEEE half (binary16) values, written when the prolongator
  /// is rebuilt: 36 instead of 72 bytes per block. P's entries are dimensionless (T has
  /// orthonormal columns, P = (I - w D^-1 A~) T), so half's range needs no scaling. R stays
  /// the exact transpose of the rounded P, so the V-cycle stays symmetric and positive
  /// definite (the coarse term is semidefinite for any P); the coarse matrix is still the
  /// Galerkin product of the double P (NUMERICS.md 3.6: what the rounding costs).
  bool half_transfers = true;
  Index parallel_min_dofs = 6144;  ///< loops run on all OpenMP threads from this many DOFs on
  /// The Gauss-Seidel row ranges of a threaded level hold at least this many DOFs (2 to 8
  /// ranges; 0: always 8). Rows coupled to another range are swept by colour and read their
  /// row twice in the fused first sweep, so short ranges cost passes: with 8 ranges, level 1 of
  /// the 256^2 wool hang had 25% boundary rows (53% at 128^2), with this rule 2 ranges and
  /// about 7% (NUMERICS.md 3.6). The range count depends on the level's size only, never on
  /// the thread count, so the result is the same on any number of threads.
  Index min_part_dofs = 24576;
  /// With a matrix-free term E (setup()'s `extra_diagonal`, e.g. baraff_witkin's self-contact
  /// springs): true, E's diagonal blocks join level 0 before the coarse levels are built, so
  /// the Galerkin products carry P^T diag(E) P; false, they join level 0 (its smoother and
  /// residual) only, after the coarse levels were built from A alone. Either way the V-cycle
  /// stays SPD and the pattern is A's (NUMERICS.md 3.6, "Matrix-free terms").
  bool extra_on_coarse_levels = true;
  /// Sparser coarse levels: an off-diagonal block A_IJ of a coarse (Galerkin) matrix whose
  /// scaled norm s_IJ = |L_I^-1 A_IJ L_J^-T|_F (A_II = L_I L_I^T) is below this is dropped,
  /// and each diagonal block is scaled by 1 + (the sum of its row's dropped s_IJ). The result
  /// is the Galerkin matrix plus a positive semidefinite term, so it stays SPD and so does the
  /// V-cycle (NUMERICS.md 3.6, "Why M is SPD"; measured in docs/plugins/solvers.md). Which
  /// blocks are dropped is decided on the first set-up of a pattern (later refreshes keep
  /// the pattern and recompute the values and the scaling). 0: off.
  double coarse_drop_tolerance = 0;
  /// The hierarchy's arrays of 2 MiB and more (level matrices and their float and half
  /// copies, column indices, diagonal inverses, work vectors) are 2 MiB-aligned and advised
  /// as transparent huge pages (madvise, Linux; huge_pages.hpp): the V-cycle streams them
  /// from memory at 256^2 and up, and with 4 KiB pages each 4 KiB costs a TLB miss. Values
  /// and results are the same either way (NUMERICS.md 3.6, "Huge pages").
  bool huge_pages = true;
};

/// Block-sparse matrix with BR x BC blocks (row-major, 9 or 18 or 36 doubles per block).
struct BlockMatrix {
  Index rows = 0, cols = 0;
  int br = 3, bc = 3;
  std::vector<Index> rp;
  HugeVector<Index> ci;  ///< (the large arrays: HugePageAllocator, SaAmgOptions::huge_pages)
  HugeVector<double> v;
  HugeVector<float> f;  ///< float copy of v read by the V-cycle (SaAmgOptions::float_storage)
  HugeVector<Half> h;   ///< half copy of v (level 0's P and R with SaAmgOptions::half_transfers)
  std::size_t bsize() const { return static_cast<std::size_t>(br) * bc; }
  Index nnz() const { return static_cast<Index>(ci.size()); }
  double* block(Index k) { return v.data() + bsize() * static_cast<std::size_t>(k); }
  const double* block(Index k) const { return v.data() + bsize() * static_cast<std::size_t>(k); }
};

/// Seconds spent in the preconditioner, cumulative since construction (steady clock; a few
/// clock reads per setup and per V-cycle). `apply_fine_*` split level 0's share of the
/// V-cycles: smoothing sweeps vs residual + restriction + prolongation; `apply_coarse` is
/// everything below level 0 (coarser smoothing and the coarsest solve).
struct SaAmgTimings {
  double setup = 0;            ///< setup(): level-0 copy, diagonal inverses, P, Galerkin, factor
  double setup_galerkin = 0;   ///< of which Galerkin products (A P, P^T A P)
  double setup_prolongator = 0;  ///< of which tentative + smoothed prolongators (when rebuilt)
  double apply = 0;            ///< apply(): whole V-cycles
  double apply_fine_smooth = 0;  ///< (with smoothing_sweeps 1 it includes the residual fused into the first sweep)
  double apply_fine_transfer = 0;
  double apply_coarse = 0;
  long setups = 0, applies = 0;
};

struct LevelInfo {
  Index rows = 0;     ///< block rows
  int block = 3;      ///< block size
  Index nnz_blocks = 0;
  int colours = 0;   ///< colours of the part-boundary rows
  int parts = 0;     ///< row blocks smoothed lexicographically in parallel
  Index p_nnz_blocks = 0;  ///< blocks of the prolongator to the next level (0 on the coarsest)
  Index boundary_rows = 0;  ///< rows coupled to another part (swept by colour)
  Index clean_rows = 0;     ///< interior rows with no boundary neighbour (one pass in the fused sweep)
};

class SaAmg {
 public:
  explicit SaAmg(SaAmgOptions o = {}) : o_(o) {}

  /// Build (first call, or after invalidate() / a new pattern) or refresh the hierarchy for
  /// A~ = S A S + (I - S). `x` holds the vertex positions (3n) for the rotation modes; when it
  /// is empty only the 3 translations are used. Returns false with `message` when a diagonal
  /// block or the coarsest matrix is not positive definite. `extra_diagonal` (9 per vertex,
  /// row-major, or empty): the diagonal blocks E_ii of a positive semidefinite term E that the
  /// outer iteration adds to A matrix-free; S_i E_ii S_i is added to level 0's diagonal blocks
  /// (and, with extra_on_coarse_levels, reaches the coarse levels through the Galerkin products).
  bool setup(const BsrMatrix& A, const Filter& S, std::span<const double> x, std::string& message,
             std::span<const double> extra_diagonal = {});
  void invalidate() { built_ = false; }
  /// Whether the last setup() succeeded for this pattern and this filter (A's values are the
  /// caller's to compare).
  bool set_up_for(const BsrMatrix& A, const Filter& S) const {
    return built_ && pattern_ == &A.pattern() && pattern_nnz_ == A.pattern().nnz_blocks() && !filter_changed(S);
  }
  /// Level 0's diagonal blocks only: S_i A_ii S_i (+ I - S_i) + S_i E_ii S_i again and their
  /// inverses; the off-diagonal blocks and the coarse levels stay those of the last setup().
  /// For a new E with the A and S of the last setup() (set_up_for, and the same values): the
  /// V-cycle stays symmetric positive definite whatever E the coarse levels were built with
  /// (NUMERICS.md 3.6, "Matrix-free terms").
  bool refresh_level0_diagonal(const BsrMatrix& A, const Filter& S, std::span<const double> extra_diagonal,
                               std::string& message);

  /// z = M r: one symmetric V-cycle on A~ (r and z have 3n entries and must not alias).
  void apply(const double* r, double* z);

  const std::vector<LevelInfo>& levels() const { return info_; }
  /// sum over levels of nnz scalars / nnz scalars of level 0.
  double operator_complexity() const;
  int refreshes() const { return refreshes_; }
  int prolongator_builds() const { return prolongator_builds_; }
  int hierarchy_builds() const { return hierarchy_builds_; }
  const SaAmgOptions& options() const { return o_; }
  const SaAmgTimings& timings() const { return t_; }
  /// Level l's matrix (level 0: A~) and its prolongator to level l + 1 (empty on the coarsest),
  /// in double, as built by the last setup(): for tests that recompute the Galerkin product.
  const BlockMatrix& level_matrix(std::size_t l) const { return L_[l].A; }
  const BlockMatrix& prolongator(std::size_t l) const { return L_[l].P; }
  const BlockMatrix& restriction(std::size_t l) const { return L_[l].R; }
  /// |P_h - P|_F / |P|_F of level 0's half prolongator against the double one (0 without halves).
  double half_transfer_error() const;

 private:
  struct Level {
    BlockMatrix A;                    // b x b blocks
    std::vector<Index> diag;          // position of (i, i)
    HugeVector<double> dinv;          // b*b per row: inverse of the diagonal block
    HugeVector<float> dinv_f;         // float storage: dinv symmetrised and rounded (the V-cycle's)
    std::vector<Index> colour_ptr, colour_rows;  // boundary rows (coupled to another part) by colour
    std::vector<Index> part_ptr, part_rows;      // interior rows of each part, increasing
    std::vector<std::uint8_t> clean;  // interior row with no boundary neighbour (fused residual)
    std::vector<Index> agg;           // aggregate of each row, -1 when in none
    std::vector<Index> member_ptr, members;  // rows of each aggregate
    std::vector<double> B;            // near-null space on this level: b x m per row
    std::vector<double> T;            // tentative prolongator: b x m per row (its one block)
    std::vector<std::uint8_t> dead;   // per scalar DOF of this level: a zero column of P above
    BlockMatrix P, R, AP;             // to/from the next level: P (b x m), R = P^T, A P
    std::vector<Index> r_from_p;      // block of P transposed into each block of R
    std::vector<Index> trans;         // position of the transposed block (j, i) of each block (i, j) of A
    HugeVector<double> x, b, r;       // work vectors
    HugeVector<double> ev;            // last power-iteration vector of D^-1 A (warm start)
    // coarse_drop_tolerance: G is the full Galerkin product, A its copy without the dropped
    // blocks (decided once per pattern) and with the diagonal blocks scaled.
    BlockMatrix G;
    std::vector<Index> g_diag, g_trans;   // diagonal / transposed block positions in G
    std::vector<Index> a_from_g;          // block of G copied into each block of A
    std::vector<Index> drop_g, drop_i;    // dropped blocks of G above the diagonal, their rows
    std::vector<Index> drop_ptr, drop_idx;  // per row of G: its dropped pairs (indices into drop_g)
    std::vector<double> drop_s, chol;     // s_IJ per dropped pair, Cholesky factors of G's diagonal
  };

  void build(const BsrMatrix& A, const Filter& S, std::span<const double> x);
  void fill_level0(const BsrMatrix& A, const Filter& S);
  void add_extra_diagonal(const Filter& S, std::span<const double> E);
  bool invert_diagonal(std::size_t l, std::string& message);
  void near_null_level0(const Filter& S, std::span<const double> x);
  void tentative(std::size_t l);
  double lambda_max(std::size_t l);
  void smooth_prolongator(std::size_t l);
  void galerkin(std::size_t l);
  void drop_weak(std::size_t l);
  bool factor_coarsest(std::string& message);
  void aggregate(std::size_t l);
  void colour(std::size_t l);
  void build_patterns(std::size_t l);
  template <class T, class D>
  void cycle(std::size_t l, const double* b, double* x);
  void sync_float(bool level0_only, bool transfers);
  bool filter_changed(const Filter& S) const;
  void remember_filter(const Filter& S);
  bool parallel(const Level& L) const { return static_cast<Index>(L.A.rows) * L.A.br >= o_.parallel_min_dofs; }

  SaAmgOptions o_;
  SaAmgTimings t_;
  bool built_ = false;
  const BsrPattern* pattern_ = nullptr;
  Index pattern_nnz_ = -1;
  int m_ = 6;  // near-null modes in use
  std::vector<Level> L_;
  std::vector<LevelInfo> info_;
  std::vector<double> centroid_;
  std::vector<std::vector<Index>> marker_;  // per thread, for the sparse products
  Eigen::MatrixXd coarse_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  bool coarse_direct_ = true;
  int refreshes_ = 0, prolongator_builds_ = 0, since_prolongator_ = 0, since_hierarchy_ = 0, hierarchy_builds_ = 0;
  std::vector<Index> s_constrained_;
  std::vector<double> s_proj_;
  bool had_coordinates_ = false;
};

}  // namespace loom::amg
