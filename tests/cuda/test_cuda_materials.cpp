// The material boundary of the CUDA backend (issue 17) and bending on the device (issue 14),
// through the Thrust-OpenMP stand-in (and on a GPU as test_cuda_gpu):
//   * a material defined here, out of tree, runs on the device through its own device
//     description (Material::describe_device): the backend never names it;
//   * gnatv and mass_spring with hinge bending (BentMaterial): forces, Jacobians, RK4 and
//     Baraff-Witkin runs against the CPU backend on a curved (non-flat rest) cloth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "cuda_integrators.hpp"
#include "cuda_test_compare.hpp"
#include "cuda_test_state.hpp"
#include "device_model.hpp"
#include "device_pcg.hpp"
#include "gnatv_material.hpp"
#include "loom/bending.hpp"
#include "loom/device_material.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"
#include "rk4_integrator.hpp"
#ifdef LOOM_TEST_HAVE_BW
#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#endif

using namespace loom;
namespace lc = loom::cuda;
using lc::DVec;

namespace {

using loom_cuda_test::rel_diff;

using loom_cuda_test::to_host;

// ---------------------------------------------------------------- an out-of-tree material
// Springs on the mesh edges (edges along x damped, the others not: two Spring blocks) plus
// hinge bending on every interior edge. Its CPU forces are written here from the formulas
// (Hooke spring with an axial damper; the hinge kernel for the bending part); its device
// description exports the same elements. Nothing in plugins/backends/cuda knows this class.
class OutOfTreeMaterial final : public Material {
 public:
  OutOfTreeMaterial(const Mesh& mesh, double b)
      : n_(mesh.num_vertices()), hinges_(mesh, [&] {
          BendingOptions o;
          o.b_weft = o.b_warp = o.b_bias = b;
          o.exact_jacobian = true;
          return o;
        }()) {
    for (const auto& e : mesh.edges()) {
      const double* p = &mesh.positions[3 * static_cast<std::size_t>(e[0])];
      const double* q = &mesh.positions[3 * static_cast<std::size_t>(e[1])];
      const double d[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]};
      const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      const bool along_x = std::fabs(d[0]) > 0.99 * l;
      springs_.push_back({e[0], e[1], l, along_x ? 900.0 : 500.0, along_x ? 0.4 : 0.0});
    }
  }
  std::string name() const override { return "out_of_tree_test"; }
  void compute_masses(std::span<double> m) const override { std::fill(m.begin(), m.end(), 2e-3); }
  void compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const override {
    std::fill(f.begin(), f.end(), 0.0);
    for (const Spring& s : springs_) {
      const std::size_t a = 3 * static_cast<std::size_t>(s.i), b = 3 * static_cast<std::size_t>(s.j);
      double d[3], u[3];
      for (int k = 0; k < 3; ++k) {
        d[k] = x[b + k] - x[a + k];
        u[k] = v[b + k] - v[a + k];
      }
      const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      const double nu = (d[0] * u[0] + d[1] * u[1] + d[2] * u[2]) / l;  // n . (v_j - v_i)
      for (int k = 0; k < 3; ++k) {
        const double fi = (s.k * (l - s.l0) + s.c * nu) * d[k] / l;  // on i, toward j when stretched
        f[a + k] += fi;
        f[b + k] -= fi;
      }
    }
    hinges_.add_forces(x, f);
  }
  double elastic_energy(std::span<const double>) const override { return 0.0; }
  double max_strain(std::span<const double>) const override { return 0.0; }
  bool has_jacobian() const override { return true; }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const override {
    for (const Spring& s : springs_) pairs.push_back({s.i, s.j});
    hinges_.jacobian_pairs(pairs);
  }
  bool describe_device(DeviceDescription& out) const override {
    ElementBlock damped, plain, hinge;
    damped.kernel = plain.kernel = ElementKernel::Spring;  // no clamp: the exact Jacobian
    for (const Spring& s : springs_) {
      ElementBlock& b = s.c != 0.0 ? damped : plain;
      b.vertices.insert(b.vertices.end(), {s.i, s.j});
      b.data.insert(b.data.end(), {s.l0, s.k, s.c});
    }
    hinge.kernel = ElementKernel::Hinge;
    hinge.flags = ElementBlock::kExactJacobian;
    for (Index h = 0; h < hinges_.num_hinges(); ++h) {
      for (int a = 0; a < 4; ++a) hinge.vertices.push_back(hinges_.hinges()[h][a]);
      hinge.data.insert(hinge.data.end(), {hinges_.rest()[h].k, hinges_.rest()[h].theta0});
    }
    out.blocks.push_back(std::move(hinge));  // in any order: the backend sums the blocks
    out.blocks.push_back(std::move(plain));
    out.blocks.push_back(std::move(damped));
    return true;
  }

 private:
  struct Spring {
    Index i, j;
    double l0, k, c;
  };
  Index n_;
  std::vector<Spring> springs_;
  HingeSet hinges_;
};

/// A curved sheet (rest angles != 0): an nx x ny grid in the xz plane lifted to
/// y = 0.08 sin(pi x) (1 m square).
Mesh curved_grid(Index nx, Index ny) {
  Mesh m = make_grid(nx, ny, 1.0, 1.0, GridPlane::XZ);
  for (Index i = 0; i < m.num_vertices(); ++i) m.positions[3 * i + 1] = 0.08 * std::sin(std::numbers::pi * m.positions[3 * i]);
  return m;
}

enum class Membrane { DampedSprings, Gnatv, OutOfTree };

/// Scene on the curved sheet: two pinned corners, a perturbed start with velocities.
std::unique_ptr<Scene> make_scene(Membrane m, Index nx, Index ny, double b, bool exact = false, double pert = 0.01,
                                  double vel = 0.2) {
  auto sc = std::make_unique<Scene>();
  sc->source = "<test>";
  sc->mesh = curved_grid(nx, ny);
  const Params bend = Params::from_string("stiffness: " + std::to_string(b) + "\njacobian: " +
                                              (exact ? "exact" : "gauss_newton") + "\n",
                                          "<test>");
  if (m == Membrane::OutOfTree) {
    sc->material = std::make_unique<OutOfTreeMaterial>(sc->mesh, b);
  } else {
    std::unique_ptr<Material> membrane;
    if (m == Membrane::Gnatv)
      membrane = std::make_unique<gnatv::GnatvMaterial>(
          Params::from_string("material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n", "<test>"),
          sc->mesh);
    else
      membrane = std::make_unique<mass_spring::MassSpringMaterial>(
          Params::from_string("stencil: mesh_edges\nstiffness: 2000\ndamping: 0.3\ndensity: 0.1\n", "<test>"), sc->mesh);
    sc->material = std::make_unique<BentMaterial>(std::move(membrane), sc->mesh, read_bending_options(bend));
  }
  loom_cuda_test::init_perturbed_state(*sc, nx, 13, pert, vel);
  return sc;
}

using loom_cuda_test::run;

}  // namespace

// ---------------------------------------------------------------- the boundary
TEST(CudaMaterialBoundary, OutOfTreeMaterialRunsOnTheDevice) {
  auto sc = make_scene(Membrane::OutOfTree, 7, 6, 5e-3);
  State& st = sc->state;
  std::vector<std::array<Index, 2>> pairs;
  sc->material->jacobian_pairs(pairs);
  const BsrPattern P = BsrPattern::from_pairs(st.size(), pairs);
  lc::DeviceForceModel<double> model;
  model.build(*sc, &P);
  ASSERT_EQ(model.kind(), lc::ForceModelKind::Device);
  // Spring blocks run first (the first one assigns), whatever order the material gave.
  EXPECT_EQ(model.kernels(), (std::vector<ElementKernel>{ElementKernel::Spring, ElementKernel::Spring, ElementKernel::Hinge}));
  // Forces against the material's own CPU code.
  std::vector<double> f(st.x.size());
  sc->material->compute_forces(st.x, st.v, f);
  DVec<double> x(st.x.begin(), st.x.end()), v(st.v.begin(), st.v.end()), df(st.x.size(), 7.0);
  model.forces(x, v, df);
  EXPECT_LE(rel_diff(to_host(df), f), 1e-12);
  // Jacobians against central differences of the material's CPU forces (at v = 0, where the
  // damper's position derivative, which the kernels leave out, vanishes; df/dv is exact).
  std::vector<double> v0(st.v.size(), 0.0);
  DVec<double> dv0(v0.begin(), v0.end()), jx(9 * P.nnz_blocks(), 3.0), jv(9 * P.nnz_blocks(), 3.0);
  model.jacobians(x, dv0, jx, &jv);
  const auto Jx = to_host(jx), Jv = to_host(jv);
  const Index N = 3 * st.size();
  const double eps = 1e-6;
  double err_x = 0, err_v = 0, max_x = 0, max_v = 0;
  std::vector<double> fp(N), fm(N), xp = st.x, vp = v0;
  for (Index col = 0; col < N; ++col) {
    for (int which = 0; which < 2; ++which) {
      std::vector<double>& y = which == 0 ? xp : vp;
      const double keep = y[col];
      y[col] = keep + eps;
      sc->material->compute_forces(xp, vp, fp);
      y[col] = keep - eps;
      sc->material->compute_forces(xp, vp, fm);
      y[col] = keep;
      const Index jb = col / 3;
      for (Index row = 0; row < N; ++row) {
        const double fd = (fp[row] - fm[row]) / (2 * eps);
        const Index k = P.find(row / 3, jb);
        const double dev = k < 0 ? 0.0 : (which == 0 ? Jx : Jv)[9 * static_cast<std::size_t>(k) + 3 * (row % 3) + col % 3];
        (which == 0 ? err_x : err_v) = std::max(which == 0 ? err_x : err_v, std::fabs(dev - fd));
        (which == 0 ? max_x : max_v) = std::max(which == 0 ? max_x : max_v, std::fabs(fd));
      }
    }
  }
  EXPECT_GT(max_x, 100.0);
  EXPECT_GT(max_v, 0.1);
  EXPECT_LE(err_x / max_x, 1e-6);
  EXPECT_LE(err_v / max_v, 1e-8);
  // A whole RK4 run on the device against the CPU integrator with the same material.
  auto cpu = make_scene(Membrane::OutOfTree, 7, 6, 5e-3);
  auto dev = make_scene(Membrane::OutOfTree, 7, 6, 5e-3);
  Rk4Integrator ci;
  auto di = lc::make_cuda_rk4(lc::Precision::Double);
  run(ci, *cpu, 2e-4, 100);
  run(*di, *dev, 2e-4, 100);
  EXPECT_GT(rel_diff(cpu->state.x, cpu->mesh.positions), 1e-3);
  EXPECT_LE(rel_diff(dev->state.x, cpu->state.x), 1e-12);
  EXPECT_LE(rel_diff(dev->state.v, cpu->state.v), 1e-10);
}

TEST(CudaMaterialBoundary, AMaterialWithoutADescriptionIsEvaluatedOnTheHost) {
  auto sc = make_scene(Membrane::DampedSprings, 5, 5, 1e-3);
  // A material that does not override describe_device: the host fallback, same forces.
  struct Opaque final : Material {
    const Material& inner;
    explicit Opaque(const Material& m) : inner(m) {}
    std::string name() const override { return "opaque"; }
    void compute_masses(std::span<double> m) const override { inner.compute_masses(m); }
    void compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const override {
      inner.compute_forces(x, v, f);
    }
    double elastic_energy(std::span<const double> x) const override { return inner.elastic_energy(x); }
    double max_strain(std::span<const double> x) const override { return inner.max_strain(x); }
  };
  Scene wrapped;
  wrapped.source = "<test>";
  wrapped.state = sc->state;
  wrapped.material = std::make_unique<Opaque>(*sc->material);
  lc::DeviceForceModel<double> model;
  model.build(wrapped, nullptr);
  EXPECT_EQ(model.kind(), lc::ForceModelKind::Host);
  std::vector<double> f(sc->state.x.size());
  sc->material->compute_forces(sc->state.x, sc->state.v, f);
  DVec<double> x(sc->state.x.begin(), sc->state.x.end()), v(sc->state.v.begin(), sc->state.v.end()), df(f.size());
  model.forces(x, v, df);
  EXPECT_EQ(to_host(df), f);
}

TEST(CudaMaterialBoundary, InconsistentDescriptionsAreRejected) {
  DeviceDescription d;
  ElementBlock b;
  b.kernel = ElementKernel::Hinge;
  b.vertices = {0, 1, 2, 3};
  b.data = {1.0};  // stride 2
  d.blocks.push_back(b);
  try {
    validate(d, 4, "mine");
    FAIL() << "expected logic_error";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("material 'mine', device block 0 (hinge)"), std::string::npos) << e.what();
  }
  d.blocks[0].data = {1.0, 0.0};
  EXPECT_NO_THROW(validate(d, 4, "mine"));
  EXPECT_THROW(validate(d, 3, "mine"), std::logic_error);  // vertex 3 outside 0..2
  d.blocks[0].data = {1.0, std::nan("")};
  EXPECT_THROW(validate(d, 4, "mine"), std::logic_error);
  d.blocks[0].data = {1.0, 0.0};
  d.blocks[0].kernel = ElementKernel::GnatvTriangle;  // 4 indices are not triangles
  EXPECT_THROW(validate(d, 4, "mine"), std::logic_error);
}

// ---------------------------------------------------------------- bending on the device
struct BentCase {
  Membrane membrane;
  bool exact;
};
class CudaBending : public ::testing::TestWithParam<BentCase> {};

TEST_P(CudaBending, ForcesAndJacobiansMatchTheCpuMaterial) {
  const auto [m, exact] = GetParam();
  auto sc = make_scene(m, 9, 8, 2e-2, exact);
  State& st = sc->state;
  std::vector<std::array<Index, 2>> pairs;
  sc->material->jacobian_pairs(pairs);
  const BsrPattern P = BsrPattern::from_pairs(st.size(), pairs);
  sc->material->bind_pattern(P);
  lc::DeviceForceModel<double> model;
  model.build(*sc, &P);
  ASSERT_EQ(model.kind(), lc::ForceModelKind::Device);
  ASSERT_EQ(model.kernels().back(), ElementKernel::Hinge);
  std::vector<double> f(st.x.size()), fm(st.x.size());
  sc->material->compute_forces(st.x, st.v, f);
  BsrMatrix dfdx(&P), dfdv(&P);
  sc->material->compute_jacobians(st.x, st.v, dfdx, &dfdv);
  // The hinges contribute far above the 1e-12 tolerance below (so a missing or wrong hinge
  // block fails); wool's membrane forces dominate: the hinges are ~6e-5 of them here.
  const auto& bent = static_cast<const BentMaterial&>(*sc->material);
  bent.membrane().compute_forces(st.x, st.v, fm);
  EXPECT_GT(rel_diff(fm, f), 1e-6);
  DVec<double> x(st.x.begin(), st.x.end()), v(st.v.begin(), st.v.end()), df(st.x.size());
  DVec<double> jx(9 * P.nnz_blocks(), 1.0), jv(9 * P.nnz_blocks(), 1.0);  // garbage: must be overwritten
  model.forces(x, v, df);
  model.jacobians(x, v, jx, &jv);
  EXPECT_LE(rel_diff(to_host(df), f), 1e-12);
  EXPECT_LE(rel_diff(to_host(jx), dfdx.values()), 1e-12);
  EXPECT_LE(rel_diff(to_host(jv), dfdv.values()), 1e-12);
}

TEST(CudaBendingRun, Rk4MatchesTheCpuBackend) {
  for (Membrane m : {Membrane::DampedSprings, Membrane::Gnatv}) {
    auto cpu = make_scene(m, 9, 8, 2e-2);
    auto dev = make_scene(m, 9, 8, 2e-2);
    Rk4Integrator ci;
    auto di = lc::make_cuda_rk4(lc::Precision::Double);
    const double h = m == Membrane::Gnatv ? 5e-5 : 2e-4;
    run(ci, *cpu, h, 60);
    run(*di, *dev, h, 60);
    EXPECT_GT(rel_diff(cpu->state.x, cpu->mesh.positions), 1e-3);
    EXPECT_LE(rel_diff(dev->state.x, cpu->state.x), 1e-10);
    EXPECT_LE(rel_diff(dev->state.v, cpu->state.v), 1e-10);
  }
}

#ifdef LOOM_TEST_HAVE_BW
TEST_P(CudaBending, BaraffWitkinRunMatchesTheCpuBackend) {
  const auto [m, exact] = GetParam();
  auto cpu = make_scene(m, 9, 8, 2e-2, exact);
  auto dev = make_scene(m, 9, 8, 2e-2, exact);
  cpu->solver = std::make_unique<EigenLdlt>();
  lc::PcgOptions po;
  po.tolerance = 1e-15;
  dev->solver = std::make_unique<lc::CusparsePcg>(po);
  BaraffWitkinOptions co;
  co.kang_cho_damping = 0.02;
  BaraffWitkin ci(co);
  lc::BwOptionsD o;
  o.kang_cho_damping = 0.02;
  auto di = lc::make_cuda_baraff_witkin(o, lc::Precision::Double);
  const double h = m == Membrane::Gnatv ? 2.5e-4 : 2e-3;
  run(ci, *cpu, h, 5);
  run(*di, *dev, h, 5);
  EXPECT_GT(di->last_step().linear_iterations, 3);
  EXPECT_GT(rel_diff(cpu->state.x, cpu->mesh.positions), 1e-4);
  EXPECT_LE(rel_diff(dev->state.x, cpu->state.x), 1e-10);
  EXPECT_LE(rel_diff(dev->state.v, cpu->state.v), 1e-10);
}
#endif

INSTANTIATE_TEST_SUITE_P(Membranes, CudaBending,
                         ::testing::Values(BentCase{Membrane::DampedSprings, false}, BentCase{Membrane::Gnatv, false},
                                           BentCase{Membrane::Gnatv, true}),
                         [](const auto& info) {
                           return std::string(info.param.membrane == Membrane::Gnatv ? "Gnatv" : "Springs") +
                                  (info.param.exact ? "Exact" : "GaussNewton");
                         });

TEST(CudaBendingFloat, TracksDouble) {
  auto sc = make_scene(Membrane::Gnatv, 9, 7, 2e-2);
  lc::DeviceForceModel<float> model;
  model.build(*sc, nullptr);
  std::vector<double> f(sc->state.x.size());
  sc->material->compute_forces(sc->state.x, sc->state.v, f);
  std::vector<float> xf(sc->state.x.begin(), sc->state.x.end());
  DVec<float> x(xf.begin(), xf.end()), v(xf.size(), 0.0f), df(xf.size());
  model.forces(x, v, df);
  const double e = rel_diff(to_host(df), f);
  EXPECT_LE(e, 1e-3);
  EXPECT_GT(e, 1e-12);  // it really ran in float
}
