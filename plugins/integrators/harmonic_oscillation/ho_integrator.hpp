// harmonic_oscillation: Kang & Cho 2011 per-spring harmonic-oscillation integration, corrected
// (docs/NUMERICS.md section 1; per-spring math in loom/kernels/ho.hpp).
//
// Variants:
//   velocity          exact per-spring velocity change (inverse-mass shares), then x += h v_new
//   analytic_position also the exact per-spring position increment (HO-A), x += h (v_old + h g/2) + dx
//   kang_cho_2011     the published formula (eqs. 7-12, sign of eq. 12 fixed); converges to k/2
// Springs are superposed Jacobi-style (every spring sees the state at the start of the step).
#pragma once

#include <array>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "loom/integrator.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/spring_layout.hpp"
#include "loom/springs.hpp"
#include "loom/traversal.hpp"
#include "loom/vertex_order.hpp"
#include "ho_window.hpp"

#ifdef _OPENMP
#include <omp.h>
#else
inline int omp_get_max_threads() { return 1; }
#endif

namespace loom {

enum class HoVariant { Velocity, AnalyticPosition, KangCho2011 };
HoVariant parse_ho_variant(const std::string& s);
const char* to_string(HoVariant v);
/// The keys of harmonic_oscillation (cpu and cuda): variant, storage (cpu); precision and
/// host_sync_every (cuda).
const ParamSpec& harmonic_oscillation_spec();
/// Reads `variant` through harmonic_oscillation_spec() (the cpu and cuda variants share it).
HoVariant read_ho_variant(const Params& p);
/// Help of harmonic_oscillation's key `merge_springs`.
inline constexpr const char* kHoMergeSpringsHelp =
    "merge springs on the same two vertices into one before stepping: the impulse is linear in the stretch and "
    "the axial velocity, so the merged spring takes the sum of its members' HO constants (rest length their "
    "kx-weighted mean; analytic_position merges only equal rest lengths): the same step in exact arithmetic, "
    "fewer springs per step (the kang_cho_table1 stencil doubles almost every spring). false: every spring on "
    "its own (the results before 2026-12-01, bit for bit)";

/// A run of springs and a block of the grouped sweep (loom/spring_groups.hpp).
using HoSegment = SpringSegment;
using HoBlock = SpringBlock;

/// Springs in traversal order with i < j and their per-step constants. T = double in the
/// plugin; the benchmark also builds a float copy.
template <class T>
struct HoSprings {
  std::vector<Index> i, j;
  std::vector<T> l0, k, c;        ///< rest length, stiffness, axial damper (from the material)
  std::vector<T> kx, kv;          ///< velocity constants (kang_cho_2011: kx, ka)
  std::vector<T> ex, ev;          ///< position constants (analytic_position only)
  // Table storage: when the springs have few distinct (l0, k, c, w_i + w_j), each spring stores
  // a 16-bit id into small tables instead of its own l0 and constants (10 instead of 32 bytes
  // per spring in double); the per-spring kx, kv, ex, ev are then empty. Not used on the
  // windowed grouped sweep unless asked for (ho_tables_wanted): it streams per-spring constants.
  bool table = false;
  std::vector<std::uint16_t> id;
  std::vector<T> t_l0, t_kx, t_kv, t_ex, t_ev;
  // traversal structure (built with the layout; the same for every scalar type)
  std::vector<std::uint8_t> is_deferred;   ///< per vertex: touched by a cross spring
  std::vector<Index> deferred;             ///< those vertices
  // Grouped traversal: each part's vertex range is cut into blocks of kHoVertexBlock vertices;
  // the springs whose lower endpoint lies in a block are ordered by (offset j - i, i) and cut
  // into segments of consecutive i with equal offset, so that a segment reads x, v, w
  // contiguously (no gathers). Used when segments average at least 4 springs.
  using Segment = HoSegment;
  using Block = HoBlock;
  bool grouped = false;
  std::vector<Segment> segs;
  std::vector<Block> blocks;
  std::vector<Index> part_block;           ///< blocks of part p: [part_block[p], part_block[p + 1])
  // Window of the grouped sweep (ho_window.hpp): per block, 1 + the largest vertex it reads; the
  // window capacity in vertices (0: off, the plain grouped sweep runs); the scratch, parts x
  // kHoWinArrays x win_cap (written by the step: each part uses only its own slice).
  std::vector<Index> block_need;
  Index win_span = 0;             ///< the most vertices live at once (plan_ho_window)
  Index win_cap = 0;
  mutable std::vector<T> win;
  /// Windowed sweep: impulses and scatter in one pass for unit-stride segments whose lower and
  /// upper ranges are disjoint (ho_window_impulses_scatter), and one scatter pass for those whose
  /// ranges overlap (window_segment_scatter_overlap); the same bits. false: impulses, then two
  /// scatter passes for every segment (table1's HoStep_double_unfused row).
  bool fuse = true;
  /// Windowed sweep: a twin pair of segments (SpringSegment::twin: duplicate springs on the same
  /// endpoints, 88% of the Table 1 cloth's springs) computes its shared geometry once
  /// (ho_window_impulses_twin); the same bits. false: each segment on its own (table1's
  /// HoStep_double_notwin row).
  bool twins = true;
  // Merged duplicates (build_ho_springs' HoMerge, key `merge_springs`): springs on the same two
  // vertices folded into one. HO's impulse is linear in the stretch and the axial velocity with
  // constants that depend only on k, c, W and h (loom/kernels/ho.hpp), so a group's impulse is one
  // spring's with the members' constants added (and, for unequal rest lengths, l0 the kx-weighted
  // mean); the constants are those sums, recomputed from the members at every prepare. Spring q
  // stands for merged group g = merge_group[q] when g >= 0: its members' rest lengths,
  // stiffnesses and dampers are merge_l0/k/c[merge_first[g] .. merge_first[g + 1]), and l0[q],
  // k[q], c[q] hold the group's l0 (set by update_ho_coefficients), sum of k and sum of c. All
  // empty when nothing was merged.
  std::vector<Index> merge_group;
  std::vector<Index> merge_first;
  std::vector<double> merge_l0, merge_k, merge_c;
  Index merged = 0;   ///< springs folded away (the members beyond each group's first)

  Index size() const { return static_cast<Index>(i.size()); }
  /// Whether spring q stands for a merged group.
  bool is_merged(Index q) const { return !merge_group.empty() && merge_group[q] >= 0; }
};

/// The most vertices per block of the grouped traversal (the per-segment buffers' capacity).
constexpr Index kHoVertexBlock = kSpringGroupBlockMax;
/// Vertices per block of HO's grouped traversal (build_ho_springs' default; see kSpringGroupBlock
/// for what the size changes; table1's HoStep_double_block64/128/256 rows compare sizes).
constexpr Index kHoGroupBlock = kSpringGroupBlock;

/// Which springs on the same two vertices build_ho_springs merges into one (HoSprings::merge_group):
/// none; only groups whose rest lengths are equal (what analytic_position can merge: its
/// displacement constants would need a second weighted rest length otherwise); every group.
enum class HoMerge { None, EqualRestLength, All };

/// The merge mode of a variant when merging is asked for (key `merge_springs`).
inline HoMerge ho_merge_mode(HoVariant v, bool merge) {
  if (!merge) return HoMerge::None;
  return v == HoVariant::AnalyticPosition ? HoMerge::EqualRestLength : HoMerge::All;
}

/// Build the traversal layout and the spring arrays from a spring set over n vertices: springs
/// in traversal order with i < j (HO is symmetric in its endpoints), sorted by i within each
/// part, and the vertices that cross springs touch.
/// allow_grouping = false keeps the plain blocked sweep (tests compare the two).
/// group_block: vertices per block of the grouped sweep (group_springs; benchmarks compare sizes).
/// merge: which duplicate springs become one (HoMerge; the plugin's default is ho_merge_mode(v, true)).
void build_ho_springs(Index n, const SpringSet& set, SpringLayout& layout, HoSprings<double>& out,
                      bool allow_grouping = true, Index group_block = kHoGroupBlock, HoMerge merge = HoMerge::None);

/// Copy the structure (endpoints, traversal data) and the material constants to another scalar.
template <class T, class U>
void convert_ho_springs(const HoSprings<U>& in, HoSprings<T>& out) {
  out.i = in.i;
  out.j = in.j;
  out.is_deferred = in.is_deferred;
  out.deferred = in.deferred;
  out.grouped = in.grouped;
  out.segs = in.segs;
  out.blocks = in.blocks;
  out.part_block = in.part_block;
  out.block_need = in.block_need;
  out.win_span = in.win_span;
  out.win_cap = in.win_cap;
  out.win.assign(in.win.size(), T(0));
  out.fuse = in.fuse;
  out.twins = in.twins;
  out.merge_group = in.merge_group;
  out.merge_first = in.merge_first;
  out.merge_l0 = in.merge_l0;
  out.merge_k = in.merge_k;
  out.merge_c = in.merge_c;
  out.merged = in.merged;
  out.l0.assign(in.l0.begin(), in.l0.end());
  out.k.assign(in.k.begin(), in.k.end());
  out.c.assign(in.c.begin(), in.c.end());
  out.table = false;
}

/// Vertex order of the step (key `reorder`; the rule is loom/vertex_order.hpp's).
using HoReorder = ReorderMode;
constexpr Index kHoReorderMinVertices = kReorderMinVertices;
inline bool ho_reorder_pays(Index n, double span_user, double span_rcm) { return reorder_pays(n, span_user, span_rcm); }

/// Below this many springs a step runs on the calling thread.
constexpr Index kHoSerialSprings = kParallelMinSprings;  // the rule in common.hpp

/// Largest number of distinct spring parameter sets stored as a table (16-bit ids).
constexpr std::size_t kHoMaxTable = 65536;

/// Constants of one parameter set (k, c, W = w_i + w_j) in double: kx, kv, ex, ev.
inline std::array<double, 4> ho_constants(HoVariant variant, double k, double c, double W, double h) {
  if (variant == HoVariant::KangCho2011) {
    const auto r = kernels::kang_cho_coefficients<double>(k, W, 0.0, h);
    return {r.kx, r.ka, 0.0, 0.0};
  }
  const auto r = kernels::ho_coefficients<double>(k, c, W, 0.0, h);
  return {r.kx, r.kv, r.ex, r.ev};
}

/// Whether update_ho_coefficients may store tables (HoSprings::table) for springs s.
/// allow_table = false: never (storage: direct). Otherwise tables are used when there are at most
/// kHoMaxTable distinct (l0, k, c, W), except on the windowed grouped sweep (s.grouped and
/// s.win_cap > 0), which streams per-spring constants (contiguous loads; a table lookup per
/// spring is a gather, which costs more there than the 22 bytes per spring it saves:
/// docs/plugins/integrators.md), unless tables_on_window (tests and benchmarks).
template <class T>
bool ho_tables_wanted(const HoSprings<T>& s, bool allow_table, bool tables_on_window) {
  return allow_table && (tables_on_window || !(s.grouped && s.win_cap > 0));
}

/// Hash of a parameter-table key (update_ho_coefficients).
struct HoKeyHash {
  template <std::size_t N>
  std::size_t operator()(const std::array<double, N>& a) const {
    std::size_t x = 0;
    for (double d : a) x = x * 1000003u ^ std::hash<double>()(d);
    return x;
  }
};

/// Rest length and constants {l0, kx, kv, ex, ev} of merged spring q (HoSprings::is_merged) with
/// W = w_i + w_j: each member's constants (ho_constants) added; l0 the members' when they agree,
/// otherwise the kx-weighted mean, so that sum kx_m (l - l0_m) = kx (l - l0) at every length. The
/// displacement constants of analytic_position cannot share that mean, so build_ho_springs
/// merges only equal rest lengths for it (HoMerge::EqualRestLength); a group that breaks this is a
/// logic error.
template <class T>
std::array<double, 5> ho_merged_constants(const HoSprings<T>& s, Index q, HoVariant variant, double W, double h) {
  bool equal = true;
  const auto r = pair_group_constants(
      s.merge_first, s.merge_l0, s.merge_group[q],
      [&](Index m) { return ho_constants(variant, s.merge_k[m], s.merge_c[m], W, h); }, equal);
  if (!equal && variant == HoVariant::AnalyticPosition)
    throw std::logic_error("harmonic_oscillation: analytic_position springs merged with unequal rest lengths");
  return r;
}

/// (Re)compute the constants for step h and inverse masses w (called by prepare, so whenever h
/// or a mass changes). Deduplicates (l0, k, c, W) into tables when ho_tables_wanted and there
/// are at most kHoMaxTable distinct sets; otherwise stores the constants per spring.
template <class T>
void update_ho_coefficients(HoSprings<T>& s, HoVariant variant, const T* w, T h, bool allow_table = true,
                            bool tables_on_window = false) {
  const Index S = s.size();
  const bool pos = variant == HoVariant::AnalyticPosition;
  const double hd = static_cast<double>(h);
  s.table = false;
  if (ho_tables_wanted(s, allow_table, tables_on_window)) {
    std::unordered_map<std::array<double, 4>, std::uint32_t, HoKeyHash> map;
    std::vector<std::array<double, 4>> keys;
    s.id.resize(S);
    bool ok = true;
    // A merged spring's table entry is keyed by its own constants (its members' sums, below):
    // (l0, kx, kv, -1 - index) never equals a plain spring's (l0, k, c, W >= 0) key, and merged
    // springs share an entry only when their constants are equal.
    std::vector<std::array<double, 5>> mc;   // constants of the merged entries, by -1 - key[3]
    std::unordered_map<std::array<double, 5>, std::uint32_t, HoKeyHash> mmap;
    for (Index q = 0; q < S && ok; ++q) {
      const double W = static_cast<double>(w[s.i[q]]) + static_cast<double>(w[s.j[q]]);
      std::array<double, 4> key{static_cast<double>(s.l0[q]), static_cast<double>(s.k[q]),
                                static_cast<double>(s.c[q]), W};
      if (s.is_merged(q)) {
        const auto c = ho_merged_constants(s, q, variant, W, hd);
        const auto mi = mmap.try_emplace(c, static_cast<std::uint32_t>(mc.size())).first;
        if (mi->second == mc.size()) mc.push_back(c);
        key = {c[0], c[1], c[2], -1.0 - static_cast<double>(mi->second)};
      }
      auto it = map.find(key);
      if (it == map.end()) {
        if (keys.size() >= kHoMaxTable) ok = false;
        it = map.emplace(key, static_cast<std::uint32_t>(keys.size())).first;
        keys.push_back(key);
      }
      s.id[q] = static_cast<std::uint16_t>(it->second);
    }
    if (ok) {
      s.table = true;
      const std::size_t m = keys.size();
      s.t_l0.resize(m);
      s.t_kx.resize(m);
      s.t_kv.resize(m);
      s.t_ex.assign(pos ? m : 0, T(0));
      s.t_ev.assign(pos ? m : 0, T(0));
      for (std::size_t t = 0; t < m; ++t) {
        std::array<double, 4> c{};
        if (keys[t][3] < 0.0) {   // a merged entry: its constants computed above
          const auto& e = mc[static_cast<std::size_t>(-1.0 - keys[t][3])];
          c = {e[1], e[2], e[3], e[4]};
        } else {
          c = ho_constants(variant, keys[t][1], keys[t][2], keys[t][3], hd);
        }
        s.t_l0[t] = static_cast<T>(keys[t][0]);
        s.t_kx[t] = static_cast<T>(c[0]);
        s.t_kv[t] = static_cast<T>(c[1]);
        if (pos) {
          s.t_ex[t] = static_cast<T>(c[2]);
          s.t_ev[t] = static_cast<T>(c[3]);
        }
      }
      s.kx.clear();
      s.kv.clear();
      s.ex.clear();
      s.ev.clear();
      return;
    }
  }
  s.id.clear();
  s.kx.resize(S);
  s.kv.resize(S);
  s.ex.resize(pos ? S : 0);
  s.ev.resize(pos ? S : 0);
#pragma omp parallel for schedule(static) if (S >= kHoSerialSprings)
  for (Index q = 0; q < S; ++q) {
    const double W = static_cast<double>(w[s.i[q]]) + static_cast<double>(w[s.j[q]]);
    std::array<double, 4> c{};
    if (s.is_merged(q)) {
      const auto e = ho_merged_constants(s, q, variant, W, hd);
      s.l0[q] = static_cast<T>(e[0]);
      c = {e[1], e[2], e[3], e[4]};
    } else {
      c = ho_constants(variant, static_cast<double>(s.k[q]), static_cast<double>(s.c[q]), W, hd);
    }
    s.kx[q] = static_cast<T>(c[0]);
    s.kv[q] = static_cast<T>(c[1]);
    if (pos) {
      s.ex[q] = static_cast<T>(c[2]);
      s.ev[q] = static_cast<T>(c[3]);
    }
  }
}

/// Where a spring's l0 and constants live: per spring (direct) or in tables indexed by id.
template <class T>
struct HoParamView {
  const T* l0;
  const T* kx;
  const T* kv;
  const T* ex;
  const T* ev;
  const std::uint16_t* id;   ///< table mode only
};

template <class T>
HoParamView<T> ho_param_view(const HoSprings<T>& s) {
  if (s.table) return {s.t_l0.data(), s.t_kx.data(), s.t_kv.data(), s.t_ex.data(), s.t_ev.data(), s.id.data()};
  return {s.l0.data(), s.kx.data(), s.kv.data(), s.ex.data(), s.ev.data(), nullptr};
}

/// Impulse (and HO-A displacement) per unit inverse mass of spring q: g (and p).
template <class T, HoVariant V, bool Table>
inline void ho_one_spring(Index q, const Index* I, const Index* J, const HoParamView<T>& P, const T* x,
                          const T* v, T g[3], T p[3]) {
  const std::size_t a = 3 * static_cast<std::size_t>(I[q]);
  const std::size_t b = 3 * static_cast<std::size_t>(J[q]);
  const std::size_t c = Table ? static_cast<std::size_t>(P.id[q]) : static_cast<std::size_t>(q);
  if constexpr (V == HoVariant::AnalyticPosition) {
    const kernels::HoCoeffs<T> k{P.kx[c], P.kv[c], P.ex[c], P.ev[c]};
    kernels::ho_spring_velocity_position(x, v, a, b, P.l0[c], k, g, p);
  } else if constexpr (V == HoVariant::KangCho2011) {
    kernels::kang_cho_spring_velocity(x, v, a, b, P.l0[c], P.kx[c], P.kv[c], g);
  } else {
    kernels::ho_spring_velocity(x, v, a, b, P.l0[c], P.kx[c], P.kv[c], g);
  }
}

/// Phase 1 of a block of m springs: each spring's impulse per unit inverse mass g (and its
/// displacement p for analytic_position) into the block buffers G (and P), 3 per spring. Plain
/// restrict pointers so that the loop vectorises (gathers only).
template <class T, HoVariant V, bool Table>
inline void ho_block_impulses(Index m, const Index* __restrict I, const Index* __restrict J,
                              const std::uint16_t* __restrict ID, const T* __restrict L0,
                              const T* __restrict KX, const T* __restrict KV, const T* __restrict EX,
                              const T* __restrict EV, const T* __restrict x, const T* __restrict v,
                              T* __restrict G, T* __restrict P) {
  for (Index r = 0; r < m; ++r) {
    const std::size_t a = 3 * static_cast<std::size_t>(I[r]);
    const std::size_t b = 3 * static_cast<std::size_t>(J[r]);
    const std::size_t c = Table ? static_cast<std::size_t>(ID[r]) : static_cast<std::size_t>(r);
    if constexpr (V == HoVariant::AnalyticPosition) {
      const kernels::HoCoeffs<T> k{KX[c], KV[c], EX[c], EV[c]};
      kernels::ho_spring_velocity_position(x, v, a, b, L0[c], k, G + 3 * r, P + 3 * r);
    } else if constexpr (V == HoVariant::KangCho2011) {
      kernels::kang_cho_spring_velocity(x, v, a, b, L0[c], KX[c], KV[c], G + 3 * r);
    } else {
      kernels::ho_spring_velocity(x, v, a, b, L0[c], KX[c], KV[c], G + 3 * r);
    }
  }
}

/// Phase 1 of a segment: springs (i0 + Step r, i0 + Step r + off), r < len; strided reads.
template <class T, HoVariant V, bool Table, int Step>
inline void ho_segment_impulses(Index len, Index i0, Index off, const std::uint16_t* __restrict ID,
                                const T* __restrict L0, const T* __restrict KX, const T* __restrict KV,
                                const T* __restrict EX, const T* __restrict EV, const T* __restrict x,
                                const T* __restrict v, T* __restrict G, T* __restrict P) {
  for (Index r = 0; r < len; ++r) {
    const std::size_t a = 3 * static_cast<std::size_t>(i0 + Step * r);
    const std::size_t b = a + 3 * static_cast<std::size_t>(off);
    const std::size_t c = Table ? static_cast<std::size_t>(ID[r]) : static_cast<std::size_t>(r);
    if constexpr (V == HoVariant::AnalyticPosition) {
      const kernels::HoCoeffs<T> k{KX[c], KV[c], EX[c], EV[c]};
      kernels::ho_spring_velocity_position(x, v, a, b, L0[c], k, G + 3 * r, P + 3 * r);
    } else if constexpr (V == HoVariant::KangCho2011) {
      kernels::kang_cho_spring_velocity(x, v, a, b, L0[c], KX[c], KV[c], G + 3 * r);
    } else {
      kernels::ho_spring_velocity(x, v, a, b, L0[c], KX[c], KV[c], G + 3 * r);
    }
  }
}

/// Phase 2 of a segment: +G at the lower endpoints, then -G at the upper ones (two passes: the
/// ranges may overlap).
template <class T, int Step>
inline void ho_segment_scatter(Index len, Index i0, Index off, T* __restrict acc, const T* __restrict G) {
  T* ai = acc + 3 * static_cast<std::size_t>(i0);
  for (Index r = 0; r < len; ++r)
    for (int e = 0; e < 3; ++e) ai[3 * Step * r + e] += G[3 * r + e];
  T* aj = acc + 3 * static_cast<std::size_t>(i0 + off);
  for (Index r = 0; r < len; ++r)
    for (int e = 0; e < 3; ++e) aj[3 * Step * r + e] -= G[3 * r + e];
}

/// Springs per block in the sweep: phase 1 computes the impulses of a block (vectorised,
/// gathers only), phase 2 scatters them.
constexpr Index kHoBlock = 128;

/// One HO step on raw arrays (3n positions/velocities, n inverse masses), race free, no
/// allocation. dv (and dx for analytic_position) are 3n accumulators that must be zero on
/// entry; they are zero again on return.
///
/// Accumulation: a spring's impulse per unit inverse mass g (Delta v_i = +w_i g, Delta v_j =
/// -w_j g) is summed unweighted into both endpoints' accumulators (+g, -g, like a force), and
/// a vertex's sum is multiplied by its inverse mass once, when it is finalised: w_i (g_1 + g_2
/// + ...) instead of w_i g_1 + w_i g_2 + ... (equal to rounding), which halves the stores of
/// the impulse loops and drops their inverse-mass loads.
///
/// Traversal: each part of the layout is swept in order of lower endpoint (s.i). A vertex q
/// of the part is complete as soon as the sweep has passed every spring with lower endpoint
/// q (its other springs have a smaller lower endpoint), unless a cross spring touches it
/// (s.deferred). So the sweep finalises q right away (v += w dv + h g, x += h v), while
/// q's data is still in cache, and clears the accumulator; the deferred vertices are
/// finalised after the cross springs. One pass over the vertices per step.
template <class T, HoVariant V, bool Table>
void ho_step_impl(const SpringLayout& layout, const HoSprings<T>& s, T* x, T* v, T* dv, T* dx, const T* w, T h,
                  const std::array<T, 3>& g) {
  constexpr bool kPos = V == HoVariant::AnalyticPosition;
  constexpr std::size_t kPosBlock = kPos ? 3 * kHoBlock : 1;
  const Index* I = s.i.data();
  const Index* J = s.j.data();
  const HoParamView<T> P = ho_param_view(s);
  const std::uint8_t* deferred = s.is_deferred.data();
  const T hh2 = h * h / T(2);
  const T hg[3] = {h * g[0], h * g[1], h * g[2]};
  const T gg[3] = {hh2 * g[0], hh2 * g[1], hh2 * g[2]};

  // Vertex q with unweighted sums sv (and sp): kernels::ho_finalise_vertex (shared with the
  // CUDA backend) on w_q sv (and w_q sp).
  auto finish = [&](Index q, const T* sv, const T* sp) {
    const std::size_t o = 3 * static_cast<std::size_t>(q);
    const T wq = w[q];
    const T dq[3] = {wq * sv[0], wq * sv[1], wq * sv[2]};
    T pq[3] = {T(0), T(0), T(0)};
    if constexpr (kPos) {
      pq[0] = wq * sp[0];
      pq[1] = wq * sp[1];
      pq[2] = wq * sp[2];
    }
    kernels::ho_finalise_vertex<T, kPos>(x + o, v + o, dq, pq, wq, h, hg, gg);
  };
  auto finalize = [&](Index q) {  // from the 3n accumulators, which it clears
    const std::size_t o = 3 * static_cast<std::size_t>(q);
    T* dq = dv + o;
    T* pq = kPos ? dx + o : nullptr;
    finish(q, dq, pq);
    dq[0] = dq[1] = dq[2] = T(0);
    if constexpr (kPos) pq[0] = pq[1] = pq[2] = T(0);
  };
  // One spring, computed and scattered directly (cross springs).
  auto single = [&](Index q) {
    const std::size_t a = 3 * static_cast<std::size_t>(I[q]);
    const std::size_t b = 3 * static_cast<std::size_t>(J[q]);
    T gv[3], pv[3];
    ho_one_spring<T, V, Table>(q, I, J, P, x, v, gv, pv);
    for (int e = 0; e < 3; ++e) {
      dv[a + e] += gv[e];
      dv[b + e] -= gv[e];
      if constexpr (kPos) {
        dx[a + e] += pv[e];
        dx[b + e] -= pv[e];
      }
    }
  };
  // Sweep of part p's interior springs, finalising vertices as they complete.
  auto sweep = [&](int p) {
    const Index ve = layout.part_vertex_end(p);
    const Index kend = layout.part_spring_end(p);
    Index k = layout.part_spring_begin(p);
    Index qfin = layout.part_vertex_begin(p);
    alignas(64) T Gb[3 * kHoBlock];
    alignas(64) T Pb[kPosBlock];
    while (k < kend) {
      const Index k1 = std::min<Index>(k + kHoBlock, kend);
      const Index m = k1 - k;
      // phase 1: impulses per unit inverse mass, gathers only
      const std::size_t off = Table ? 0 : static_cast<std::size_t>(k);
      ho_block_impulses<T, V, Table>(m, I + k, J + k, Table ? P.id + k : nullptr, P.l0 + off, P.kx + off,
                                     P.kv + off, kPos ? P.ex + off : nullptr, kPos ? P.ev + off : nullptr, x, v,
                                     Gb, Pb);
      // phase 2: scatter. Consecutive springs mostly share their lower endpoint: its sum is kept
      // in registers for the run (no store-to-load chain through dv[i]).
      for (Index r = 0; r < m;) {
        const Index ia = I[k + r];
        T si[3] = {T(0), T(0), T(0)}, pi[3] = {T(0), T(0), T(0)};
        do {
          const std::size_t b = 3 * static_cast<std::size_t>(J[k + r]);
          for (int e = 0; e < 3; ++e) {
            si[e] += Gb[3 * r + e];
            dv[b + e] -= Gb[3 * r + e];
            if constexpr (kPos) {
              pi[e] += Pb[3 * r + e];
              dx[b + e] -= Pb[3 * r + e];
            }
          }
          ++r;
        } while (r < m && I[k + r] == ia);
        const std::size_t a = 3 * static_cast<std::size_t>(ia);
        for (int e = 0; e < 3; ++e) {
          dv[a + e] += si[e];
          if constexpr (kPos) dx[a + e] += pi[e];
        }
      }
      k = k1;
      const Index done = k < kend ? I[k] : ve;   // every spring with lower endpoint < done is applied
      for (; qfin < done; ++qfin)
        if (!deferred[qfin]) finalize(qfin);
    }
    for (; qfin < ve; ++qfin)
      if (!deferred[qfin]) finalize(qfin);
  };

  // Grouped sweep of part p (see HoSprings::grouped).
  auto sweep_grouped = [&](int p) {
    Index qfin = layout.part_vertex_begin(p);
    alignas(64) T Gb[3 * kHoVertexBlock];
    alignas(64) T Pb[kPos ? 3 * kHoVertexBlock : 1];
    for (Index bk = s.part_block[p]; bk < s.part_block[p + 1]; ++bk) {
      const auto& B = s.blocks[bk];
      for (Index sg = B.seg_begin; sg < B.seg_end; ++sg) {
        const auto& G = s.segs[sg];
        const std::size_t off = Table ? 0 : static_cast<std::size_t>(G.begin);
        const std::uint16_t* id = Table ? P.id + G.begin : nullptr;
        const T* ex = kPos ? P.ex + off : nullptr;
        const T* ev = kPos ? P.ev + off : nullptr;
        if (G.step == 1) {
          ho_segment_impulses<T, V, Table, 1>(G.len, G.i0, G.off, id, P.l0 + off, P.kx + off, P.kv + off, ex, ev,
                                              x, v, Gb, Pb);
          ho_segment_scatter<T, 1>(G.len, G.i0, G.off, dv, Gb);
          if constexpr (kPos) ho_segment_scatter<T, 1>(G.len, G.i0, G.off, dx, Pb);
        } else {
          ho_segment_impulses<T, V, Table, 2>(G.len, G.i0, G.off, id, P.l0 + off, P.kx + off, P.kv + off, ex, ev,
                                              x, v, Gb, Pb);
          ho_segment_scatter<T, 2>(G.len, G.i0, G.off, dv, Gb);
          if constexpr (kPos) ho_segment_scatter<T, 2>(G.len, G.i0, G.off, dx, Pb);
        }
      }
      for (; qfin < B.vertex_end; ++qfin)
        if (!deferred[qfin]) finalize(qfin);
    }
  };

  // Windowed grouped sweep of part p (ho_window.hpp): the same segments and additions as
  // sweep_grouped, on structure-of-arrays copies of the live vertices.
  auto sweep_window = [&](int p) {
    constexpr Index Bk = kHoVertexBlock;
    constexpr int Vi = V == HoVariant::Velocity ? 0 : (V == HoVariant::AnalyticPosition ? 1 : 2);
    const Index cap = s.win_cap;
    T* A[kHoWinArrays];
    window_arrays(s.win.data(), p, cap, A);
    T* const X = A[0];
    T* const Y = A[1];
    T* const Z = A[2];
    T* const VX = A[3];
    T* const VY = A[4];
    T* const VZ = A[5];
    T* const DX = A[6];
    T* const DY = A[7];
    T* const DZ = A[8];
    T* const PX = A[9];
    T* const PY = A[10];
    T* const PZ = A[11];
    const int narr = kPos ? 12 : 9;
    Index ws = layout.part_vertex_begin(p), fill = ws, qfin = ws;
    alignas(64) T Gb[3 * Bk];
    alignas(64) T Qb[kPos ? 3 * Bk : 1];
    alignas(64) T Gb2[3 * Bk];               // the second segment of a twin pair
    alignas(64) T Qb2[kPos ? 3 * Bk : 1];
    for (Index bk = s.part_block[p]; bk < s.part_block[p + 1]; ++bk) {
      const auto& B = s.blocks[bk];
      const Index need = s.block_need[bk];
      window_make_room(A, narr, cap, need, qfin, fill, ws);
      window_fill<T, true, kPos>(x, v, fill, need, ws, X, Y, Z, VX, VY, VZ, DX, DY, DZ, PX, PY, PZ);
      fill = std::max(fill, need);
      for (Index sg = B.seg_begin; sg < B.seg_end; ++sg) {
        const auto& G = s.segs[sg];
        const std::size_t off = Table ? 0 : static_cast<std::size_t>(G.begin);
        const std::uint16_t* id = Table ? P.id + G.begin : nullptr;
        const T* ex = kPos ? P.ex + off : nullptr;
        const T* ev = kPos ? P.ev + off : nullptr;
        const Index a = G.i0 - ws;
        const T* l0 = P.l0 + off;
        const T* kx = P.kx + off;
        const T* kv = P.kv + off;
        if (s.twins && G.twin) {
          // a twin pair (the next segment has the same endpoints): the geometry once, then each
          // segment's additions in the order of the two segments run one after the other
          const auto& G2 = s.segs[sg + 1];
          const std::size_t off2 = Table ? 0 : static_cast<std::size_t>(G2.begin);
          const HoSegConsts<T> CA{id, l0, kx, kv, ex, ev};
          const HoSegConsts<T> CB{Table ? P.id + G2.begin : nullptr, P.l0 + off2, P.kx + off2, P.kv + off2,
                                  kPos ? P.ex + off2 : nullptr, kPos ? P.ev + off2 : nullptr};
          ++sg;
          if constexpr (!kPos) {
            if (s.fuse && G.step == 1 && G.off >= G.len) {
              ho_window_impulses_scatter_twin<T, Vi, Table, Bk>(G.len, a, G.off, CA, CB, X, Y, Z, VX, VY, VZ, Gb,
                                                                Gb2, DX, DY, DZ);
              continue;
            }
          }
          const auto run2 = [&]<int Step>() {
            ho_window_impulses_twin<T, Vi, Table, Step, Bk>(G.len, a, G.off, CA, CB, X, Y, Z, VX, VY, VZ, Gb, Gb2,
                                                            Qb, Qb2);
            if (s.fuse && (Step == 2 || G.off > 0)) {   // both segments' scatters in one pass per array
              window_segment_scatter_twin<T, Step, Bk>(G.len, a, G.off, DX, DY, DZ, Gb, Gb2);
              if constexpr (kPos) window_segment_scatter_twin<T, Step, Bk>(G.len, a, G.off, PX, PY, PZ, Qb, Qb2);
              return;
            }
            window_segment_scatter<T, Step, Bk>(G.len, a, G.off, DX, DY, DZ, Gb);
            if constexpr (kPos) window_segment_scatter<T, Step, Bk>(G.len, a, G.off, PX, PY, PZ, Qb);
            window_segment_scatter<T, Step, Bk>(G.len, a, G.off, DX, DY, DZ, Gb2);
            if constexpr (kPos) window_segment_scatter<T, Step, Bk>(G.len, a, G.off, PX, PY, PZ, Qb2);
          };
          if (G.step == 1)
            run2.template operator()<1>();
          else
            run2.template operator()<2>();
          continue;
        }
        // unit stride, lower and upper ranges disjoint: impulses and scatter in one pass
        if constexpr (!kPos) {
          if (s.fuse && G.step == 1 && G.off >= G.len) {
            ho_window_impulses_scatter<T, Vi, Table, Bk>(G.len, a, G.off, id, l0, kx, kv, X, Y, Z, VX, VY, VZ, Gb,
                                                         DX, DY, DZ);
            continue;
          }
        }
        // One run with its stride (1 or 2) as a template argument.
        const auto run = [&]<int Step>() {
          ho_window_impulses<T, Vi, Table, Step, Bk>(G.len, a, G.off, id, l0, kx, kv, ex, ev, X, Y, Z, VX, VY, VZ,
                                                     Gb, Qb);
          if constexpr (Step == 1 && !kPos) {
            if (s.fuse && G.off > 0) {   // off < len here: overlapping ranges, one scatter pass
              window_segment_scatter_overlap<T, Bk>(G.len, a, G.off, DX, DY, DZ, Gb);
              return;
            }
          }
          window_segment_scatter<T, Step, Bk>(G.len, a, G.off, DX, DY, DZ, Gb);
          if constexpr (kPos) window_segment_scatter<T, Step, Bk>(G.len, a, G.off, PX, PY, PZ, Qb);
        };
        if (G.step == 1)
          run.template operator()<1>();
        else
          run.template operator()<2>();
      }
      // cross springs add to a deferred vertex later: hand its sums to the accumulators
      const auto hand_off = [&](Index q) {
        const Index l = q - ws;
        const std::size_t o = 3 * static_cast<std::size_t>(q);
        dv[o] += DX[l];
        dv[o + 1] += DY[l];
        dv[o + 2] += DZ[l];
        if constexpr (kPos) {
          dx[o] += PX[l];
          dx[o + 1] += PY[l];
          dx[o + 2] += PZ[l];
        }
      };
#if defined(LOOM_HO_FINALISE_AVX2)
      // velocity and kang_cho_2011 in double: 4 vertices at a time, the same bits (ho_window.hpp)
      if constexpr (!kPos && std::is_same_v<T, double>) {
        const Index vend = ho_finalise_block_avx2(qfin, B.vertex_end, ws, X, Y, Z, VX, VY, VZ, DX, DY, DZ, w,
                                                  deferred, x, v, h, hg);
        for (; qfin < vend; ++qfin)
          if (deferred[qfin]) hand_off(qfin);
      }
#endif
      for (; qfin < B.vertex_end; ++qfin) {
        const Index l = qfin - ws;
        if (deferred[qfin]) {
          hand_off(qfin);
        } else {
          const T sv[3] = {DX[l], DY[l], DZ[l]};
          T sp[3] = {T(0), T(0), T(0)};
          if constexpr (kPos) {
            sp[0] = PX[l];
            sp[1] = PY[l];
            sp[2] = PZ[l];
          }
          finish(qfin, sv, sp);
        }
      }
    }
  };

  // One parallel region (loom/traversal.hpp): the parts' sweeps, the cross springs, then the
  // vertices the cross springs touch.
  const bool serial = s.size() < kHoSerialSprings || traversal_threads() == 1;
  traverse_parts(
      layout, !serial,
      [&](int p) {
        if (s.grouped && s.win_cap > 0)
          sweep_window(p);
        else if (s.grouped)
          sweep_grouped(p);
        else
          sweep(p);
      },
      [&](Index k0, Index k1) {
        for (Index q = k0; q < k1; ++q) single(q);
      },
      static_cast<Index>(s.deferred.size()), [&](Index r) { finalize(s.deferred[r]); });
}

/// One HO step (see ho_step_impl), dispatching on the spring storage.
template <class T, HoVariant V>
void ho_step_arrays(const SpringLayout& layout, const HoSprings<T>& s, T* x, T* v, T* dv, T* dx, const T* w,
                    T h, const std::array<T, 3>& g) {
  if (s.table)
    ho_step_impl<T, V, true>(layout, s, x, v, dv, dx, w, h, g);
  else
    ho_step_impl<T, V, false>(layout, s, x, v, dv, dx, w, h, g);
}

class HoIntegrator final : public Integrator {
 public:
  explicit HoIntegrator(const Params& p = Params());
  /// allow_table = false forces per-spring constants (parameter storage: direct).
  explicit HoIntegrator(HoVariant variant, bool allow_table = true, bool allow_grouping = true,
                        HoReorder reorder = HoReorder::Auto)
      : variant_(variant), allow_table_(allow_table), allow_grouping_(allow_grouping), reorder_(reorder) {}
  std::string name() const override { return "harmonic_oscillation"; }
  IntegratorNeeds needs() const override { return {true, false, false}; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  /// One pass over every spring per step: counted as one force evaluation, for studies.
  StepStats last_step() const override {
    StepStats st;
    st.force_evaluations = 1;
    return st;
  }

  HoVariant variant() const { return variant_; }
  const HoSprings<double>& springs() const { return springs_; }
  const SpringLayout& layout() const { return layout_; }
  /// The vertex order the step runs in (identity: the user's numbering).
  const VertexOrder& order() const { return order_; }
  bool reordered() const { return !order_.identity(); }
  HoReorder reorder_mode() const { return reorder_; }
  /// Keep the parameter tables on the windowed grouped sweep too (the storage before per-spring
  /// streams became the default there; tests and benchmarks compare the two). Call before prepare.
  void set_tables_on_window(bool on) { tables_on_window_ = on; }
  /// Key `merge_springs` (HoMerge): merge springs on the same two vertices (true, the default) or
  /// keep every spring. Call before prepare.
  void set_merge_springs(bool on) { merge_ = on; }
  /// Springs folded into others by the merge (0 before prepare or with merge_springs false).
  Index merged_springs() const { return springs_.merged; }

 private:
  HoVariant variant_ = HoVariant::Velocity;
  bool allow_table_ = true;
  bool allow_grouping_ = true;
  bool tables_on_window_ = false;
  bool merge_ = true;
  SpringLayout layout_;
  HoSprings<double> springs_;
  HoReorder reorder_ = HoReorder::Auto;
  VertexOrder order_;             ///< internal vertex k is user vertex order_.perm[k]
  std::vector<double> xp_, vp_, wp_;   ///< state in the internal order (reordered runs only)
  std::vector<double> dv_, dx_;   ///< accumulators, zero between steps
  double h_ = -1;
  const SpringSet* source_ = nullptr;
  Index source_size_ = -1;   ///< springs of the set the layout was built from (before merging)
};

}  // namespace loom
