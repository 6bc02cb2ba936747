#include "cuda_integrators.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <type_traits>

#include "loom/incidence.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "loom/kernels/bw_assembly.hpp"
#include "loom/kernels/friction.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/kernels/rk4.hpp"
#include "loom/springs.hpp"
#include "bw_step.hpp"
#include "device_colliders.hpp"
#include "se_update.hpp"

namespace loom::cuda {

Precision parse_precision(const Params& p) {
  if (!p.valid()) return Precision::Double;
  return ParamReader(p, device_keys_spec()).text("precision") == "float" ? Precision::Float : Precision::Double;
}

namespace {

using Clock = std::chrono::steady_clock;

/// Checks shared by the device integrators; throws InputError with the fix. With
/// `device_colliders` sphere, plane and mesh colliders are handled on the device; otherwise
/// colliders are refused.
void check_device_scene(const Scene& scene, const char* integrator, bool device_colliders) {
  seam_require_device(scene.source);
  if (!scene.colliders.empty() && !device_colliders)
    throw InputError(scene.source + ": integrator " + integrator +
                     " on backend cuda does not handle colliders (its contacts are constraints of the implicit solve, "
                     "not on the device yet). Fix: use integrator rk4 or harmonic_oscillation with backend: cuda, or "
                     "backend: cpu for baraff_witkin with colliders.");
  if (scene.colliders.size() > static_cast<std::size_t>(kMaxDeviceColliders))
    throw InputError(scene.source + ": backend cuda handles at most " + std::to_string(kMaxDeviceColliders) +
                     " colliders, the scene has " + std::to_string(scene.colliders.size()) +
                     ". Fix: merge colliders, or set backend: cpu.");
  if (scene.pins.moving())
    throw InputError(scene.source + ": integrator " + integrator +
                     " on backend cuda does not implement pins with a prescribed motion (the device keeps pinned "
                     "vertices where they are). Fix: set backend: cpu for scenes whose pins have a 'motion'.");
  if (scene.self_collision)
    throw InputError(scene.source + ": integrator " + integrator +
                     " on backend cuda does not handle self_collision yet (it is resolved on the host state, which "
                     "the device would not see). Fix: set backend: cpu for scenes with self_collision.");
}

/// Sphere, plane and mesh colliders on the device: after an explicit step, per vertex, the
/// same query and response as the CPU's ColliderSet::resolve_contacts (loom/kernels/contact.hpp,
/// loom/kernels/mesh_query.hpp; the query exact below distance 0), colliders in scene order,
/// pinned vertices skipped. The placements (frame_at) are computed on the host once per step
/// and passed by value.
template <class T>
struct ContactKernel {
  DeviceShape<T> shapes[kMaxDeviceColliders];
  int count;
  const std::uint8_t* pinned;
  T *x, *v;
  T h;
  LOOM_HD void operator()(Index i) const {
    if (pinned[i]) return;
    T* xi = x + 3LL * i;
    T* vi = v + 3LL * i;
    for (int c = 0; c < count; ++c) {
      T n[3], vs[3];
      const T d = device_query(shapes[c], xi, 0.0, n, vs);
      if (d >= T(0)) continue;
      kernels::contact_respond(xi, vi, d, n, vs, shapes[c].s.mu_static, shapes[c].s.mu_kinetic, h);
    }
  }
};

template <class T>
class DeviceColliders {
 public:
  void prepare(const Scene& scene) {
    colliders_ = &scene.colliders;
    if (!colliders_->empty()) cuda::upload(scene.state.pinned, pinned_);
    meshes_.prepare(scene.colliders);
  }
  bool active() const { return colliders_ && !colliders_->empty(); }
  /// Resolve contacts at time t (the end of a step of size h).
  void resolve(DeviceState<T>& ds, double t, double h) {
    ContactKernel<T> k{};
    k.count = fill_device_shapes(*colliders_, meshes_, t, k.shapes);
    k.pinned = raw(pinned_);
    k.x = raw(ds.x);
    k.v = raw(ds.v);
    k.h = static_cast<T>(h);
    parallel_for(ds.n, k);
  }

 private:
  const ColliderSet* colliders_ = nullptr;
  DeviceMeshes meshes_;
  DVec<std::uint8_t> pinned_;
};

/// Device bytes of the state (x, v, masses) plus `vectors` more 3n vectors and the material's
/// elements (its device description, or a host fallback: then counted as 0).
template <class T>
std::size_t explicit_bytes(const Scene& scene, int vectors) {
  const std::size_t n = static_cast<std::size_t>(scene.state.size());
  std::size_t elements = 0;
  if (scene.material)
    if (const SpringSet* s = scene.material->springs()) elements = static_cast<std::size_t>(s->size()) * (2 * sizeof(Index) + 4 * sizeof(T));
  return sizeof(T) * (3 * n * (2 + static_cast<std::size_t>(vectors)) + 2 * n) + elements +
         DeviceMeshes::bytes(scene.colliders);
}

/// Reads host_sync_every: 0 (the scene files' default) copies x, v back into scene.state only
/// when the framework asks (Integrator::sync_to_host); n >= 1 after every n-th step as well.
/// Without parameters (integrators made in code): 1, every step.
int parse_sync_every(const Params& p) {
  if (!p.valid()) return 1;
  return ParamReader(p, device_keys_spec()).int32("host_sync_every");
}

/// Copy back after the step that makes state.step a multiple of `every` (call before finish_step);
/// returns whether it did (every = 0: never, the framework asks for it).
template <class T>
bool sync_after_step(DeviceState<T>& ds, State& s, int every) {
  if (every == 1 || (every > 1 && (s.step + 1) % every == 0)) {
    ds.download(s);
    return true;
  }
  return false;
}

/// The guard's test (Simulation::check_state) on device data: vertex i when its position is not
/// finite or its squared speed is not <= vmax2 (NaN fails every comparison), `none` otherwise.
/// Sums in double, as the host does on the downloaded values (float converts exactly).
template <class T>
struct GuardTerm {
  const T *x, *v;
  double vmax2;
  Index none;
  LOOM_HD Index operator()(Index i) const {
    const T* xi = x + 3LL * i;
    const T* vi = v + 3LL * i;
    const double a = static_cast<double>(xi[0]) + static_cast<double>(xi[1]) + static_cast<double>(xi[2]);
    const double v0 = vi[0], v1 = vi[1], v2 = vi[2];
    const double s2 = v0 * v0 + v1 * v1 + v2 * v2;
    return (!(s2 <= vmax2) || !(a - a == 0.0)) ? i : none;  // a - a is NaN for a NaN or infinite a
  }
};

/// What every device integrator does with its copy of the state between steps: the lazy copy
/// back (host_sync_every: 0) and the guard on the device.
template <class T>
struct HostMirror {
  bool stale = false;  ///< scene.state.x/v are older than the device's
  void after_step(DeviceState<T>& ds, State& s, int every) { stale = !sync_after_step(ds, s, every); }
  void sync(DeviceState<T>& ds, State& s) {
    if (!stale || ds.n != s.size()) return;
    ds.download(s);
    stale = false;
  }
  /// -2 while the host copy is current (the framework checks it there) or nothing is on the device.
  Index first_unguarded(DeviceState<T>& ds, double vmax2) const {
    if (!stale || ds.n == 0) return -2;
    const Index none = ds.n;
    const Index i = reduce_min_index(ds.n, GuardTerm<T>{raw(ds.x), raw(ds.v), vmax2, none}, none);
    return i == none ? -1 : i;
  }
};

// ======================= harmonic oscillation =======================

template <class T, HoVariantD V>
struct HoSpringKernel {  // per spring: impulse (and HO-A displacement) per unit inverse mass
  const Index *I, *J;
  const T *L0, *KX, *KV, *EX, *EV, *x, *v;
  T *G, *P;
  LOOM_HD void operator()(Index q) const {
    const long long a = 3LL * I[q], b = 3LL * J[q];
    T g[3];
    if constexpr (V == HoVariantD::AnalyticPosition) {
      const kernels::HoCoeffs<T> c{KX[q], KV[q], EX[q], EV[q]};
      T p[3];
      kernels::ho_spring_velocity_position(x, v, a, b, L0[q], c, g, p);
      for (int e = 0; e < 3; ++e) P[3LL * q + e] = p[e];
    } else if constexpr (V == HoVariantD::KangCho2011) {
      kernels::kang_cho_spring_velocity(x, v, a, b, L0[q], KX[q], KV[q], g);
    } else {
      kernels::ho_spring_velocity(x, v, a, b, L0[q], KX[q], KV[q], g);
    }
    for (int e = 0; e < 3; ++e) G[3LL * q + e] = g[e];
  }
};

template <class T, HoVariantD V>
struct HoVertexKernel {  // per vertex: gather the impulses, then update x and v in place
  const Index *ptr, *spring;
  const signed char* sign;
  const T *w, *G, *P;
  T *x, *v;
  T h, hh2, g0, g1, g2;
  LOOM_HD void operator()(Index i) const {
    constexpr bool kPos = V == HoVariantD::AnalyticPosition;
    const long long d = 3LL * i;
    const T wi = w[i];
    const T g[3] = {g0, g1, g2};
    // The same arithmetic as the CPU plugin: the vertex's spring impulses (per unit inverse
    // mass) are summed unweighted, sv = sum of +-G_q, and scaled by w_i once, dv = w_i sv
    // (not w_i G_1 + w_i G_2 + ...). Only the summation order differs from the CPU's.
    T sv[3] = {T(0), T(0), T(0)}, sp[3] = {T(0), T(0), T(0)};
    for (Index k = ptr[i]; k < ptr[i + 1]; ++k) {
      const long long q = 3LL * spring[k];
      for (int e = 0; e < 3; ++e) {
        if (sign[k] > 0) {
          sv[e] += G[q + e];
          if constexpr (kPos) sp[e] += P[q + e];
        } else {
          sv[e] -= G[q + e];
          if constexpr (kPos) sp[e] -= P[q + e];
        }
      }
    }
    const T dv[3] = {wi * sv[0], wi * sv[1], wi * sv[2]};
    const T dx[3] = {wi * sp[0], wi * sp[1], wi * sp[2]};
    // The CPU plugin's finalisation, one source (loom/kernels/ho.hpp).
    const T hg[3] = {h * g[0], h * g[1], h * g[2]};
    const T gg[3] = {hh2 * g[0], hh2 * g[1], hh2 * g[2]};
    kernels::ho_finalise_vertex<T, kPos>(x + d, v + d, dv, dx, wi, h, hg, gg);
  }
};

template <class T>
class CudaHo final : public Integrator {
 public:
  CudaHo(HoVariantD v, int sync_every, bool merge) : variant_(v), sync_every_(sync_every), merge_(merge) {}
  std::string name() const override { return "harmonic_oscillation"; }
  IntegratorNeeds needs() const override { return {true, false, false}; }
  bool handles_contacts() const override { return true; }  // on the device
  void sync_to_host(Scene& scene) override { mirror_.sync(ds_, scene.state); }
  Index first_unguarded_vertex(double vmax2) override { return mirror_.first_unguarded(ds_, vmax2); }

  void prepare(Scene& scene, double h) override {
    mirror_.sync(ds_, scene.state);  // a repeated prepare uploads the current state, not a stale host copy
    check_device_scene(scene, "harmonic_oscillation", true);
    require_device_memory(explicit_bytes<T>(scene, 4), scene.source, "harmonic_oscillation");
    colliders_.prepare(scene);
    const Material* mat = scene.material.get();
    const SpringSet* set = mat ? mat->springs() : nullptr;
    if (!set)
      throw InputError(scene.source + ": integrator harmonic_oscillation needs a spring material, but material '" +
                       (mat ? mat->name() : std::string("(none)")) +
                       "' exposes no springs. Fix: use material type mass_spring, or rk4 / baraff_witkin.");
    for (Index q = 0; q < set->size(); ++q) {
      if (!(set->stiffness[q] >= 0.0) || !(set->damping[q] >= 0.0))
        throw InputError(scene.source + ": harmonic_oscillation needs springs with stiffness >= 0 and damping >= 0 "
                         "(spring " + std::to_string(q) + "). Fix: check the material's stiffness and damping.");
      if (variant_ == HoVariantD::KangCho2011 && set->damping[q] != 0.0)
        throw InputError(scene.source + ": harmonic_oscillation variant kang_cho_2011 (the published formula) has "
                         "no spring damping. Fix: set the material's spring damping to 0, or use variant velocity "
                         "or analytic_position.");
    }
    // Springs on the same two vertices merged as the CPU plugin merges them (key merge_springs;
    // docs/plugins/integrators.md, "Duplicate springs merged"): the members' constants added.
    groups_ = merge_ ? group_springs_by_pair(*set, variant_ == HoVariantD::AnalyticPosition) : SpringPairGroups{};
    const SpringSet& sp = merge_ ? groups_.springs : *set;
    const Index n = scene.state.size(), S = sp.size();
    hi_.resize(S);
    hj_.resize(S);
    for (Index q = 0; q < S; ++q) {
      hi_[q] = std::min(sp.i[q], sp.j[q]);  // HO is symmetric in (i, j)
      hj_[q] = std::max(sp.i[q], sp.j[q]);
    }
    hk_ = sp.stiffness;
    hc_ = sp.damping;
    hl0_ = sp.rest_length;
    cuda::upload(hi_, si_);
    cuda::upload(hj_, sj_);
    const VertexIncidence inc(n, hi_, hj_);  // the one incidence builder (loom/incidence.hpp)
    cuda::upload(inc.offsets, inc_ptr_);
    cuda::upload(inc.spring, inc_spring_);
    cuda::upload(inc.sign, inc_sign_);
    G_.assign(3 * static_cast<std::size_t>(S), T(0));
    P_.assign(variant_ == HoVariantD::AnalyticPosition ? 3 * static_cast<std::size_t>(S) : 0, T(0));
    ds_.upload(scene.state);
    mirror_.stale = false;
    coefficients(scene.state, h);
  }

  void step(Scene& scene, double h) override {
    if (ds_.n != scene.state.size()) prepare(scene, h);
    if (h != h_) coefficients(scene.state, h);
    switch (variant_) {
      case HoVariantD::Velocity: run<HoVariantD::Velocity>(scene, h); break;
      case HoVariantD::AnalyticPosition: run<HoVariantD::AnalyticPosition>(scene, h); break;
      case HoVariantD::KangCho2011: run<HoVariantD::KangCho2011>(scene, h); break;
    }
    if (colliders_.active()) colliders_.resolve(ds_, scene.state.time + h, h);
    mirror_.after_step(ds_, scene.state, sync_every_);
    finish_step(scene.state, h);
  }

 private:
  void coefficients(const State& s, double h) {
    const Index S = static_cast<Index>(hi_.size());
    std::vector<T> kx(S), kv(S), ex, ev;
    const bool pos = variant_ == HoVariantD::AnalyticPosition;
    if (pos) {
      ex.resize(S);
      ev.resize(S);
    }
    std::vector<T> l0(S);
    for (Index q = 0; q < S; ++q) {  // in double, like the CPU plugin
      const double wi = s.inv_mass[hi_[q]], wj = s.inv_mass[hj_[q]];
      auto constants = [&](double k, double c) -> std::array<double, 4> {
        if (variant_ == HoVariantD::KangCho2011) {
          const auto r = kernels::kang_cho_coefficients<double>(k, wi, wj, h);
          return {r.kx, r.ka, 0.0, 0.0};
        }
        const auto r = kernels::ho_coefficients<double>(k, c, wi, wj, h);
        return {r.kx, r.kv, r.ex, r.ev};
      };
      std::array<double, 5> e{hl0_[q], 0, 0, 0, 0};
      if (merge_ && groups_.group[q] >= 0) {   // a merged group: its members' constants added
        bool equal = true;
        e = pair_group_constants(groups_.first, groups_.l0, groups_.group[q],
                                 [&](Index m) { return constants(groups_.k[m], groups_.c[m]); }, equal);
      } else {
        const auto c = constants(hk_[q], hc_[q]);
        for (int a = 0; a < 4; ++a) e[1 + a] = c[a];
      }
      l0[q] = static_cast<T>(e[0]);
      kx[q] = static_cast<T>(e[1]);
      kv[q] = static_cast<T>(e[2]);
      if (pos) {
        ex[q] = static_cast<T>(e[3]);
        ev[q] = static_cast<T>(e[4]);
      }
    }
    cuda::upload(l0, l0_);
    cuda::upload(kx, kx_);
    cuda::upload(kv, kv_);
    cuda::upload(ex, ex_);
    cuda::upload(ev, ev_);
    h_ = h;
  }

  template <HoVariantD V>
  void run(Scene& scene, double hd) {
    const T h = static_cast<T>(hd);
    const Index S = static_cast<Index>(hi_.size());
    parallel_for(S, HoSpringKernel<T, V>{raw(si_), raw(sj_), raw(l0_), raw(kx_), raw(kv_), raw(ex_), raw(ev_),
                                          raw(ds_.x), raw(ds_.v), raw(G_), raw(P_)});
    parallel_for(ds_.n, HoVertexKernel<T, V>{raw(inc_ptr_), raw(inc_spring_), raw(inc_sign_), raw(ds_.w), raw(G_),
                                              raw(P_), raw(ds_.x), raw(ds_.v), h, h * h / T(2),
                                              static_cast<T>(scene.gravity[0]), static_cast<T>(scene.gravity[1]),
                                              static_cast<T>(scene.gravity[2])});
  }

  HoVariantD variant_;
  int sync_every_ = 1;
  bool merge_ = true;
  SpringPairGroups groups_;   // merge_springs: the merged groups' members (host)
  DeviceState<T> ds_;
  HostMirror<T> mirror_;  // the host copy of x and v against ds_ (lazy copy, device guard)
  DeviceColliders<T> colliders_;
  std::vector<Index> hi_, hj_;
  std::vector<double> hk_, hc_, hl0_;
  DVec<Index> si_, sj_, inc_ptr_, inc_spring_;
  DVec<signed char> inc_sign_;
  DVec<T> l0_, kx_, kv_, ex_, ev_, G_, P_;
  double h_ = -1;
};

// ======================= rk4 =======================

template <class T>
struct Rk4Stage {  // stage 1 (kind 0), 2-3 (kind 1, next = h/2 or h), 4 (kind 2)
  int kind;
  const T *w, *f;
  T *x, *v, *xs, *vs, *ax, *av;
  T g0, g1, g2, next, h;
  LOOM_HD void operator()(Index i) const {
    const T g[3] = {g0, g1, g2};
    for (int a = 0; a < 3; ++a) {
      const long long d = 3LL * i + a;
      const T acc = kernels::rk4_accel(f[d], w[i], g[a]);
      if (kind == 0)
        kernels::rk4_first(x[d], v[d], acc, xs[d], vs[d], ax[d], av[d], next);
      else if (kind == 1)
        kernels::rk4_middle(x[d], v[d], acc, xs[d], vs[d], ax[d], av[d], next);
      else
        kernels::rk4_last(x[d], v[d], acc, vs[d], ax[d], av[d], h);
    }
  }
};

template <class T>
class CudaRk4 final : public Integrator {
 public:
  CudaRk4(int sync_every, bool merge) : sync_every_(sync_every), merge_(merge) {}
  std::string name() const override { return "rk4"; }
  bool handles_contacts() const override { return true; }  // on the device
  void sync_to_host(Scene& scene) override { mirror_.sync(ds_, scene.state); }
  Index first_unguarded_vertex(double vmax2) override { return mirror_.first_unguarded(ds_, vmax2); }
  void prepare(Scene& scene, double) override {
    mirror_.sync(ds_, scene.state);  // a repeated prepare uploads the current state, not a stale host copy
    check_device_scene(scene, "rk4", true);
    require_device_memory(explicit_bytes<T>(scene, 9), scene.source, "rk4");
    colliders_.prepare(scene);
    if (!scene.material) throw InputError(scene.source + ": rk4 needs a material; add a 'material:' section");
    model_.build(scene, nullptr, merge_);   // key merge_springs
    ds_.upload(scene.state);
    mirror_.stale = false;
    const std::size_t m = 3 * static_cast<std::size_t>(ds_.n);
    xs_.assign(m, T(0));
    vs_.assign(m, T(0));
    f_.assign(m, T(0));
    ax_.assign(m, T(0));
    av_.assign(m, T(0));
    stats_ = {};
    stats_.force_evaluations = 4;
  }
  void step(Scene& scene, double hd) override {
    if (ds_.n != scene.state.size()) prepare(scene, hd);
    const T h = static_cast<T>(hd), hh = T(0.5) * h;
    const T g0 = static_cast<T>(scene.gravity[0]), g1 = static_cast<T>(scene.gravity[1]),
            g2 = static_cast<T>(scene.gravity[2]);
    auto stage = [&](int kind, T next) {
      parallel_for(ds_.n, Rk4Stage<T>{kind, raw(ds_.w), raw(f_), raw(ds_.x), raw(ds_.v), raw(xs_), raw(vs_), raw(ax_),
                                      raw(av_), g0, g1, g2, next, h});
    };
    model_.forces(ds_.x, ds_.v, f_);
    stage(0, hh);
    model_.forces(xs_, vs_, f_);
    stage(1, hh);
    model_.forces(xs_, vs_, f_);
    stage(1, h);
    model_.forces(xs_, vs_, f_);
    stage(2, h);
    if (colliders_.active()) colliders_.resolve(ds_, scene.state.time + hd, hd);
    mirror_.after_step(ds_, scene.state, sync_every_);
    finish_step(scene.state, hd);
  }
  StepStats last_step() const override { return stats_; }

 private:
  int sync_every_ = 1;
  bool merge_ = true;
  DeviceState<T> ds_;
  HostMirror<T> mirror_;  // the host copy of x and v against ds_ (lazy copy, device guard)
  DeviceColliders<T> colliders_;
  DeviceForceModel<T> model_;
  DVec<T> xs_, vs_, f_, ax_, av_;
  StepStats stats_;
};

// ======================= symplectic_euler =======================

template <class T>
struct SeVertexKernel {  // per vertex: the CPU plugin's update, one source (symplectic_euler/se_update.hpp)
  const T *w, *f;
  T *x, *v;
  T h, g0, g1, g2;
  LOOM_HD void operator()(Index i) const {
    const long long d = 3LL * i;
    symplectic_euler::se_update_vertex(x + d, v + d, f + d, w[i], h, g0, g1, g2);
  }
};

/// symplectic_euler on the device: forces from the device force model (any material with a
/// device description: springs, GNATV triangles, hinges; else the host fallback), then the
/// per-vertex update, then sphere, plane and mesh contacts at t + h (what Simulation::step does after the
/// CPU plugin's step). One force evaluation per step.
template <class T>
class CudaSe final : public Integrator {
 public:
  CudaSe(int sync_every, bool merge) : sync_every_(sync_every), merge_(merge) {}
  std::string name() const override { return "symplectic_euler"; }
  bool handles_contacts() const override { return true; }  // on the device
  void sync_to_host(Scene& scene) override { mirror_.sync(ds_, scene.state); }
  Index first_unguarded_vertex(double vmax2) override { return mirror_.first_unguarded(ds_, vmax2); }
  void prepare(Scene& scene, double h) override {
    mirror_.sync(ds_, scene.state);  // a repeated prepare uploads the current state, not a stale host copy
    check_device_scene(scene, "symplectic_euler", true);
    if (!scene.material)
      throw InputError(scene.source + ": symplectic_euler needs a material; add a material: section to the scene");
    if (!(h > 0)) throw InputError(scene.source + ": symplectic_euler needs dt > 0");
    require_device_memory(explicit_bytes<T>(scene, 1), scene.source, "symplectic_euler");
    colliders_.prepare(scene);
    model_.build(scene, nullptr, merge_);   // key merge_springs
    ds_.upload(scene.state);
    mirror_.stale = false;
    f_.assign(3 * static_cast<std::size_t>(ds_.n), T(0));
    stats_ = {};
    stats_.force_evaluations = 1;
  }
  void step(Scene& scene, double hd) override {
    if (ds_.n != scene.state.size()) prepare(scene, hd);
    model_.forces(ds_.x, ds_.v, f_);
    parallel_for(ds_.n, SeVertexKernel<T>{raw(ds_.w), raw(f_), raw(ds_.x), raw(ds_.v), static_cast<T>(hd),
                                          static_cast<T>(scene.gravity[0]), static_cast<T>(scene.gravity[1]),
                                          static_cast<T>(scene.gravity[2])});
    if (colliders_.active()) colliders_.resolve(ds_, scene.state.time + hd, hd);
    mirror_.after_step(ds_, scene.state, sync_every_);
    finish_step(scene.state, hd);
  }
  StepStats last_step() const override { return stats_; }
  /// The force model's kind (Device, or Host for a material without a device description).
  ForceModelKind force_model() const { return model_.kind(); }

 private:
  int sync_every_ = 1;
  bool merge_ = true;
  DeviceState<T> ds_;
  HostMirror<T> mirror_;  // the host copy of x and v against ds_ (lazy copy, device guard)
  DeviceColliders<T> colliders_;
  DeviceForceModel<T> model_;
  DVec<T> f_;
  StepStats stats_;
};

// ======================= baraff_witkin =======================

// BwAssemble: one block row of A and b, shared with the CPU plugin (loom/kernels/bw_assembly.hpp).
using kernels::BwAssemble;

template <class T>
struct PinPrescribed {  // z = -v0 on the pinned vertices (fixed pins)
  const Index* pins;
  const T* v;
  T* z;
  LOOM_HD void operator()(Index k) const {
    const long long o = 3LL * pins[k];
    z[o] = -v[o];
    z[o + 1] = -v[o + 1];
    z[o + 2] = -v[o + 2];
  }
};

template <class T>
struct BwUpdate {
  const T* dv;
  T *x, *v;
  T h;
  LOOM_HD void operator()(Index d) const {
    v[d] += dv[d];
    x[d] += h * v[d];
  }
};

// ---- Baraff-Witkin contacts on the device: the rules of the CPU plugin (BaraffWitkin::
// set_constraints, release_pulling_contacts, apply_friction, stop_landed, project_positions in
// plugins/integrators/baraff_witkin/baraff_witkin.cpp), one thread per vertex, one contact per
// vertex (the deepest collider), at most kMaxDeviceColliders sphere, plane or mesh colliders.
// Contact flags: 0 none, 1 in contact (friction acts), 2 landing during the step (no friction).

/// Matches BaraffWitkin::kContactTolerance.
constexpr double kDeviceContactTolerance = 1e-9;
/// Matches BaraffWitkin::kQueryCutoff: the constraint queries are exact below this distance (a
/// mesh skips its far parts), and asked again exactly for the start distance of a vertex
/// predicted to land.
constexpr double kDeviceQueryCutoff = 1e-6;

template <class T>
struct BwConstraintKernel {  // S_i, z_i and the contact of vertex i; returns 1 for a collider contact
  DeviceShape<T> s0[kMaxDeviceColliders], s1[kMaxDeviceColliders];  // at the step start / end
  int count;
  const std::uint8_t* pinned;
  const std::uint8_t* in_contact;
  const T *x, *v, *f, *w;
  T g0, g1, g2, h, tol;
  unsigned char* free;
  T* proj;
  T* z;
  std::uint8_t* flag;
  T *normal, *sv, *mus, *muk, *dvn;
  LOOM_HD int operator()(Index i) const {
    const long long o = 3LL * i;
    T* P = proj + 9LL * i;
    for (int e = 0; e < 9; ++e) P[e] = T(0);
    flag[i] = 0;
    if (pinned[i]) {  // fixed pins: dv = -v0 (moving pins are refused on the device)
      free[i] = 0;
      for (int k = 0; k < 3; ++k) z[o + k] = -v[o + k];
      return 0;
    }
    free[i] = 3;
    P[0] = P[4] = P[8] = T(1);
    z[o] = z[o + 1] = z[o + 2] = T(0);
    if (count == 0) return 0;
    const T* xi = x + o;
    const T* vi = v + o;
    const T g[3] = {g0, g1, g2};
    T vp[3], xp[3];
    for (int k = 0; k < 3; ++k) {
      vp[k] = vi[k] + h * (w[i] * f[o + k] + g[k]);
      xp[k] = xi[k] + h * vp[k];
    }
    int best = -1;
    T depth = T(0), bd = T(0), bn[3] = {T(0), T(0), T(0)}, bv[3] = {T(0), T(0), T(0)};
    for (int c = 0; c < count; ++c) {
      T n0[3], v0[3], n1[3], v1[3];
      T d0 = device_query(s0[c], xi, kDeviceQueryCutoff, n0, v0);
      const T d1 = device_query(s1[c], xp, kDeviceQueryCutoff, n1, v1);
      const T band = static_cast<T>(kDeviceContactTolerance);  // as BaraffWitkin::set_constraints
      if (d1 <= band && d0 >= static_cast<T>(kDeviceQueryCutoff)) d0 = device_query(s0[c], xi, INFINITY, n0, v0);
      const T d = d0 < d1 ? d0 : d1;
      if (d <= band && (best < 0 || d < depth)) {
        best = c;
        const bool next = d1 < d0;
        for (int k = 0; k < 3; ++k) {
          bn[k] = next ? n1[k] : n0[k];
          bv[k] = next ? v1[k] : v0[k];
        }
        bd = d0;
        depth = d;
      }
    }
    if (best < 0) return 0;
    const T vn = kernels::dot3(vi, bn);
    const T vpn = kernels::dot3(vp, bn);
    const T sn = kernels::dot3(bv, bn);
    const T target = sn - bd / h;  // normal velocity that ends the step on the surface
    if (vpn > target) return 0;    // does not reach the surface within the step
    // Filter::constrain_direction on a free vertex: S_i = I - p p^T, p = n / |n|.
    using std::sqrt;
    const T len = sqrt(kernels::dot3(bn, bn));
    T p[3];
    for (int k = 0; k < 3; ++k) p[k] = bn[k] / len;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) P[3 * r + c] -= p[r] * p[c];
    free[i] = 2;
    const T d = target - vn;
    for (int k = 0; k < 3; ++k) {
      z[o + k] = d * bn[k];
      normal[o + k] = bn[k];
      sv[o + k] = bv[k];
    }
    dvn[i] = d;
    mus[i] = s0[best].s.mu_static;
    muk[i] = s0[best].s.mu_kinetic;
    flag[i] = (bd > tol && !in_contact[i]) ? 2 : 1;
    return 1;
  }
};

template <class T>
struct BwReleaseKernel {  // impulse (A dv - b).n of a contact; a pulling one (< 0) is released; returns 1 then
  const Index *row_ptr, *col;
  const T *a, *dv, *b, *normal;
  std::uint8_t* flag;
  unsigned char* free;
  T *proj, *z, *impulse;
  LOOM_HD int operator()(Index i) const {
    if (!flag[i]) return 0;
    T r[3] = {T(0), T(0), T(0)};
    for (Index k = row_ptr[i]; k < row_ptr[i + 1]; ++k) kernels::mat3_mul_add(a + 9LL * k, dv + 3LL * col[k], r);
    const long long o = 3LL * i;
    const T imp = (r[0] - b[o]) * normal[o] + (r[1] - b[o + 1]) * normal[o + 1] + (r[2] - b[o + 2]) * normal[o + 2];
    impulse[i] = imp;
    if (!(imp < T(0))) return 0;
    flag[i] = 0;
    free[i] = 3;
    T* P = proj + 9LL * i;
    for (int e = 0; e < 9; ++e) P[e] = (e % 4 == 0) ? T(1) : T(0);
    z[o] = z[o + 1] = z[o + 2] = T(0);
    return 1;
  }
};

template <class T>
struct BwFrictionKernel {  // Coulomb friction as a velocity correction (contacts, not landings)
  const std::uint8_t* flag;
  const T *v, *w, *normal, *sv, *mus, *muk, *impulse;
  T* dv;
  LOOM_HD void operator()(Index i) const {
    if (flag[i] != 1 || (mus[i] <= T(0) && muk[i] <= T(0))) return;
    const long long o = 3LL * i;
    const T imp = impulse[i] > T(0) ? impulse[i] : T(0);
    const T j = imp * w[i];
    T vrel[3];
    for (int k = 0; k < 3; ++k) vrel[k] = v[o + k] + dv[o + k] - sv[o + k];
    const T vn = kernels::dot3(vrel, normal + o);
    T vt[3];
    for (int k = 0; k < 3; ++k) vt[k] = vrel[k] - vn * normal[o + k];
    using std::sqrt;
    const T len = sqrt(kernels::dot3(vt, vt));
    T keep = T(1);
    if (len <= mus[i] * j) {
      keep = T(0);
    } else if (len > T(0)) {
      const T kk = T(1) - muk[i] * j / len;
      keep = kk > T(0) ? kk : T(0);
    }
    for (int k = 0; k < 3; ++k) dv[o + k] -= (T(1) - keep) * vt[k];
  }
};

// Coulomb friction inside the solve (the CPU's implicit_friction rule, loom/kernels/friction.hpp):
// one thread per vertex adds, corrects or finishes the tangential damper of its contact; the
// damper lives in the vertex's own diagonal block and right-hand side, so threads never share
// a write.
template <class T>
struct BwFrictionDamperKernel {
  int mode;  // 0 the first damper (returns 1 where one was added), 1 a correction (1 where changed), 2 the finish
  const std::uint8_t* flag;
  const Index* diag;
  const T *v, *mass, *normal, *sv, *mus, *muk, *impulse;
  T *a, *b, *dv, *hc, *len0;
  T* warm;  // the response of the vertex's contact in the last step (0: none), as the CPU's warm_D_
  std::uint8_t* stick;  // 1 held, 0 sliding, 2 sliding after being let go (ColliderFrictionState::released)
  LOOM_HD int operator()(Index i) const {
    const long long o = 3LL * i;
    kernels::ColliderFrictionState<T> fs;
    if (mode == 0) {
      bool any = false;
      if (flag[i] == 1)
        any = kernels::start_collider_friction(v + o, dv + o, sv + o, normal + o, warm[i] > T(0) ? warm[i] : mass[i],
                                               mus[i], muk[i], impulse[i], a + 9LL * diag[i], b + o, fs);
      warm[i] = T(0);  // set again by the finish
      hc[i] = fs.hc;
      len0[i] = fs.len0;
      stick[i] = fs.stick ? 1 : 0;
      return any ? 1 : 0;
    }
    if (hc[i] == T(0)) return 0;
    fs.hc = hc[i];
    fs.len0 = len0[i];
    fs.stick = stick[i] == 1;
    fs.released = stick[i] == 2;
    if (mode == 2) {
      warm[i] = kernels::collider_friction_response(v + o, dv + o, sv + o, normal + o, mass[i], fs);
      kernels::finish_collider_friction(v + o, dv + o, sv + o, normal + o, fs);
      return 0;
    }
    if (!kernels::correct_collider_friction(v + o, dv + o, sv + o, normal + o, mass[i], mus[i], muk[i], impulse[i],
                                            a + 9LL * diag[i], b + o, fs))
      return 0;
    hc[i] = fs.hc;
    stick[i] = fs.stick ? 1 : (fs.released ? 2 : 0);
    return 1;
  }
};

// The contacts' friction against their Coulomb bounds after a solve (the CPU's
// BaraffWitkin::collider_friction_tally): part 0 the misses, 1 the kinetic bounds mu_k J, summed
// by reduce_sum.
template <class T>
struct BwFrictionMissKernel {
  int part;
  const T *v, *dv, *normal, *sv, *mus, *muk, *impulse, *hc;
  const std::uint8_t* stick;
  LOOM_HD T operator()(Index i) const {
    if (hc[i] == T(0)) return T(0);
    const long long o = 3LL * i;
    kernels::ColliderFrictionState<T> fs;
    fs.hc = hc[i];
    fs.stick = stick[i] == 1;
    T excess, bound;
    const T miss = kernels::collider_friction_miss(v + o, dv + o, sv + o, normal + o, mus[i], muk[i], impulse[i], fs,
                                                   excess, bound);
    return part == 0 ? miss : bound;
  }
};

template <class T>
struct BwFinishContactsKernel {  // landed vertices stop their approach; in_contact for the next step
  const std::uint8_t* flag;
  const T *normal, *sv;
  T* v;
  std::uint8_t* in_contact;
  LOOM_HD void operator()(Index i) const {
    in_contact[i] = flag[i] ? 1 : 0;
    if (flag[i] != 2) return;
    const long long o = 3LL * i;
    T* vi = v + o;
    const T rel = (vi[0] - sv[o]) * normal[o] + (vi[1] - sv[o + 1]) * normal[o + 1] + (vi[2] - sv[o + 2]) * normal[o + 2];
    if (rel < T(0))
      for (int k = 0; k < 3; ++k) vi[k] -= rel * normal[o + k];
  }
};

template <class T>
struct BwProjectKernel {  // residual penetration after the step: positions onto the offset surfaces
  DeviceShape<T> s1[kMaxDeviceColliders];
  int count;
  const std::uint8_t* pinned;
  T* x;
  LOOM_HD void operator()(Index i) const {
    if (pinned[i]) return;
    T* xi = x + 3LL * i;
    for (int c = 0; c < count; ++c) {
      T n[3], vs[3];
      const T d = device_query(s1[c], xi, 0.0, n, vs);  // exact where < 0
      if (d < T(0))
        for (int k = 0; k < 3; ++k) xi[k] -= d * n[k];
    }
  }
};

template <class T>
class CudaBw final : public Integrator {
 public:
  explicit CudaBw(BwOptionsD o) : opt_(o) {}
  std::string name() const override { return "baraff_witkin"; }
  IntegratorNeeds needs() const override { return {false, true, true}; }
  /// Sphere, plane and mesh contacts are constraints of the solve (the framework must not resolve
  /// them again on the host).
  bool handles_contacts() const override { return true; }
  void sync_to_host(Scene& scene) override { mirror_.sync(ds_, scene.state); }
  Index first_unguarded_vertex(double vmax2) override { return mirror_.first_unguarded(ds_, vmax2); }

  void prepare(Scene& scene, double h) override {
    mirror_.sync(ds_, scene.state);  // a repeated prepare uploads the current state, not a stale host copy
    check_device_scene(scene, "baraff_witkin", true);
    if (!(h > 0) || !std::isfinite(h))
      throw InputError("baraff_witkin: the time step must be positive and finite; set integrator.dt");
    if (!scene.material || !scene.material->has_jacobian())
      throw InputError(scene.source + ": baraff_witkin needs a material with force Jacobians (mass_spring, gnatv)");
    const auto* solver = dynamic_cast<const CusparsePcg*>(scene.solver.get());
    if (!solver)
      throw InputError(scene.source + ": baraff_witkin on backend cuda solves on the device with filtered_pcg, but the "
                       "scene's solver is '" + (scene.solver ? scene.solver->name() : std::string("none")) +
                       "'. Fix: set solver: {type: filtered_pcg} (or backend: cpu for the CPU solvers).");
    pcg_ = DevicePcg<double, T>(solver->options());
    pcg_.set_name(solver->name());
    State& s = scene.state;
    const Index n = s.size();
    std::vector<std::array<Index, 2>> pairs;
    scene.material->jacobian_pairs(pairs);
    for (const auto& pr : pairs)
      if (pr[0] < 0 || pr[1] < 0 || pr[0] >= n || pr[1] >= n)
        throw InputError("baraff_witkin: material '" + scene.material->name() + "' reported a Jacobian pair outside the mesh");
    pattern_ = std::make_unique<BsrPattern>(BsrPattern::from_pairs(n, pairs));
    {  // the device arrays below, before any is allocated
      const std::size_t nb = static_cast<std::size_t>(pattern_->nnz_blocks()), nv = static_cast<std::size_t>(n);
      const std::size_t bytes = sizeof(T) * (27 * nb + 18 * nv + 3 * nv * 12 + 10 * nv) +
                                sizeof(Index) * (2 * nb + 3 * nv) + explicit_bytes<T>(scene, 0);
      require_device_memory(bytes, scene.source, "baraff_witkin (" + std::to_string(n) + " vertices, " +
                                                     std::to_string(nb) + " matrix blocks)");
    }
    scene.material->bind_pattern(*pattern_);
    model_.build(scene, pattern_.get());
    A_.set_pattern(*pattern_);
    dfdx_ = A_.values;
    dfdv_ = A_.values;
    std::vector<double> degree(n);
    for (Index i = 0; i < n; ++i) degree[i] = static_cast<double>(pattern_->row_ptr[i + 1] - pattern_->row_ptr[i] - 1);
    cuda::upload(degree, degree_);
    const std::size_t N = 3 * static_cast<std::size_t>(n);
    f_.assign(N, T(0));
    b_.assign(N, T(0));
    z_.assign(N, T(0));
    dv_.assign(N, T(0));
    if constexpr (!std::is_same_v<T, double>) {   // the mixed-precision solve's double vectors
      bd_.assign(N, 0.0);
      zd_.assign(N, 0.0);
      dvd_.assign(N, 0.0);
    }
    Filter S;
    S.reset(n);
    for (Index i : s.pin_list) S.constrain_all(i);
    S_.upload(S);
    cuda::upload(s.pin_list, pins_);
    pcg_.analyze(n);
    ds_.upload(s);
    mirror_.stale = false;
    // Sphere, plane and mesh colliders: contacts are constraints of the solve, as on the CPU.
    colliders_ = scene.colliders.empty() ? nullptr : &scene.colliders;
    if (colliders_) {
      meshes_.prepare(scene.colliders);
      cuda::upload(s.pinned, pinned_);
      in_contact_.assign(n, 0);
      flag_.assign(n, 0);
      cnormal_.assign(N, T(0));
      csv_.assign(N, T(0));
      cmus_.assign(n, T(0));
      cmuk_.assign(n, T(0));
      cdvn_.assign(n, T(0));
      cimpulse_.assign(n, T(0));
      chc_.assign(n, T(0));
      clen0_.assign(n, T(0));
      cwarm_.assign(n, T(0));
      cstick_.assign(n, 0);
      S_.resize(n);
    }
    last_ = {};
  }

  void step(Scene& scene, double h) override {
    if (ds_.n != scene.state.size() || !pattern_) prepare(scene, h);
    StepStats st;
    t0_ = scene.state.time;
    advance(scene, h, 0, st);
    mirror_.after_step(ds_, scene.state, opt_.host_sync_every);
    finish_step(scene.state, h);
    last_ = st;
  }
  StepStats last_step() const override { return last_; }

 private:
  // The operations of the shared step skeleton (plugins/integrators/baraff_witkin/bw_step.hpp),
  // the same attempt and retry policy as the CPU plugin, on device data.
  struct StepOps {
    CudaBw& bw;
    Scene& scene;
    int contacts = 0;
    void forces() { bw.model_.forces(bw.ds_.x, bw.ds_.v, bw.f_); }
    void assemble(double hd) {
      bw.model_.jacobians(bw.ds_.x, bw.ds_.v, bw.dfdx_, &bw.dfdv_);
      const T h = static_cast<T>(hd);
      const double alpha = bw.opt_.rayleigh_alpha, beta = bw.opt_.rayleigh_beta, cd = bw.opt_.kang_cho_damping;
      parallel_for(bw.ds_.n,
                   BwAssemble<T>{raw(bw.A_.row_ptr), raw(bw.A_.col), raw(bw.dfdx_), raw(bw.dfdv_), raw(bw.ds_.v),
                                 raw(bw.f_), raw(bw.ds_.mass), raw(bw.degree_), raw(bw.A_.values), raw(bw.b_), h,
                                 static_cast<T>(1.0 + hd * alpha), static_cast<T>(hd * hd + hd * beta),
                                 static_cast<T>(hd + beta), static_cast<T>(hd * cd), static_cast<T>(alpha),
                                 static_cast<T>(cd), static_cast<T>(scene.gravity[0]), static_cast<T>(scene.gravity[1]),
                                 static_cast<T>(scene.gravity[2])});
    }
    int set_constraints(double hd) {
      contacts = 0;
      if (bw.colliders_)
        contacts = bw.set_contact_constraints(scene, hd);
      else
        parallel_for(static_cast<Index>(bw.pins_.size()), PinPrescribed<T>{raw(bw.pins_), raw(bw.ds_.v), raw(bw.z_)});
      return contacts;
    }
    bool factorize(SolveReport& rep) { return bw.pcg_.factorize(bw.A_, bw.S_, rep); }
    SolveReport solve() {
      if constexpr (std::is_same_v<T, double>) {
        return bw.pcg_.solve(bw.A_, bw.S_, bw.b_, bw.z_, bw.dv_);
      } else {
        // precision: float: the system (A, S, b, z) as assembled in float, solved by CG in double
        // (float vectors stall above the tolerance: their rounding floor), dv rounded back.
        const Index N = 3 * bw.ds_.n;
        parallel_for(N, ConvertKernel<T, double>{raw(bw.b_), raw(bw.bd_)});
        parallel_for(N, ConvertKernel<T, double>{raw(bw.z_), raw(bw.zd_)});
        parallel_for(N, ConvertKernel<T, double>{raw(bw.dv_), raw(bw.dvd_)});
        SolveReport rep = bw.pcg_.solve(bw.A_, bw.S_, bw.bd_, bw.zd_, bw.dvd_);
        parallel_for(N, ConvertKernel<double, T>{raw(bw.dvd_), raw(bw.dv_)});
        return rep;
      }
    }
    void zero_dv() { fill(bw.dv_, T(0)); }
    bool release_pulling_contacts(double) { return bw.release_pulling_contacts(); }
    // No self-contact on the device; with implicit_friction (default) the contacts' dampers join
    // A and b and bw::friction_solves solves, corrects and solves again, as on the CPU.
    template <class F>
    bool extra_solves(bool ok, double, F&& solve_once) {
      if (!ok || contacts == 0 || !bw.opt_.implicit_friction) return ok;
      if (bw.friction_dampers(0) == 0) return ok;
      long long solves = 0;
      // Corrected while the contacts miss their bounds, in sum, by more than
      // kernels::kFrictionStopTolerance of the bounds' sum (as on the CPU).
      return bw::friction_solves(
          solve_once, [&] { return !bw.friction_settled() && bw.friction_dampers(1) > 0; },
          [&] { bw.friction_dampers(2); },
          [&](double k) {
            bw.pcg_.set_tolerance_scale(k);
            return true;
          },
          solves);
    }
    void after_solve(double) {
      if (contacts > 0 && !bw.opt_.implicit_friction)
        parallel_for(bw.ds_.n, BwFrictionKernel<T>{raw(bw.flag_), raw(bw.ds_.v), raw(bw.ds_.w), raw(bw.cnormal_),
                                                    raw(bw.csv_), raw(bw.cmus_), raw(bw.cmuk_), raw(bw.cimpulse_),
                                                    raw(bw.dv_)});
    }
    void update(double hd) {
      parallel_for(3 * bw.ds_.n, BwUpdate<T>{raw(bw.dv_), raw(bw.ds_.x), raw(bw.ds_.v), static_cast<T>(hd)});
    }
    void after_update(double hd) {
      if (!bw.colliders_) return;
      parallel_for(bw.ds_.n, BwFinishContactsKernel<T>{raw(bw.flag_), raw(bw.cnormal_), raw(bw.csv_), raw(bw.ds_.v),
                                                       raw(bw.in_contact_)});
      BwProjectKernel<T> pk{};
      pk.count = fill_device_shapes(*bw.colliders_, bw.meshes_, bw.t0_ + hd, pk.s1);
      pk.pinned = raw(bw.pinned_);
      pk.x = raw(bw.ds_.x);
      parallel_for(bw.ds_.n, pk);
    }
    double& start_time() { return bw.t0_; }
    bool warm_start() const { return bw.opt_.warm_start; }
    bool halve_on_failure() const { return bw.opt_.halve_on_failure; }
    int max_halvings() const { return bw.opt_.max_halvings; }
  };

  // The filter, z and the collider contacts of this (sub)step, from the state at its start
  // t0_ and the explicit prediction to t0_ + h; returns the number of contacts.
  int set_contact_constraints(const Scene& scene, double hd) {
    BwConstraintKernel<T> k{};
    k.count = fill_device_shapes(*colliders_, meshes_, t0_, k.s0);
    fill_device_shapes(*colliders_, meshes_, t0_ + hd, k.s1);
    k.pinned = raw(pinned_);
    k.in_contact = raw(in_contact_);
    k.x = raw(ds_.x);
    k.v = raw(ds_.v);
    k.f = raw(f_);
    k.w = raw(ds_.w);
    k.g0 = static_cast<T>(scene.gravity[0]);
    k.g1 = static_cast<T>(scene.gravity[1]);
    k.g2 = static_cast<T>(scene.gravity[2]);
    k.h = static_cast<T>(hd);
    k.tol = static_cast<T>(kDeviceContactTolerance);
    k.free = raw(S_.free);
    k.proj = raw(S_.proj);
    k.z = raw(z_);
    k.flag = raw(flag_);
    k.normal = raw(cnormal_);
    k.sv = raw(csv_);
    k.mus = raw(cmus_);
    k.muk = raw(cmuk_);
    k.dvn = raw(cdvn_);
    const int contacts = reduce_sum<int>(ds_.n, k);
    S_.rebuild_constrained();
    return contacts;
  }

  // The friction dampers of the contacts (BwFrictionDamperKernel's mode); the number of
  // vertices that got or changed one.
  int friction_dampers(int mode) {
    return reduce_sum<int>(ds_.n, BwFrictionDamperKernel<T>{mode, raw(flag_), raw(A_.diag), raw(ds_.v), raw(ds_.mass),
                                                            raw(cnormal_), raw(csv_), raw(cmus_), raw(cmuk_),
                                                            raw(cimpulse_), raw(A_.values), raw(b_), raw(dv_),
                                                            raw(chc_), raw(clen0_), raw(cwarm_), raw(cstick_)});
  }

  // Whether the contacts' friction is close enough to Coulomb's bounds to stop correcting
  // (kernels::FrictionTally::settled).
  bool friction_settled() {
    kernels::FrictionTally<T> t;
    auto part = [&](int k) {
      return reduce_sum<T>(ds_.n, BwFrictionMissKernel<T>{k, raw(ds_.v), raw(dv_), raw(cnormal_), raw(csv_), raw(cmus_),
                                                           raw(cmuk_), raw(cimpulse_), raw(chc_), raw(cstick_)});
    };
    t.miss = part(0);
    t.bound = part(1);
    return t.settled();
  }

  // Releases the contacts whose impulse (A dv - b).n is negative; true when any was.
  bool release_pulling_contacts() {
    const int released = reduce_sum<int>(
        ds_.n, BwReleaseKernel<T>{raw(A_.row_ptr), raw(A_.col), raw(A_.values), raw(dv_), raw(b_), raw(cnormal_),
                                  raw(flag_), raw(S_.free), raw(S_.proj), raw(z_), raw(cimpulse_)});
    if (released == 0) return false;
    S_.rebuild_constrained();
    return true;
  }

  void advance(Scene& scene, double h, int depth, StepStats& st) {
    StepOps ops{*this, scene};
    bw::advance(ops, scene.state, h, depth, st, "baraff_witkin (cuda)");
  }

  BwOptionsD opt_;
  DeviceState<T> ds_;
  HostMirror<T> mirror_;  // the host copy of x and v against ds_ (lazy copy, device guard)
  DeviceForceModel<T> model_;
  std::unique_ptr<BsrPattern> pattern_;
  DeviceBsr<T> A_;
  DVec<T> dfdx_, dfdv_, degree_, f_, b_, z_, dv_;
  DVec<Index> pins_;
  DeviceFilter<T> S_;
  DevicePcg<double, T> pcg_;   // vectors in double for either precision (mixed with float: DevicePcg)
  DVec<double> bd_, zd_, dvd_;   // precision: float: b, z and dv in double for the solve
  const ColliderSet* colliders_ = nullptr;
  DeviceMeshes meshes_;
  DVec<std::uint8_t> pinned_, in_contact_, flag_, cstick_;
  DVec<T> cnormal_, csv_, cmus_, cmuk_, cdvn_, cimpulse_, chc_, clen0_, cwarm_;
  double t0_ = 0;  // start time of the (sub)step being solved
  StepStats last_;
};

/// The cpu plugin's reading of `variant` (one spec for both backends).
HoVariantD parse_variant(const Params& p) {
  const HoVariant v = read_ho_variant(p);
  return v == HoVariant::Velocity           ? HoVariantD::Velocity
         : v == HoVariant::AnalyticPosition ? HoVariantD::AnalyticPosition
                                            : HoVariantD::KangCho2011;
}

}  // namespace

std::unique_ptr<Integrator> make_cuda_ho(HoVariantD variant, Precision precision, int host_sync_every, bool merge) {
  if (precision == Precision::Float) return std::make_unique<CudaHo<float>>(variant, host_sync_every, merge);
  return std::make_unique<CudaHo<double>>(variant, host_sync_every, merge);
}
std::unique_ptr<Integrator> make_cuda_ho(const Params& p) {
  const bool merge = !p.valid() || ParamReader(p, harmonic_oscillation_spec()).flag("merge_springs");
  return make_cuda_ho(parse_variant(p), parse_precision(p), parse_sync_every(p), merge);
}

std::unique_ptr<Integrator> make_cuda_rk4(Precision precision, int host_sync_every, bool merge) {
  if (precision == Precision::Float) return std::make_unique<CudaRk4<float>>(host_sync_every, merge);
  return std::make_unique<CudaRk4<double>>(host_sync_every, merge);
}
std::unique_ptr<Integrator> make_cuda_rk4(const Params& p) {
  const bool merge = !p.valid() || ParamReader(p, rk4_spec()).flag("merge_springs");
  return make_cuda_rk4(parse_precision(p), parse_sync_every(p), merge);
}

std::unique_ptr<Integrator> make_cuda_symplectic_euler(Precision precision, int host_sync_every, bool merge) {
  if (precision == Precision::Float) return std::make_unique<CudaSe<float>>(host_sync_every, merge);
  return std::make_unique<CudaSe<double>>(host_sync_every, merge);
}
std::unique_ptr<Integrator> make_cuda_symplectic_euler(const Params& p) {
  // One spec (symplectic_euler::spec(), which appends the device keys); `reorder` is cpu only
  // and refused here by the spec's backends column.
  if (p.valid() && p.has("type")) p.mark_used("type");
  const bool merge = !p.valid() || ParamReader(p, symplectic_euler::spec()).flag("merge_springs");
  return make_cuda_symplectic_euler(parse_precision(p), parse_sync_every(p), merge);
}

std::unique_ptr<Integrator> make_cuda_baraff_witkin(const BwOptionsD& o, Precision precision) {
  if (precision == Precision::Float) return std::make_unique<CudaBw<float>>(o);
  return std::make_unique<CudaBw<double>>(o);
}
std::unique_ptr<Integrator> make_cuda_baraff_witkin(const Params& p) {
  // The keys both backends honour are read by the cpu plugin's parser (one spec, one struct).
  const BaraffWitkinOptions c = parse_baraff_witkin_options(p, "cuda");
  BwOptionsD o;
  o.kang_cho_damping = c.kang_cho_damping;
  o.rayleigh_alpha = c.rayleigh_alpha;
  o.rayleigh_beta = c.rayleigh_beta;
  o.halve_on_failure = c.on_failure == BaraffWitkinOptions::OnFailure::HalveStep;
  o.max_halvings = c.max_halvings;
  o.warm_start = c.warm_start;
  o.implicit_friction = c.implicit_friction;
  o.host_sync_every = parse_sync_every(p);
  return make_cuda_baraff_witkin(o, parse_precision(p));
}

}  // namespace loom::cuda
