#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <stdexcept>

#include "device_model.hpp"
#include "loom/incidence.hpp"
#include "loom/kernels/bending.hpp"
#include "loom/kernels/spring.hpp"
#include "loom/springs.hpp"

namespace loom::cuda {

const char* to_string(ForceModelKind k) {
  switch (k) {
    case ForceModelKind::Device: return "device kernels";
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
  bool accumulate;  // add to f (another block wrote it first) instead of overwriting
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
    if (accumulate) {
      a0 += f[3LL * i];
      a1 += f[3LL * i + 1];
      a2 += f[3LL * i + 2];
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
  bool accumulate;  // add to the row (another block wrote it first) instead of overwriting
  LOOM_HD void operator()(Index i) const {
    if (!accumulate)
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

// ---- coloured elements (GnatvTriangle, Hinge): one launch per colour ----
template <class T>
LOOM_HD inline gnatv::RestTriangle<T> rest_triangle(const T* d) {
  gnatv::RestTriangle<T> r;
  for (int a = 0; a < 3; ++a) {
    r.ru[a] = d[a];
    r.rv[a] = d[3 + a];
  }
  r.area = d[6];
  return r;
}

template <class T>
struct GnatvForces {
  const Index* tri;
  const T* data;
  gnatv::Curves<T> curves;
  const T* x;
  T* f;
  LOOM_HD void operator()(Index t) const {
    const Index* tv = tri + 3LL * t;
    T P[3][3], F[3][3];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = x[3LL * tv[j] + k];
    gnatv::forces(rest_triangle(data + 7LL * t), curves, P, F);
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) f[3LL * tv[j] + k] += F[j][k];
  }
};

template <class T>
struct GnatvJacobian {
  const Index *tri, *scatter;
  const T* data;
  gnatv::Curves<T> curves;
  bool psd;
  const T* x;
  T* A;
  LOOM_HD void operator()(Index t) const {
    const Index* tv = tri + 3LL * t;
    T P[3][3], J[3][3][9];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = x[3LL * tv[j] + k];
    gnatv::jacobian(rest_triangle(data + 7LL * t), curves, P, psd, J);
    const Index* sc = scatter + 9LL * t;
    for (int b = 0; b < 9; ++b) {
      T* dst = A + 9LL * sc[b];
      const T* src = J[b / 3][b % 3];
      for (int q = 0; q < 9; ++q) dst[q] += src[q];
    }
  }
};

template <class T>
struct HingeForces {
  const Index* hv;
  const T* data;  // {k, theta0} per hinge
  const T* x;
  T* f;
  LOOM_HD void operator()(Index h) const {
    const Index* v = hv + 4LL * h;
    T P[4][3], F[4][3];
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) P[a][k] = x[3LL * v[a] + k];
    const bending::RestHinge<T> r{data[2LL * h], data[2LL * h + 1]};
    bending::forces(r, P, F);
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) f[3LL * v[a] + k] += F[a][k];
  }
};

template <class T>
struct HingeJacobian {  // the kernel's Jacobian is in double (its exact Hessian uses dual numbers)
  const Index *hv, *scatter;
  const T* data;
  bool exact;
  const T* x;
  T* A;
  LOOM_HD void operator()(Index h) const {
    const Index* v = hv + 4LL * h;
    double P[4][3], J[4][4][9];
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) P[a][k] = static_cast<double>(x[3LL * v[a] + k]);
    const bending::RestHinge<double> r{static_cast<double>(data[2LL * h]), static_cast<double>(data[2LL * h + 1])};
    bending::jacobian(r, P, exact, J);
    const Index* sc = scatter + 16LL * h;
    for (int b = 0; b < 16; ++b) {
      T* dst = A + 9LL * sc[b];
      const double* src = J[b / 4][b % 4];
      for (int q = 0; q < 9; ++q) dst[q] += static_cast<T>(src[q]);
    }
  }
};

template <class T>
void warn_host_fallback(const std::string& name) {
  static bool once = false;
  if (once) return;
  once = true;
  std::fprintf(stderr,
               "loom: backend cuda: material '%s' has no device description (Material::describe_device); its forces "
               "are computed on the host (x, v and f are copied for every evaluation)\n",
               name.c_str());
}

}  // namespace

template <class T>
void DeviceForceModel<T>::build(const Scene& scene, const BsrPattern* pattern, bool merge_springs) {
  merged_ = 0;
  material_ = scene.material.get();
  if (!material_) throw InputError(scene.source + ": backend cuda: the scene has no material");
  n_ = scene.state.size();
  pattern_ = pattern;
  kind_ = ForceModelKind::Host;
  kernels_.clear();
  springs_.clear();
  coloured_.clear();
  DeviceDescription desc;
  if (material_->describe_device(desc)) {
    validate(desc, n_, material_->name());
    kind_ = ForceModelKind::Device;
    if (pattern) {
      cuda::upload(pattern->row_ptr, pat_row_ptr_);
      cuda::upload(pattern->diag, pat_diag_);
    }
    // Spring blocks first: the first one overwrites f and the Jacobian rows, the rest add.
    for (const ElementBlock& b : desc.blocks)
      if (b.kernel == ElementKernel::Spring) add_springs(b, pattern, merge_springs && !pattern);
    for (const ElementBlock& b : desc.blocks)
      if (b.kernel != ElementKernel::Spring) add_coloured(b, pattern);
    return;
  }
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
void DeviceForceModel<T>::add_springs(const ElementBlock& b, const BsrPattern* pattern, bool merge) {
  auto d = std::make_unique<DeviceSprings<T>>();
  d->clamp = (b.flags & ElementBlock::kClampCompressed) != 0;
  SpringSet set;
  for (Index q = 0; q < b.size(); ++q)
    set.add(b.vertices[2 * q], b.vertices[2 * q + 1], b.data[3 * q], b.data[3 * q + 1], b.data[3 * q + 2],
            SpringClass::Structural);
  if (merge) {   // forces only: the merged spring's force is its group's (loom/springs.hpp)
    Index m = 0;
    set = merge_duplicate_springs(set, &m);
    merged_ += m;
  }
  const Index S = set.size();
  d->count = S;
  const std::vector<Index>& I = set.i;
  const std::vector<Index>& J = set.j;
  const std::vector<double>& l0 = set.rest_length;
  const std::vector<double>& k = set.stiffness;
  const std::vector<double>& c = set.damping;
  for (Index q = 0; q < S; ++q) d->damped = d->damped || c[q] != 0.0;
  cuda::upload(I, d->si);
  cuda::upload(J, d->sj);
  cuda::upload(l0, d->l0);
  cuda::upload(k, d->k);
  cuda::upload(c, d->c);
  // Incidence: vertex -> (spring, sign), springs in increasing order (loom/incidence.hpp).
  const VertexIncidence inc(n_, I, J);
  const std::vector<Index>& ptr = inc.offsets;
  const std::vector<Index>& sp = inc.spring;
  const std::vector<std::int8_t>& sg = inc.sign;
  std::vector<Index> blk;
  if (pattern) {
    blk.resize(sp.size());
    for (Index i = 0; i < n_; ++i)
      for (Index e = ptr[i]; e < ptr[i + 1]; ++e) {
        const Index q = sp[e];
        const Index other = sg[e] > 0 ? J[q] : I[q];
        blk[e] = pattern->find(i, other);
        if (blk[e] < 0) throw std::logic_error("backend cuda: a spring is missing from the Jacobian pattern");
      }
    cuda::upload(blk, d->inc_block);
    d->per_spring_d.assign(d->damped ? 9 * static_cast<std::size_t>(S) : 0, T(0));
  }
  cuda::upload(ptr, d->inc_ptr);
  cuda::upload(sp, d->inc_spring);
  cuda::upload(sg, d->inc_sign);
  d->per_spring.assign((pattern ? 9 : 3) * static_cast<std::size_t>(S), T(0));
  springs_.push_back(std::move(d));
  kernels_.push_back(ElementKernel::Spring);
}

template <class T>
void DeviceForceModel<T>::add_coloured(const ElementBlock& b, const BsrPattern* pattern) {
  auto d = std::make_unique<DeviceColoured<T>>();
  d->kernel = b.kernel;
  d->arity = kernel_arity(b.kernel);
  d->stride = kernel_stride(b.kernel);
  d->flags = b.flags;
  const int ar = d->arity, st = d->stride;
  // Own greedy vertex colouring (elements of one colour share no vertex), independent of the
  // material's internal order: elements stored colour by colour.
  const Index ne = b.size();
  std::vector<std::uint64_t> used(n_, 0);
  std::vector<int> colour(ne);
  int ncol = 0;
  for (Index e = 0; e < ne; ++e) {
    const Index* v = &b.vertices[static_cast<std::size_t>(ar) * e];
    std::uint64_t busy = 0;
    for (int a = 0; a < ar; ++a) busy |= used[v[a]];
    int c = 0;
    while (c < 64 && (busy >> c) & 1u) ++c;
    if (c == 64)
      throw std::logic_error(std::string("backend cuda: more than 64 colours of ") + to_string(b.kernel) +
                             " elements (a vertex in too many elements)");
    colour[e] = c;
    ncol = std::max(ncol, c + 1);
    for (int a = 0; a < ar; ++a) used[v[a]] |= std::uint64_t(1) << c;
  }
  d->colour_start.assign(ncol + 1, 0);
  for (Index e = 0; e < ne; ++e) d->colour_start[colour[e] + 1]++;
  for (int c = 0; c < ncol; ++c) d->colour_start[c + 1] += d->colour_start[c];
  std::vector<Index> order(ne);
  {
    std::vector<Index> pos(d->colour_start.begin(), d->colour_start.end() - 1);
    for (Index e = 0; e < ne; ++e) order[pos[colour[e]]++] = e;
  }
  std::vector<Index> vert(static_cast<std::size_t>(ar) * ne);
  std::vector<double> data(static_cast<std::size_t>(st) * ne);
  for (Index k = 0; k < ne; ++k) {
    for (int a = 0; a < ar; ++a) vert[ar * k + a] = b.vertices[static_cast<std::size_t>(ar) * order[k] + a];
    for (int a = 0; a < st; ++a) data[st * k + a] = b.data[static_cast<std::size_t>(st) * order[k] + a];
  }
  cuda::upload(vert, d->vert);
  cuda::upload(data, d->data);
  if (b.kernel == ElementKernel::GnatvTriangle) {
    cuda::upload(b.shared, d->shared);
    CurveView<T> views[3];
    unpack_curves<T>(b.shared, raw(d->shared), views);
    d->curves = {views[0], views[1], views[2]};
  }
  if (pattern) {  // block (v_a, v_b) of element k at ar*ar*k + ar*a + b
    std::vector<Index> sc(static_cast<std::size_t>(ar) * ar * ne);
    for (Index k = 0; k < ne; ++k)
      for (int a = 0; a < ar; ++a)
        for (int c = 0; c < ar; ++c) {
          const Index q = pattern->find(vert[ar * k + a], vert[ar * k + c]);
          if (q < 0)
            throw std::logic_error(std::string("backend cuda: a ") + to_string(b.kernel) +
                                   " element is missing from the Jacobian pattern");
          sc[static_cast<std::size_t>(ar) * ar * k + ar * a + c] = q;
        }
    cuda::upload(sc, d->scatter);
  }
  kernels_.push_back(b.kernel);
  coloured_.push_back(std::move(d));
}

template <class T>
void DeviceForceModel<T>::forces(const DVec<T>& x, const DVec<T>& v, DVec<T>& f) {
  ++force_calls_;
  if (kind_ == ForceModelKind::Host) {
    cuda::download(x, hx_, stage_);
    cuda::download(v, hv_, stage_);
    material_->compute_forces(hx_, hv_, hf_);
    cuda::upload(hf_, f);
    return;
  }
  bool written = false;
  for (auto& s : springs_) {
    parallel_for(s->count, SpringForce<T>{raw(s->si), raw(s->sj), raw(s->l0), raw(s->k), raw(s->c), raw(x), raw(v),
                                          raw(s->per_spring)});
    parallel_for(n_, GatherForce<T>{raw(s->inc_ptr), raw(s->inc_spring), raw(s->inc_sign), raw(s->per_spring), raw(f),
                                    written});
    written = true;
  }
  if (!written) fill(f, T(0));
  for (auto& c : coloured_)
    for (std::size_t k = 0; k + 1 < c->colour_start.size(); ++k) {
      const Index b = c->colour_start[k], e = c->colour_start[k + 1];
      if (c->kernel == ElementKernel::GnatvTriangle)
        parallel_for(b, e, GnatvForces<T>{raw(c->vert), raw(c->data), c->curves, raw(x), raw(f)});
      else
        parallel_for(b, e, HingeForces<T>{raw(c->vert), raw(c->data), raw(x), raw(f)});
    }
}

template <class T>
void DeviceForceModel<T>::jacobians(const DVec<T>& x, const DVec<T>& v, DVec<T>& dfdx, DVec<T>* dfdv) {
  if (!pattern_) throw std::logic_error("backend cuda: jacobians() without a pattern");
  if (kind_ == ForceModelKind::Host) {
    cuda::download(x, hx_, stage_);
    cuda::download(v, hv_, stage_);
    material_->compute_jacobians(hx_, hv_, *hdfdx_, hdfdv_.get());
    cuda::upload(hdfdx_->values(), dfdx);
    if (dfdv) cuda::upload(hdfdv_->values(), *dfdv);
    return;
  }
  bool written = false, written_v = false;
  for (auto& s : springs_) {
    const bool with_v = dfdv && s->damped;
    parallel_for(s->count, SpringBlocks<T>{raw(s->si), raw(s->sj), raw(s->l0), raw(s->k), raw(s->c), raw(x), s->clamp,
                                           raw(s->per_spring), with_v ? raw(s->per_spring_d) : nullptr});
    parallel_for(n_, GatherBlocks<T>{raw(pat_row_ptr_), raw(pat_diag_), raw(s->inc_ptr), raw(s->inc_spring),
                                     raw(s->inc_block), raw(s->per_spring), raw(dfdx), written});
    written = true;
    if (with_v) {
      parallel_for(n_, GatherBlocks<T>{raw(pat_row_ptr_), raw(pat_diag_), raw(s->inc_ptr), raw(s->inc_spring),
                                       raw(s->inc_block), raw(s->per_spring_d), raw(*dfdv), written_v});
      written_v = true;
    }
  }
  // Blocks of the pattern no spring touches must be zeroed too: zero everything unless a
  // spring block covered every row (its gather assigns whole rows).
  if (!written) fill(dfdx, T(0));
  if (dfdv && !written_v) fill(*dfdv, T(0));  // no other kernel has damping: df/dv = 0
  for (auto& c : coloured_)
    for (std::size_t k = 0; k + 1 < c->colour_start.size(); ++k) {
      const Index b = c->colour_start[k], e = c->colour_start[k + 1];
      if (c->kernel == ElementKernel::GnatvTriangle)
        parallel_for(b, e, GnatvJacobian<T>{raw(c->vert), raw(c->scatter), raw(c->data), c->curves,
                                            (c->flags & ElementBlock::kPsd) != 0, raw(x), raw(dfdx)});
      else
        parallel_for(b, e, HingeJacobian<T>{raw(c->vert), raw(c->scatter), raw(c->data),
                                            (c->flags & ElementBlock::kExactJacobian) != 0, raw(x), raw(dfdx)});
    }
}

template class DeviceForceModel<double>;
template class DeviceForceModel<float>;

}  // namespace loom::cuda
