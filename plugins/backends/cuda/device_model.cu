#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <stdexcept>

#include "device_model.hpp"
#include "loom/kernels/spring.hpp"

#ifdef LOOM_CUDA_WITH_MASS_SPRING
#include "mass_spring.hpp"
#endif
#ifdef LOOM_CUDA_WITH_GNATV
#include "gnatv_material.hpp"
#endif

namespace loom::cuda {

const char* to_string(ForceModelKind k) {
  switch (k) {
    case ForceModelKind::Springs: return "springs on device";
    case ForceModelKind::Gnatv: return "gnatv triangles on device";
    case ForceModelKind::Host: return "host material (copies per evaluation)";
  }
  return "?";
}

namespace {

// ---- springs: phase 1 per spring, phase 2 gather per vertex ----
template <class T>
struct SpringForce {
  const Index *I, *J;
  const T *L0, *K, *C, *x, *v;
  T* out;
  LOOM_HD void operator()(Index s) const {
    const long long a = 3LL * I[s], b = 3LL * J[s];
    T fi[3];
    kernels::spring_force_damped(x + a, x + b, v + a, v + b, K[s], L0[s], C[s], fi);
    out[3LL * s] = fi[0];
    out[3LL * s + 1] = fi[1];
    out[3LL * s + 2] = fi[2];
  }
};

template <class T>
struct GatherForce {
  const Index *ptr, *spring;
  const signed char* sign;
  const T* g;
  T* f;
  LOOM_HD void operator()(Index i) const {
    T a0 = T(0), a1 = T(0), a2 = T(0);
    for (Index e = ptr[i]; e < ptr[i + 1]; ++e) {
      const T* gs = g + 3LL * spring[e];
      if (sign[e] > 0) {
        a0 += gs[0]; a1 += gs[1]; a2 += gs[2];
      } else {
        a0 -= gs[0]; a1 -= gs[1]; a2 -= gs[2];
      }
    }
    f[3LL * i] = a0;
    f[3LL * i + 1] = a1;
    f[3LL * i + 2] = a2;
  }
};

template <class T>
struct SpringBlocks {
  const Index *I, *J;
  const T *L0, *K, *C, *x;
  bool clamp;
  T* kb;   // 9 per spring
  T* db;   // 9 per spring or null
  LOOM_HD void operator()(Index s) const {
    const long long a = 3LL * I[s], b = 3LL * J[s];
    kernels::spring_stiffness_block(x + a, x + b, K[s], L0[s], clamp, kb + 9LL * s);
    if (db) kernels::spring_damping_block(x + a, x + b, C[s], db + 9LL * s);
  }
};

// Row i: diagonal block -sum K_s, block (i, other) +K_s (blocks are symmetric).
template <class T>
struct GatherBlocks {
  const Index *row_ptr, *diag, *ptr, *spring, *block;
  const T* kb;
  T* A;
  LOOM_HD void operator()(Index i) const {
    for (long long q = 9LL * row_ptr[i]; q < 9LL * row_ptr[i + 1]; ++q) A[q] = T(0);
    T* D = A + 9LL * diag[i];
    for (Index e = ptr[i]; e < ptr[i + 1]; ++e) {
      const T* B = kb + 9LL * spring[e];
      T* O = A + 9LL * block[e];
      for (int q = 0; q < 9; ++q) {
        D[q] -= B[q];
        O[q] += B[q];
      }
    }
  }
};

// ---- gnatv: one launch per colour ----
template <class T>
struct GnatvForces {
  const Index* tri;
  const gnatv::RestTriangle<T>* rest;
  gnatv::Curves<T> curves;
  const T* x;
  T* f;
  LOOM_HD void operator()(Index t) const {
    const Index* tv = tri + 3LL * t;
    T P[3][3], F[3][3];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = x[3LL * tv[j] + k];
    gnatv::forces(rest[t], curves, P, F);
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) f[3LL * tv[j] + k] += F[j][k];
  }
};

template <class T>
struct GnatvJacobian {
  const Index *tri, *scatter;
  const gnatv::RestTriangle<T>* rest;
  gnatv::Curves<T> curves;
  bool psd;
  const T* x;
  T* A;
  LOOM_HD void operator()(Index t) const {
    const Index* tv = tri + 3LL * t;
    T P[3][3], J[3][3][9];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = x[3LL * tv[j] + k];
    gnatv::jacobian(rest[t], curves, P, psd, J);
    const Index* sc = scatter + 9LL * t;
    for (int b = 0; b < 9; ++b) {
      T* dst = A + 9LL * sc[b];
      const T* src = J[b / 3][b % 3];
      for (int q = 0; q < 9; ++q) dst[q] += src[q];
    }
  }
};

template <class T>
void warn_host_fallback(const std::string& name) {
  static bool once = false;
  if (once) return;
  once = true;
  std::fprintf(stderr,
               "loom: backend cuda: material '%s' has no device version; its forces are computed on the host "
               "(x, v and f are copied for every evaluation)\n",
               name.c_str());
}

}  // namespace

template <class T>
void DeviceForceModel<T>::build(const Scene& scene, const BsrPattern* pattern) {
  material_ = scene.material.get();
  if (!material_) throw InputError(scene.source + ": backend cuda: the scene has no material");
  n_ = scene.state.size();
  pattern_ = pattern;
  kind_ = ForceModelKind::Host;
#ifdef LOOM_CUDA_WITH_MASS_SPRING
  if (const auto* ms = dynamic_cast<const mass_spring::MassSpringMaterial*>(material_)) {
    kind_ = ForceModelKind::Springs;
    const SpringSet& s = *ms->springs();
    const Index S = s.size();
    clamp_ = ms->clamp_compressed();
    damped_ = false;
    for (double c : s.damping) damped_ = damped_ || c != 0.0;
    cuda::upload(s.i, si_);
    cuda::upload(s.j, sj_);
    cuda::upload(s.rest_length, l0_);
    cuda::upload(s.stiffness, k_);
    cuda::upload(s.damping, c_);
    // Incidence: vertex -> (spring, sign), springs in increasing order.
    std::vector<Index> ptr(n_ + 1, 0), sp(2 * static_cast<std::size_t>(S)), blk;
    std::vector<signed char> sg(2 * static_cast<std::size_t>(S));
    for (Index q = 0; q < S; ++q) {
      ptr[s.i[q] + 1]++;
      ptr[s.j[q] + 1]++;
    }
    for (Index i = 0; i < n_; ++i) ptr[i + 1] += ptr[i];
    std::vector<Index> fillp(ptr.begin(), ptr.end() - 1);
    for (Index q = 0; q < S; ++q) {
      sp[fillp[s.i[q]]] = q;
      sg[fillp[s.i[q]]++] = 1;
      sp[fillp[s.j[q]]] = q;
      sg[fillp[s.j[q]]++] = -1;
    }
    if (pattern) {
      blk.resize(sp.size());
      for (Index i = 0; i < n_; ++i)
        for (Index e = ptr[i]; e < ptr[i + 1]; ++e) {
          const Index q = sp[e];
          const Index other = sg[e] > 0 ? s.j[q] : s.i[q];
          blk[e] = pattern->find(i, other);
          if (blk[e] < 0) throw std::logic_error("backend cuda: a spring is missing from the Jacobian pattern");
        }
      cuda::upload(blk, inc_block_);
      cuda::upload(pattern->row_ptr, pat_row_ptr_);
      cuda::upload(pattern->diag, pat_diag_);
      per_spring_d_.assign(damped_ ? 9 * static_cast<std::size_t>(S) : 0, T(0));
    }
    cuda::upload(ptr, inc_ptr_);
    cuda::upload(sp, inc_spring_);
    cuda::upload(sg, inc_sign_);
    per_spring_.assign((pattern ? 9 : 3) * static_cast<std::size_t>(S), T(0));
    return;
  }
#endif
#ifdef LOOM_CUDA_WITH_GNATV
  if (const auto* gm = dynamic_cast<const gnatv::GnatvMaterial*>(material_)) {
    kind_ = ForceModelKind::Gnatv;
    psd_ = gm->psd_projection();
    // Own greedy vertex colouring (triangles of one colour share no vertex), independent of
    // the material's internal execution order: triangles stored colour by colour.
    const auto& all = gm->triangles();
    const Index nt = static_cast<Index>(all.size());
    std::vector<std::uint64_t> used(n_, 0);
    std::vector<int> colour(nt);
    int ncol = 0;
    for (Index t = 0; t < nt; ++t) {
      const std::uint64_t busy = used[all[t][0]] | used[all[t][1]] | used[all[t][2]];
      int c = 0;
      while (c < 64 && (busy >> c) & 1u) ++c;
      if (c == 64) throw std::logic_error("backend cuda: more than 64 triangle colours (a vertex in > 63 triangles)");
      colour[t] = c;
      ncol = std::max(ncol, c + 1);
      for (int a = 0; a < 3; ++a) used[all[t][a]] |= std::uint64_t(1) << c;
    }
    colour_start_.assign(ncol + 1, 0);
    for (Index t = 0; t < nt; ++t) colour_start_[colour[t] + 1]++;
    for (int c = 0; c < ncol; ++c) colour_start_[c + 1] += colour_start_[c];
    std::vector<Index> order(nt);
    {
      std::vector<Index> pos(colour_start_.begin(), colour_start_.end() - 1);
      for (Index t = 0; t < nt; ++t) order[pos[colour[t]]++] = t;
    }
    std::vector<std::array<Index, 3>> tris(nt);
    for (Index k = 0; k < nt; ++k) tris[k] = all[order[k]];
    std::vector<Index> tv(3 * static_cast<std::size_t>(nt));
    for (Index t = 0; t < nt; ++t)
      for (int a = 0; a < 3; ++a) tv[3 * t + a] = tris[t][a];
    cuda::upload(tv, tri_);
    std::vector<gnatv::RestTriangle<T>> rest(nt);
    for (Index t = 0; t < nt; ++t) {
      const auto& r = gm->rest()[order[t]];
      for (int a = 0; a < 3; ++a) {
        rest[t].ru[a] = static_cast<T>(r.ru[a]);
        rest[t].rv[a] = static_cast<T>(r.rv[a]);
      }
      rest[t].area = static_cast<T>(r.area);
    }
    rest_.assign(rest.begin(), rest.end());
    // Curves: x, y, m, cum of the three curves in one device array.
    const CurveView<double>* cv[3] = {&gm->curves().uu, &gm->curves().vv, &gm->curves().uv};
    std::vector<double> data;
    std::size_t off[3];
    for (int c = 0; c < 3; ++c) {
      off[c] = data.size();
      const int m = cv[c]->n;
      data.insert(data.end(), cv[c]->x, cv[c]->x + m);
      data.insert(data.end(), cv[c]->y, cv[c]->y + m);
      data.insert(data.end(), cv[c]->m, cv[c]->m + m);
      data.insert(data.end(), cv[c]->cum, cv[c]->cum + m);
    }
    cuda::upload(data, curve_data_);
    CurveView<T>* out[3] = {&curves_.uu, &curves_.vv, &curves_.uv};
    for (int c = 0; c < 3; ++c) {
      const int m = cv[c]->n;
      const T* base = raw(curve_data_) + off[c];
      out[c]->x = base;
      out[c]->y = base + m;
      out[c]->m = base + 2 * m;
      out[c]->cum = base + 3 * m;
      out[c]->n = m;
      out[c]->inv_step = static_cast<T>(cv[c]->inv_step);
      out[c]->left_slope = static_cast<T>(cv[c]->left_slope);
      out[c]->right_slope = static_cast<T>(cv[c]->right_slope);
      out[c]->w_offset = static_cast<T>(cv[c]->w_offset);
    }
    if (pattern) {
      std::vector<Index> sc(9 * static_cast<std::size_t>(nt));
      for (Index t = 0; t < nt; ++t)
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i) {
            const Index k = pattern->find(tris[t][j], tris[t][i]);
            if (k < 0) throw std::logic_error("backend cuda: a triangle is missing from the Jacobian pattern");
            sc[9 * t + 3 * j + i] = k;
          }
      cuda::upload(sc, tri_scatter_);
    }
    return;
  }
#endif
  warn_host_fallback<T>(material_->name());
  hx_.assign(3 * static_cast<std::size_t>(n_), 0.0);
  hv_ = hx_;
  hf_ = hx_;
  if (pattern) {
    hdfdx_ = std::make_unique<BsrMatrix>(pattern);
    hdfdv_ = std::make_unique<BsrMatrix>(pattern);
  }
}

template <class T>
void DeviceForceModel<T>::forces(const DVec<T>& x, const DVec<T>& v, DVec<T>& f) {
  ++force_calls_;
  switch (kind_) {
    case ForceModelKind::Springs: {
      const Index S = static_cast<Index>(si_.size());
      parallel_for(S, SpringForce<T>{raw(si_), raw(sj_), raw(l0_), raw(k_), raw(c_), raw(x), raw(v), raw(per_spring_)});
      parallel_for(n_, GatherForce<T>{raw(inc_ptr_), raw(inc_spring_), raw(inc_sign_), raw(per_spring_), raw(f)});
      return;
    }
    case ForceModelKind::Gnatv: {
      fill(f, T(0));
      for (std::size_t c = 0; c + 1 < colour_start_.size(); ++c)
        parallel_for(colour_start_[c], colour_start_[c + 1],
                     GnatvForces<T>{raw(tri_), raw(rest_), curves_, raw(x), raw(f)});
      return;
    }
    case ForceModelKind::Host: {
      cuda::download(x, hx_, stage_);
      cuda::download(v, hv_, stage_);
      material_->compute_forces(hx_, hv_, hf_);
      cuda::upload(hf_, f);
      return;
    }
  }
}

template <class T>
void DeviceForceModel<T>::jacobians(const DVec<T>& x, const DVec<T>& v, DVec<T>& dfdx, DVec<T>* dfdv) {
  if (!pattern_) throw std::logic_error("backend cuda: jacobians() without a pattern");
  switch (kind_) {
    case ForceModelKind::Springs: {
      const Index S = static_cast<Index>(si_.size());
      const bool with_v = dfdv && damped_;
      parallel_for(S, SpringBlocks<T>{raw(si_), raw(sj_), raw(l0_), raw(k_), raw(c_), raw(x), clamp_, raw(per_spring_),
                                      with_v ? raw(per_spring_d_) : nullptr});
      parallel_for(n_, GatherBlocks<T>{raw(pat_row_ptr_), raw(pat_diag_), raw(inc_ptr_), raw(inc_spring_), raw(inc_block_),
                                       raw(per_spring_), raw(dfdx)});
      if (dfdv) {
        if (with_v)
          parallel_for(n_, GatherBlocks<T>{raw(pat_row_ptr_), raw(pat_diag_), raw(inc_ptr_), raw(inc_spring_),
                                           raw(inc_block_), raw(per_spring_d_), raw(*dfdv)});
        else
          fill(*dfdv, T(0));
      }
      return;
    }
    case ForceModelKind::Gnatv: {
      fill(dfdx, T(0));
      if (dfdv) fill(*dfdv, T(0));  // no material damping: df/dv = 0
      for (std::size_t c = 0; c + 1 < colour_start_.size(); ++c)
        parallel_for(colour_start_[c], colour_start_[c + 1],
                     GnatvJacobian<T>{raw(tri_), raw(tri_scatter_), raw(rest_), curves_, psd_, raw(x), raw(dfdx)});
      return;
    }
    case ForceModelKind::Host: {
      cuda::download(x, hx_, stage_);
      cuda::download(v, hv_, stage_);
      material_->compute_jacobians(hx_, hv_, *hdfdx_, hdfdv_.get());
      cuda::upload(hdfdx_->values(), dfdx);
      if (dfdv) cuda::upload(hdfdv_->values(), *dfdv);
      return;
    }
  }
}

template class DeviceForceModel<double>;
template class DeviceForceModel<float>;

}  // namespace loom::cuda
