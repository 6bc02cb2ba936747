// Self-collision of the cloth: proximity repulsion with Coulomb friction, continuous collision
// detection (CCD) impulses and a fail-safe, after Bridson, Fedkiw & Anderson 2002.
//
// The framework calls begin_step() before an integrator step (it saves the start positions)
// and resolve() after it (after the colliders): resolve() changes the step's displacement
// d = x1 - x0 and the end velocity so that no vertex-triangle or edge-edge pair of
// non-adjacent elements (sharing no vertex) crosses during the step. It exists only when the
// scene declares `self_collision: {thickness: ..., friction: ...}`. docs/CONTACT.md says what
// it guarantees; docs/NUMERICS.md describes the algorithm.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/state.hpp"

namespace loom {

namespace selfcol {

/// Closest point of triangle (a, b, c) to p: returns the distance and the barycentric
/// weights w of the closest point (w[0] a + w[1] b + w[2] c).
double point_triangle_distance(const double* p, const double* a, const double* b, const double* c, double w[3]);
/// Closest points of segments (p0, p1) and (q0, q1): returns the distance; s, t in [0, 1]
/// are the parameters of the closest points p0 + s (p1 - p0), q0 + t (q1 - q0).
double segment_segment_distance(const double* p0, const double* p1, const double* q0, const double* q1, double& s,
                                double& t);

/// Cheap tests that the distance of two segments (p0, p1), (q0, q1), or of p to triangle
/// (a, b, c), is at least r, for rejecting a pair before its exact distance: a separating axis
/// along the direction between the elements' centres (on a unit vector u, a segment lies within
/// half its projected length of its midpoint, a triangle within its vertices' largest
/// projection from its centroid). True only when the distance is >= r; false says nothing.
/// Sheet neighbours (elements beside each other, the most common pairs a rebuild visits) get a
/// bound close to their distance; stacked layers do not (their exact distance decides).
bool segments_farther_than(const double* p0, const double* p1, const double* q0, const double* q1, double r);
bool point_triangle_farther_than(const double* p, const double* a, const double* b, const double* c, double r);
/// The same for two triangles (a0, a1, a2) and (b0, b1, b2), on the axis between their
/// centroids: true only when every point of one is at least r from every point of the other, so
/// every vertex-triangle and edge-edge pair of their elements is too. A rebuild rejects a whole
/// pair of overlapping leaf boxes with it before testing their element pairs (most such pairs are
/// sheet neighbours beside each other). Triangles that share a vertex are never rejected.
bool triangles_farther_than(const double* a0, const double* a1, const double* a2, const double* b0, const double* b1,
                            const double* b2, double r);
/// Whether two triangles, given by their three vertex indices, share a vertex (their element
/// pairs are the neighbour lists', not a traversal's).
inline bool triangles_share_vertex(const Index* a, const Index* b) {
  return a[0] == b[0] || a[0] == b[1] || a[0] == b[2] || a[1] == b[0] || a[1] == b[1] || a[1] == b[2] ||
         a[2] == b[0] || a[2] == b[1] || a[2] == b[2];
}

/// Continuous collision detection for linear motion x(t) = x0 + t (x1 - x0), t in [0, 1].
/// Vertex-triangle: points are {p, a, b, c}; edge-edge: {p0, p1, q0, q1}. A collision is the
/// earliest t in (0, 1] at which the four points are coplanar (a root of the cubic
/// coplanarity polynomial) and the element distance is <= tol. Returns false if none.
bool ccd_vertex_triangle(const double x0[4][3], const double x1[4][3], double tol, double& t);
bool ccd_edge_edge(const double x0[4][3], const double x1[4][3], double tol, double& t);

/// Real roots in [0, 1] of c0 + c1 t + c2 t^2 + c3 t^3 at which the sign changes, plus the
/// critical points in (0, 1) and t = 1 (where a double root / touching can hide); sorted.
/// Returns the number written to out (at most 7).
int cubic_candidate_times(double c0, double c1, double c2, double c3, double out[7]);

/// Axis-aligned bounding box hierarchy over the triangles of a mesh: built once (median
/// splits of the rest centroids), refit every time the boxes change.
class TriangleBvh {
 public:
  struct Node {
    double lo[3], hi[3];
    Index left = -1, right = -1;  ///< children (-1 for a leaf)
    Index tri = -1;               ///< triangle of a leaf
    Index first = 0, count = 0;   ///< the leaves below: leaf_nodes()[first, first + count)
  };
  /// Build the topology from triangle centroids (3 * num_triangles doubles).
  void build(const std::vector<double>& centroids);
  /// Refit: leaf boxes from tri_lo/tri_hi (3 per triangle) inflated by pad, inner nodes as unions.
  void refit(const double* tri_lo, const double* tri_hi, double pad);
  /// All pairs of distinct leaves whose boxes overlap, each once (a < b not implied).
  template <class F>
  void self_pairs(F&& emit, std::vector<std::array<Index, 2>>& stack) const;
  /// The part of self_pairs below one task: {a, a} the pairs inside node a, {a, b} the pairs
  /// between a and b. With skip_sharing (after set_vertices()), pairs of triangles that share a
  /// vertex are not emitted.
  template <class F>
  void pairs_from(std::array<Index, 2> task, F&& emit, std::vector<std::array<Index, 2>>& stack,
                  bool skip_sharing = false) const;
  /// The vertices of the triangles (3 per triangle), for pairs_from's skip_sharing.
  void set_vertices(const std::vector<Index>& tris);
  /// Independent tasks for a parallel traversal (at least `target` where the tree has them):
  /// self_pairs emits exactly the union of pairs_from over the tasks, each pair once.
  /// `tasks` is overwritten; it allocates only when it must grow.
  void split(std::size_t target, std::vector<std::array<Index, 2>>& tasks) const;
  /// Set one leaf's box (triangle tri, no padding) and refit its ancestors.
  void update_leaf(Index tri, const double* lo, const double* hi);
  /// Every leaf (triangle) whose box overlaps [lo, hi].
  template <class F>
  void query(const double* lo, const double* hi, F&& emit, std::vector<Index>& stack) const;
  const std::vector<Node>& nodes() const { return nodes_; }
  /// The triangle of the k-th leaf in depth-first order (leaves close in the tree are close here).
  Index leaf_triangle(Index k) const { return nodes_[leaf_nodes_[k]].tri; }
  /// Subtrees of at most this many leaves are paired leaf by leaf in one loop rather than by
  /// descending node pairs (fewer stack operations; the leaves of a subtree are contiguous).
  static constexpr Index kSmallSubtree = 4;

 private:
  /// A leaf's box, triangle and vertices, in depth-first order (the leaves of a subtree are
  /// contiguous: the small-subtree loops read them in order; one cache line each).
  struct Leaf {
    double lo[3], hi[3];
    Index tri = -1;
    Index v[3] = {-1, -1, -1};
  };
  std::vector<Node> nodes_;
  std::vector<Leaf> leaves_;       ///< in the order of leaf_nodes_, refit with the nodes
  bool have_vertices_ = false;     ///< set_vertices() was called
  std::vector<Index> leaf_nodes_;  ///< leaf node indices in depth-first order (Node::first indexes it)
  std::vector<Index> parent_;  ///< per node (-1 for the root)
  std::vector<Index> leaf_;    ///< per triangle: its leaf node
};

template <class F>
void TriangleBvh::query(const double* lo, const double* hi, F&& emit, std::vector<Index>& stack) const {
  if (nodes_.empty()) return;
  stack.clear();
  stack.push_back(0);
  while (!stack.empty()) {
    const Node& n = nodes_[stack.back()];
    stack.pop_back();
    if (n.lo[0] > hi[0] || lo[0] > n.hi[0] || n.lo[1] > hi[1] || lo[1] > n.hi[1] || n.lo[2] > hi[2] || lo[2] > n.hi[2])
      continue;
    if (n.tri >= 0) {
      emit(n.tri);
    } else {
      stack.push_back(n.left);
      stack.push_back(n.right);
    }
  }
}

template <class F>
void TriangleBvh::self_pairs(F&& emit, std::vector<std::array<Index, 2>>& stack) const {
  if (nodes_.empty()) return;
  pairs_from({0, 0}, emit, stack);
}

template <class F>
void TriangleBvh::pairs_from(std::array<Index, 2> task, F&& emit, std::vector<std::array<Index, 2>>& stack,
                             bool skip_sharing) const {
  auto overlap = [](const auto& a, const auto& b) {
    return a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
           a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
  };
  skip_sharing = skip_sharing && have_vertices_;
  auto share = [](const Leaf& a, const Leaf& b) { return triangles_share_vertex(a.v, b.v); };
  auto extent = [](const Node& a) { return (a.hi[0] - a.lo[0]) + (a.hi[1] - a.lo[1]) + (a.hi[2] - a.lo[2]); };
  stack.clear();
  stack.push_back(task);  // {a, a}: the pairs inside node a; {a, b}: pairs between a and b
  while (!stack.empty()) {
    const auto [a, b] = stack.back();
    stack.pop_back();
    const Node& A = nodes_[a];
    if (a == b) {
      if (A.tri >= 0) continue;
      if (A.count <= kSmallSubtree) {
        // Inside a small subtree: every overlapping pair of its leaves, in the order the descent would find them.
        for (Index i = A.first; i < A.first + A.count; ++i) {
          const Leaf& LA = leaves_[i];
          for (Index j = i + 1; j < A.first + A.count; ++j) {
            const Leaf& LB = leaves_[j];
            if (skip_sharing && share(LA, LB)) continue;
            if (overlap(LA, LB)) emit(LA.tri, LB.tri);
          }
        }
        continue;
      }
      stack.push_back({A.left, A.left});
      stack.push_back({A.right, A.right});
      stack.push_back({A.left, A.right});
      continue;
    }
    const Node& B = nodes_[b];
    if (!overlap(A, B)) continue;
    if (A.tri >= 0 && B.tri >= 0) {
      if (!(skip_sharing && share(leaves_[A.first], leaves_[B.first]))) emit(A.tri, B.tri);
    } else if (A.count <= kSmallSubtree && B.count <= kSmallSubtree) {
      // Two small subtrees: every overlapping pair of their leaves (the same pairs the descent finds).
      for (Index i = A.first; i < A.first + A.count; ++i) {
        const Leaf& LA = leaves_[i];
        for (Index j = B.first; j < B.first + B.count; ++j) {
          const Leaf& LB = leaves_[j];
          if (skip_sharing && share(LA, LB)) continue;
          if (overlap(LA, LB)) emit(LA.tri, LB.tri);
        }
      }
    } else if (B.tri >= 0 || (A.tri < 0 && extent(A) >= extent(B))) {
      stack.push_back({A.left, b});
      stack.push_back({A.right, b});
    } else {
      stack.push_back({a, B.left});
      stack.push_back({a, B.right});
    }
  }
}

}  // namespace selfcol

/// Counters of the last resolve() call (and the seconds it spent in each phase).
struct SelfCollisionStats {
  bool rebuilt = false;          ///< the candidate lists were rebuilt or refreshed this step
  int rebuilds = 0;              ///< full rebuilds (refit + traversal of the whole cloth)
  Index refreshed = 0;           ///< vertices whose pairs alone were re-examined (incremental refresh)
  Index candidates_vt = 0, candidates_ee = 0;
  Index proximity = 0;           ///< repulsion / friction impulses
  Index ccd_collisions = 0;      ///< CCD impulses, all iterations
  int ccd_iterations = 0;        ///< CCD passes over the candidates
  Index frozen = 0;              ///< vertices the fail-safe returned to their start position
  Index near = 0;                ///< pairs of the lists that could come within the thickness this step
  Index exact_tests = 0;         ///< exact distances computed by rebuilds and refreshes (work counter)
  Index ccd_tests = 0;           ///< pairs whose CCD cubic was solved, all passes (work counter)
  double broad_seconds = 0, narrow_seconds = 0, response_seconds = 0;
};

/// What self-collision did and cost since it was built (SelfCollision::totals()): the sums of
/// SelfCollisionStats over the resolve() calls, plus the time of the whole calls and of the
/// integrators' searches through proximity_pairs() (baraff_witkin's self-contacts). The run's
/// stats.csv columns and `loom run`'s summary line come from it (docs/OUTPUT.md).
struct SelfCollisionTotals {
  long long steps = 0;            ///< resolve() calls
  double resolve_seconds = 0;     ///< wall time in resolve() (the after-step pass), all of it
  double broad_seconds = 0, narrow_seconds = 0, response_seconds = 0;  ///< its phases
  double search_seconds = 0;      ///< wall time in proximity_pairs(x, d, out) (an integrator's self-contacts)
  double search_broad_seconds = 0;  ///< of search_seconds: renewing the lists (rebuilds, refreshes); the rest is the pairs' filter and distances
  long long proximity = 0;        ///< repulsion / friction impulses
  long long ccd_collisions = 0;   ///< CCD impulses
  long long frozen = 0;           ///< vertices the fail-safe returned to their start of step
  long long rebuilds = 0;         ///< full rebuilds of the candidate lists
  long long refreshed = 0;        ///< vertices whose pairs alone were re-examined
  double seconds() const { return resolve_seconds + search_seconds; }
  long long impulses() const { return proximity + ccd_collisions; }
};

/// A vertex-triangle or edge-edge pair of non-adjacent elements near each other (see
/// SelfCollision::proximity_pairs). sum_i w[i] x[v[i]] is the vector from the closest point of
/// the triangle to the vertex (from the first edge's closest point to the second's); normal
/// is its direction and distance its length, at the positions of the query.
struct ProximityPair {
  bool vt = true;       ///< vertex-triangle (v = vertex, triangle's 3) or edge-edge (v = edge's 2, edge's 2)
  Index v[4] = {0, 0, 0, 0};
  double w[4] = {0, 0, 0, 0};
  double normal[3] = {0, 0, 0};
  double distance = 0;
};

class ColliderSet;

class SelfCollision {
 public:
  struct Options {
    double thickness = 0;   ///< m: pairs closer than this are pushed apart
    double friction = 0;    ///< Coulomb coefficient between cloth layers
    // Not scene keys: the tests switch stages off to exercise the fail-safe alone.
    int ccd_iterations = 16;  ///< CCD impulse passes before the fail-safe
    bool repulsion = true;    ///< proximity repulsion and friction
    /// When at most this fraction of the vertices has left its reach, only their pairs are
    /// re-examined (refresh); beyond it the lists are rebuilt (tests set 1 or 0 to force either).
    double refresh_fraction = 1.0 / 256;
  };
  /// Parse the scene's `self_collision` mapping (nullptr when absent). Checks the keys, and
  /// that the thickness is below the smallest distance between non-adjacent elements of the
  /// cloth as built (x), since otherwise neighbours in the sheet would repel each other.
  static std::unique_ptr<SelfCollision> parse(const Params& p, const Mesh& mesh, const std::vector<double>& x);
  SelfCollision(const Options& o, const Mesh& mesh);
  /// A state set from outside the scene file (`loom run --resume`'s restart.bin, named by
  /// `where`) gets parse()'s crossing check: throws one InputError naming `where`, the number
  /// of intersecting non-adjacent triangle pairs at x (the exact check of `loom check`), one
  /// pair and the fix when there is one. Layers closer than the thickness are accepted here
  /// (the response pushes them apart; a run with self-collision may stop with such a pair).
  /// program: the state was set by a program through Scene::state (Simulation::step's first
  /// step); the message and its fix say so instead of naming a file.
  static void refuse_crossing_state(const Mesh& mesh, const std::vector<double>& x, const std::string& where,
                                    bool program = false);

  const Options& options() const { return opt_; }
  /// Save the start-of-step positions.
  void begin_step(const State& s);
  /// After a step of size h: s.x and s.v are the integrator's end of step; modify them.
  /// With `colliders`, a vertex the response moved into a collider is put back onto its
  /// surface (inward velocity removed) before the fail-safe checks the step, so the result is
  /// both free of self-intersections and outside the colliders whenever the step's start was.
  void resolve(State& s, double h, const ColliderSet* colliders = nullptr);
  const SelfCollisionStats& last_stats() const { return stats_; }
  /// The sums since construction (stats.csv's self_collision columns, the run's summary).
  const SelfCollisionTotals& totals() const { return totals_; }

  /// The pairs that can end a step within the thickness: every non-adjacent vertex-triangle
  /// and edge-edge pair whose distance at positions x (3 per vertex), less the largest relative
  /// displacement max |d_a - d_b| of a vertex a of one element and b of the other in d (a
  /// predicted step x -> x + d), is below the thickness (this bounds both the distance at
  /// x + d and the gap linearised along the pair's normal from below). Reuses the broad phase's candidates when they still cover x and x + d (else
  /// refits and traverses, leaving candidates that resolve() reuses). out is cleared first.
  /// For integrators that enter self-contacts into their step (baraff_witkin).
  void proximity_pairs(const double* x, const double* d, std::vector<ProximityPair>& out);

  /// Smallest distance between non-adjacent vertex-triangle and edge-edge pairs at positions
  /// x, among pairs closer than `within` (returns `within` if none): for tests and the check above.
  double min_distance(const std::vector<double>& x, double within);
  /// The candidate pairs of the broad phase for displacement zero at positions x with the
  /// given inflation, as sorted lists (for tests against brute force).
  void candidate_pairs(const std::vector<double>& x, double inflate, std::vector<std::array<Index, 2>>& vt,
                       std::vector<std::array<Index, 2>>& ee);

  /// The candidate lists of the last resolve() (sorted), for tests: they hold every pair that
  /// could come within the thickness during that step.
  void candidate_lists(std::vector<std::array<Index, 2>>& vt, std::vector<std::array<Index, 2>>& ee) const;
  /// The lists' reference positions (3 per vertex) and reaches, for tests: the lists hold
  /// exactly the non-adjacent pairs whose distance at the reference positions is below
  /// thickness + the largest reach among each element's vertices.
  void list_reference(std::vector<double>& x, std::vector<double>& reach) const {
    x = ref_x_;
    reach = reach_;
  }

  /// A pair of non-adjacent elements and its distance: vertex-triangle (a = vertex, b =
  /// triangle) or edge-edge (a < b, indices into Mesh::edges()).
  struct Proximity {
    Index a, b;
    double distance;
  };
  /// Every non-adjacent vertex-triangle and edge-edge pair closer than `within` at positions x
  /// (3 per vertex), sorted by (a, b), through the same broad phase. The step's candidate lists
  /// are reused as work space: the next resolve() rebuilds them.
  void proximity_pairs(const double* x, double within, std::vector<Proximity>& vt, std::vector<Proximity>& ee);

 private:
  // resolve() and proximity_pairs(x, d, out) without the totals' bookkeeping.
  void resolve_step(State& s, double h, const ColliderSet* colliders);
  void find_pairs(const double* x, const double* d, std::vector<ProximityPair>& out);
  struct Pair {
    Index a, b;         ///< vertex, triangle  or  edge, edge
    double dist_ref;    ///< distance at the broad phase's start positions
  };
  // The candidate lists at positions x0: every pair whose boxes (vertex i: x0_i +- (reach_i +
  // gap / 2); triangles, edges: their vertices' box grown by the largest reach_ among them +
  // gap / 2) overlap; with `exact`, only those closer than gap + the two elements' reaches.
  void broad_phase(const double* x0, double gap, bool exact);
  // The traversal of broad_phase (boxes and hierarchy ready, at ref_x_): appends the pairs to
  // vt_, ee_. With `refreshed`, only the pairs that refresh() dropped (a refreshed vertex,
  // triangle or edge), through one hierarchy query per group of refreshed triangles.
  void traverse(double gap, bool exact, bool refreshed);
  // The step's lists: reach_ from this step's displacements (step_len_), then broad_phase.
  void rebuild(const double* x0);
  // Keep the lists complete for this step: nothing when every vertex is within its reach;
  // when a few are not, refresh() only their pairs; when many are not, rebuild().
  void update_candidates(const double* x0);
  // Give the vertices in refresh_v_ new reference positions (x0) and reaches, and re-examine
  // every pair that involves one of them.
  void refresh(const double* x0);
  double reach_for(Index i) const;
  // Triangle t's box (tlo_, thi_: its vertices' reference box grown by their largest reach +
  // gap / 2) and its record trec_[t] for the traversal.
  void triangle_box(Index t, double gap);
  // Whether every vertex stays within its reach of the positions of the last rebuild
  // (moved_ + step_len_ <= reach_): then no pair outside the lists comes within the thickness.
  bool candidates_valid() const;
  // The 4 vertex indices of a pair (vertex, triangle's 3) or (edge's 2, edge's 2).
  void pair_vertices(bool vt, const Pair& p, Index idx[4]) const;
  double pair_distance(bool vt, const Index idx[4], const double* x, double w[4], double n[3]) const;
  bool pair_ccd(bool vt, const Index idx[4], double tol, double& t) const;
  // Apply: separation push dpos (>= 0, displacement units) along n with weights w; velocity:
  // remove approach along n, Coulomb friction on the tangential part. Returns true if changed.
  bool respond(const Index idx[4], const double w[4], const double n[3], double dpos, double h, State& s);
  // changed_only: only pairs with a vertex put back or frozen; then, while the near list still
  // covers the changed d (d_ref, change: see the definition), only the near pairs.
  Index freeze_pass(State& s, bool changed_only, const double* d_ref, double change);
  /// Puts the touched vertices that ended inside a collider back onto its surface (at the
  /// step's end time s.time); true when one was moved.
  bool keep_outside(State& s, double h, const ColliderSet& colliders);

  Options opt_;
  double margin_ = 0;
  Index nv_ = 0, nt_ = 0;
  std::vector<Index> tris_;                      ///< 3 per triangle
  std::vector<std::array<Index, 2>> edges_;
  std::vector<std::array<Index, 3>> own_verts_;  ///< vertices owned by each triangle (-1 = none)
  std::vector<std::array<Index, 3>> own_edges_;  ///< edges owned by each triangle (-1 = none)
  std::vector<Index> tri_edges_;                 ///< the 3 edges of each triangle (k: vertices k, k+1)
  selfcol::TriangleBvh bvh_;

  // Work arrays, sized in the constructor.
  std::vector<double> x0_, d_, inv_mass_;
  std::vector<Index> touched_;            ///< vertices the response moved in this resolve()
  std::vector<std::uint8_t> touched_flag_;
  std::vector<double> tlo_, thi_;                ///< boxes of the triangles (refit into the hierarchy)
  /// What a leaf pair of the traversal reads of a triangle, in one place (a leaf pair then
  /// touches two records instead of a dozen arrays): its vertices' reference positions and
  /// reaches, its box, its edges' reaches, and which of its vertices and edges it owns.
  struct TriRecord {
    double x[9];          ///< reference positions of vertices 0, 1, 2
    double lo[3], hi[3];  ///< = tlo_, thi_
    double r[3];          ///< reach_ of each vertex
    double er[3];         ///< edge k (vertices k, k + 1): the larger reach of its two vertices
    double tr;            ///< the largest reach of the three
    Index v[3], e[3];     ///< vertex indices; edge k's index into edges_
    std::uint32_t own;    ///< bit k: owns vertex k; bit 3 + k: owns edge k
  };
  std::vector<TriRecord> trec_;                  ///< in the hierarchy's leaf order (slot), not by triangle index:
                                                 ///< the traversal meets the records of nearby leaves together
  std::vector<Index> tri_slot_, slot_tri_;       ///< triangle -> its record's slot, and back
  /// The element pairs that a rebuild's traversal would test in leaf pairs of triangles sharing
  /// a vertex (fixed by the mesh: every non-adjacent vertex-triangle pair whose vertex's owner
  /// shares a vertex with the triangle, and edge-edge pair (e < f) whose owners share one). A full
  /// rebuild skips such leaf pairs in the traversal and tests these lists instead, in a plain
  /// loop over kNeighbourChunks fixed chunks (same pairs; half a rebuild's leaf pairs at 128^2).
  std::vector<std::array<Index, 2>> nb_vt_, nb_ee_;
  static constexpr std::size_t kNeighbourChunks = 16;
  /// The neighbour-list pairs by vertex and by triangle (nb_vt_) and by either edge (nb_ee_),
  /// as CSR offsets and pair indices, and the pairs of them that the current refresh re-tests.
  std::vector<Index> nbv_off_, nbv_idx_, nbt_off_, nbt_idx_, nbe_off_, nbe_idx_;
  std::vector<Index> refresh_nbvt_, refresh_nbee_;
  std::vector<double> ref_x_;                    ///< reference positions of the lists (in their frame, below)
  /// The lists' frame. Distances between elements do not change under a rigid motion, so the
  /// lists' bounds measure each vertex's motion after one is taken off. Since the reference:
  /// u = x0 - F(ref_x), F(X) = R X + T a rotation and translation (frame_R_, frame_T_; the
  /// identity when the lists are rebuilt); in the step: e = d - f(x0), f(y) = spin_ x (y -
  /// centre_) + drift_ the frame's own motion over the step. The map y -> y + s f(y) never
  /// shortens a distance (its linear part I + s [spin_]x has singular values >= 1) and
  /// stretches u by at most kappa = sqrt(1 + |spin_|^2), so a vertex stays within kappa |u| +
  /// |e| of its reference point's image: moved_ = kappa |u|, step_len_ = |e|. Any rigid F and
  /// any f keep every bound valid; these follow the cloth's mean motion and mean rotation
  /// (fitted at the end of each resolve(), docs/NUMERICS.md), so a sheet falling, sliding or
  /// turning as a whole does not renew its lists, nor widen its reaches, for that motion.
  double frame_R_[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, frame_T_[3] = {0, 0, 0};
  double spin_[3] = {0, 0, 0}, centre_[3] = {0, 0, 0}, drift_[3] = {0, 0, 0};
  bool frame_reset_ = false;                     ///< the lists were rebuilt in this resolve()
  static constexpr int kFrameChunks = 64;        ///< fixed chunks of the frame's sums (order fixed)
  static constexpr int kFrameSums = 21;          ///< per chunk: see resolve_step()
  /// |d - f(y)|: vertex motion d over the step from start position y, the frame's taken off.
  double frame_step(const double* y, const double* d) const {
    const double r[3] = {y[0] - centre_[0], y[1] - centre_[1], y[2] - centre_[2]};
    const double e[3] = {d[0] - drift_[0] - (spin_[1] * r[2] - spin_[2] * r[1]),
                         d[1] - drift_[1] - (spin_[2] * r[0] - spin_[0] * r[2]),
                         d[2] - drift_[2] - (spin_[0] * r[1] - spin_[1] * r[0])};
    return std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
  }
  /// u = y - F(X), X = ref_x_ of vertex i: its motion since the reference, the frame's taken off.
  void frame_residual(Index i, const double* y, double u[3]) const {
    const double* X = &ref_x_[3 * static_cast<std::size_t>(i)];
    for (int k = 0; k < 3; ++k)
      u[k] = y[k] - (frame_R_[3 * k] * X[0] + frame_R_[3 * k + 1] * X[1] + frame_R_[3 * k + 2] * X[2] + frame_T_[k]);
  }
  /// kappa |y - F(X)| (see above), kappa = frame_stretch().
  double frame_moved(Index i, const double* y, double kappa) const {
    double u[3];
    frame_residual(i, y, u);
    return kappa * std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
  }
  double frame_stretch() const { return std::sqrt(1 + spin_[0] * spin_[0] + spin_[1] * spin_[1] + spin_[2] * spin_[2]); }
  /// The frame's reference point of start position y (F^-1(y)), for a refreshed vertex.
  void frame_reference(const double* y, double* X) const;
  /// The next step's frame from this step's sums (kFrameSums per chunk, see resolve_step()).
  void advance_frame(const double (*part)[kFrameSums], Index n);
  std::vector<double> moved_;                    ///< per vertex kappa |x0 - F(ref_x)| this step
  std::vector<double> step_len_;                 ///< per vertex |d - f(x0)| this step
  std::vector<Pair> vt_, ee_;
  std::vector<std::uint8_t> near_flag_;          ///< per pair (VT then EE): could be within the thickness this step
  std::vector<Index> near_;                      ///< those pairs (index into VT then EE)
  std::vector<double> near_dist_;                ///< per near pair: its distance at the step's start (-1: not computed)
  std::vector<std::uint32_t> near_clean_;        ///< per near pair: found clean by a CCD pass at ccd_clock_ < this
  std::vector<std::uint32_t> vstamp_;            ///< per vertex: ccd_clock_ after the last CCD impulse that moved it
  std::uint32_t ccd_clock_ = 0;                  ///< CCD impulses so far in this resolve()
  std::vector<double> d_near_;                   ///< d when the near list was renewed during the CCD passes
  std::vector<double> len0_;                     ///< per vertex |d| before any response this step
  double max_growth_ = 0;                        ///< largest |d| - len0 after responses
  bool responded_ = false;                       ///< d or v changed this step
  std::vector<std::array<Index, 2>> stack_;
  std::vector<double> reach_;                    ///< per vertex: motion allowed before the lists are rebuilt
  std::vector<std::array<Index, 2>> tasks_;      ///< parallel traversal tasks (TriangleBvh::split)
  std::vector<std::vector<Pair>> task_vt_, task_ee_;  ///< per-task pairs found by the traversal
  std::vector<std::vector<std::array<Index, 2>>> tstack_;  ///< per-thread traversal stacks
  std::vector<Index> vt_off_, vt_adj_, ve_off_, ve_adj_;   ///< vertex -> incident triangles / edges (CSR)
  std::vector<Index> refresh_v_, refresh_t_, refresh_e_;   ///< refresh(): the vertices and their elements
  /// refresh(): refresh_t_ in groups, one per refreshed vertex that added triangles to it (its
  /// star's triangles not in an earlier group): group g is refresh_t_[refresh_group_[g],
  /// refresh_group_[g + 1]). The traversal queries the hierarchy once per group.
  std::vector<Index> refresh_group_;
  std::vector<std::vector<Index>> qstacks_;                ///< per-thread TriangleBvh::query stacks
  std::vector<std::uint8_t> vflag_, tflag_, eflag_;        ///< refresh(): membership of those lists
  std::vector<std::uint8_t> frozen_;
  bool have_candidates_ = false;
  /// Set by proximity_pairs (an integrator with large steps, baraff_witkin): a vertex's reach
  /// grows by one step's displacement instead of two (see reach_for in self_collision.cpp).
  bool large_steps_ = false;
  SelfCollisionStats stats_;
  SelfCollisionTotals totals_;
};

inline void SelfCollision::pair_vertices(bool vt, const Pair& p, Index idx[4]) const {
  if (vt) {
    idx[0] = p.a;
    idx[1] = tris_[3 * p.b];
    idx[2] = tris_[3 * p.b + 1];
    idx[3] = tris_[3 * p.b + 2];
  } else {
    idx[0] = edges_[p.a][0];
    idx[1] = edges_[p.a][1];
    idx[2] = edges_[p.b][0];
    idx[3] = edges_[p.b][1];
  }
}

}  // namespace loom
