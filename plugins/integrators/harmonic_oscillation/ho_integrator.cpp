#include "ho_integrator.hpp"

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <type_traits>
#include <stdexcept>
#include <utility>

namespace loom {

HoVariant parse_ho_variant(const std::string& s) {
  if (s == "velocity") return HoVariant::Velocity;
  if (s == "analytic_position") return HoVariant::AnalyticPosition;
  if (s == "kang_cho_2011") return HoVariant::KangCho2011;
  throw InputError("harmonic_oscillation: unknown variant '" + s +
                   "'; use velocity, analytic_position or kang_cho_2011");
}

const char* to_string(HoVariant v) {
  switch (v) {
    case HoVariant::Velocity: return "velocity";
    case HoVariant::AnalyticPosition: return "analytic_position";
    case HoVariant::KangCho2011: return "kang_cho_2011";
  }
  return "?";
}

const ParamSpec& harmonic_oscillation_spec() {
  static const ParamSpec spec = [] {
    ParamSpec s("harmonic_oscillation", "Kang & Cho 2011 harmonic-oscillation spring integration, corrected");
    s.choice("variant", "velocity", {"velocity", "analytic_position", "kang_cho_2011"}).help(
        "velocity: exact axial velocity change per spring; analytic_position: also the exact displacement (HO-A); "
        "kang_cho_2011: the published formula (half the stiffness)");
    s.choice("storage", "auto", {"auto", "direct"}).backends({"cpu"}).help(
        "auto: constants stored per spring on the windowed grouped sweep (streamed), otherwise deduplicated into "
        "tables of (l0, k, c, W) when there are at most 65536 sets; direct: always stored per spring");
    s.choice("reorder", "auto", {"auto", "none", "rcm"}).backends({"cpu"}).help(
        "vertex order of the step: rcm renumbers the vertices internally (reverse Cuthill-McKee) so that "
        "springs join nearby vertices; results stay in the mesh's numbering. auto: rcm for meshes of at least "
        "16384 vertices whose spring span it shrinks 4x or more; none: the mesh's order");
    s.flag("merge_springs", true).backends({"cpu", "cuda"}).help(kHoMergeSpringsHelp);
    declare_device_keys(s);
    return s;
  }();
  return spec;
}

HoVariant read_ho_variant(const Params& p) {
  if (!p.valid()) return HoVariant::Velocity;
  return parse_ho_variant(ParamReader(p, harmonic_oscillation_spec()).text("variant"));
}

HoIntegrator::HoIntegrator(const Params& p) {
  if (p.valid()) {
    variant_ = read_ho_variant(p);
    const ParamReader r(p, harmonic_oscillation_spec());
    allow_table_ = r.text("storage") == "auto";
    const std::string ro = r.text("reorder");
    reorder_ = parse_reorder_mode(ro);
    merge_ = r.flag("merge_springs");
  }
}

void build_ho_springs(Index n, const SpringSet& set, SpringLayout& layout, HoSprings<double>& out,
                      bool allow_grouping, Index group_block, HoMerge merge) {
  out.merge_group.clear();
  out.merge_first.clear();
  out.merge_l0.clear();
  out.merge_k.clear();
  out.merge_c.clear();
  std::vector<std::pair<std::uint64_t, Index>> keys;   // (endpoint pair, merged group), sorted
  SpringSet sorted;   // copied once, so that the layout can store it in traversal order
  if (merge == HoMerge::None) {
    sorted = set;
  } else {
    SpringPairGroups g = group_springs_by_pair(set, merge == HoMerge::EqualRestLength);
    for (Index q = 0; q < g.springs.size(); ++q)
      if (g.group[q] >= 0) keys.emplace_back(spring_pair_key(g.springs.i[q], g.springs.j[q]), g.group[q]);
    std::sort(keys.begin(), keys.end());
    sorted = std::move(g.springs);
    out.merge_first = std::move(g.first);
    out.merge_l0 = std::move(g.l0);
    out.merge_k = std::move(g.k);
    out.merge_c = std::move(g.c);
  }
  out.merged = set.size() - sorted.size();
  layout = SpringLayout(n, sorted);
  layout.reorder(sorted);
  const Index S = sorted.size();
  out.i.resize(S);
  out.j.resize(S);
  out.l0.resize(S);
  out.k.resize(S);
  out.c.resize(S);
  for (Index q = 0; q < S; ++q) {
    out.i[q] = std::min(sorted.i[q], sorted.j[q]);   // HO is symmetric in (i, j)
    out.j[q] = std::max(sorted.i[q], sorted.j[q]);
    out.l0[q] = sorted.rest_length[q];
    out.k[q] = sorted.stiffness[q];
    out.c[q] = sorted.damping[q];
  }
  // The sweep needs each part's interior springs sorted by lower endpoint (the layout
  // guarantees it); check, since the finalisation relies on it.
  for (int p = 0; p < layout.parts(); ++p)
    for (Index q = layout.part_spring_begin(p) + 1; q < layout.part_spring_end(p); ++q)
      if (out.i[q] < out.i[q - 1])
        throw std::logic_error("harmonic_oscillation: spring layout part not sorted by lower endpoint");
  // Grouped traversal (loom/spring_groups.hpp): within each part, blocks of kHoVertexBlock
  // vertices (by lower endpoint), springs ordered by (block, offset, i), cut into segments of
  // consecutive i.
  {
    SpringGroups g;
    const std::vector<Index> perm = group_springs(layout, out.i, out.j, g, group_block);
    out.grouped = allow_grouping && g.grouped;
    if (out.grouped) {
      apply_spring_perm(perm, out.i);
      apply_spring_perm(perm, out.j);
      apply_spring_perm(perm, out.l0);
      apply_spring_perm(perm, out.k);
      apply_spring_perm(perm, out.c);
      out.segs = std::move(g.segs);
      out.blocks = std::move(g.blocks);
      out.part_block = std::move(g.part_block);
    } else {
      out.segs.clear();
      out.blocks.clear();
      out.part_block.clear();
    }
  }
  // Each spring's merged group (-1: none), found by its endpoint pair.
  if (!keys.empty()) {
    out.merge_group.assign(static_cast<std::size_t>(S), -1);
    for (Index q = 0; q < S; ++q) {
      const std::uint64_t key = spring_pair_key(out.i[q], out.j[q]);
      const auto it = std::lower_bound(keys.begin(), keys.end(), std::make_pair(key, Index{-1}));
      if (it != keys.end() && it->first == key) out.merge_group[q] = it->second;
    }
  } else {
    out.merge_first.clear();
  }
  plan_ho_window(layout, out);
  allocate_ho_window(out, layout.parts());
  out.is_deferred.assign(static_cast<std::size_t>(n), 0);
  for (Index q = layout.colour_begin(0); q < S; ++q) out.is_deferred[out.i[q]] = out.is_deferred[out.j[q]] = 1;
  out.deferred.clear();
  for (Index v = 0; v < n; ++v)
    if (out.is_deferred[v]) out.deferred.push_back(v);
}

void HoIntegrator::prepare(Scene& scene, double h) {
  const Material* mat = scene.material.get();
  const SpringSet* set = mat ? mat->springs() : nullptr;
  if (!set)
    throw InputError(scene.source + ": integrator harmonic_oscillation needs a spring material, but material '" +
                     (mat ? mat->name() : std::string("(none)")) +
                     "' exposes no springs. Fix: use material type mass_spring, or an integrator that works with "
                     "any material (symplectic_euler, rk4, baraff_witkin).");
  if (variant_ == HoVariant::KangCho2011 &&
      std::any_of(set->damping.begin(), set->damping.end(), [](double c) { return c != 0.0; }))
    throw InputError(scene.source + ": harmonic_oscillation variant kang_cho_2011 (the published formula) has no "
                     "spring damping. Fix: set the material's spring damping to 0, or use variant velocity or "
                     "analytic_position, which integrate the damper exactly.");
  for (Index q = 0; q < set->size(); ++q)
    if (!(set->stiffness[q] >= 0.0) || !(set->damping[q] >= 0.0))
      throw InputError(scene.source + ": harmonic_oscillation needs springs with stiffness >= 0 and damping >= 0 "
                       "(spring " + std::to_string(q) + "). Fix: check the material's stiffness and damping.");
  const Index n = scene.state.size();
  if (set != source_ || layout_.num_vertices() != n || source_size_ != set->size()) {
    // Vertex order: computed once per spring set (docs/plugins/integrators.md, `reorder`).
    order_ = choose_vertex_order(reorder_, n, set->i, set->j);
    if (order_.identity()) {
      build_ho_springs(n, *set, layout_, springs_, allow_grouping_, kHoGroupBlock, ho_merge_mode(variant_, merge_));
    } else {
      SpringSet internal = *set;
      for (Index& a : internal.i) a = order_.inv[a];
      for (Index& b : internal.j) b = order_.inv[b];
      build_ho_springs(n, internal, layout_, springs_, allow_grouping_, kHoGroupBlock,
                       ho_merge_mode(variant_, merge_));
    }
    source_ = set;
    source_size_ = set->size();
  }
  dv_.assign(3 * static_cast<std::size_t>(n), 0.0);
  dx_.assign(variant_ == HoVariant::AnalyticPosition ? 3 * static_cast<std::size_t>(n) : 0, 0.0);
  const double* w = scene.state.inv_mass.data();
  if (!order_.identity()) {
    xp_.assign(3 * static_cast<std::size_t>(n), 0.0);
    vp_.assign(3 * static_cast<std::size_t>(n), 0.0);
    wp_.resize(static_cast<std::size_t>(n));
    gather_vertices<1>(order_, w, wp_.data());
    w = wp_.data();
  } else {
    xp_.clear();
    vp_.clear();
    wp_.clear();
  }
  update_ho_coefficients(springs_, variant_, w, h, allow_table_, tables_on_window_);
  h_ = h;
}

void HoIntegrator::step(Scene& scene, double h) {
  State& s = scene.state;
  if (h != h_ || dv_.size() != s.x.size()) prepare(scene, h);
  const std::array<double, 3> g{scene.gravity[0], scene.gravity[1], scene.gravity[2]};
  double* x = s.x.data();
  double* v = s.v.data();
  const double* w = s.inv_mass.data();
  const bool reordered = !order_.identity();
  if (reordered) {   // the step runs on copies in the internal order
    gather_state(order_, x, v, xp_.data(), vp_.data());
    x = xp_.data();
    v = vp_.data();
    w = wp_.data();
  }
  switch (variant_) {
    case HoVariant::Velocity:
      ho_step_arrays<double, HoVariant::Velocity>(layout_, springs_, x, v, dv_.data(), nullptr, w, h, g);
      break;
    case HoVariant::KangCho2011:
      ho_step_arrays<double, HoVariant::KangCho2011>(layout_, springs_, x, v, dv_.data(), nullptr, w, h, g);
      break;
    case HoVariant::AnalyticPosition:
      ho_step_arrays<double, HoVariant::AnalyticPosition>(layout_, springs_, x, v, dv_.data(), dx_.data(), w, h, g);
      break;
  }
  if (reordered) {
    scatter_state(order_, xp_.data(), vp_.data(), s.x.data(), s.v.data());
  }
  // Moving pins (w = 0: the springs treat them as infinite masses at their prescribed
  // velocity): exactly the prescribed positions and velocities at the end of the step.
  scene.pins.apply(s, s.time + h);
  finish_step(s, h);
}

}  // namespace loom
