// SpringLayout (race-free parallel traversal) and VertexIncidence.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <vector>

#include <omp.h>

#include "loom/mesh.hpp"
#include "loom/spring_layout.hpp"
#include "mass_spring.hpp"

using namespace loom;

namespace {

struct Graph {
  Index n = 0;
  std::vector<Index> i, j;
};

Graph random_graph(Index n, Index S, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<Index> u(0, n - 1);
  Graph g;
  g.n = n;
  while (static_cast<Index>(g.i.size()) < S) {
    const Index a = u(rng), b = u(rng);
    if (a == b) continue;
    g.i.push_back(a);
    g.j.push_back(b);
  }
  return g;
}

Graph grid_graph(Index n) {
  const Mesh m = make_grid(n, n, 1.0, 1.0);
  const SpringSet s = mass_spring::build_springs(m, mass_spring::Stencil::RadiusSqrt5,
                                                 mass_spring::ClassValues::all(1.0), mass_spring::ClassValues::all(0.0));
  return {m.num_vertices(), s.i, s.j};
}

// Structural checks: a permutation; interior springs inside their part; colours are matchings.
void check_structure(const Graph& g, const SpringLayout& L) {
  const Index S = static_cast<Index>(g.i.size());
  ASSERT_EQ(L.num_springs(), S);
  std::vector<Index> o(L.order().begin(), L.order().end());
  std::sort(o.begin(), o.end());
  for (Index k = 0; k < S; ++k) ASSERT_EQ(o[k], k);
  ASSERT_EQ(L.part_vertex_begin(0), 0);
  ASSERT_EQ(L.part_vertex_end(L.parts() - 1), g.n);
  for (int p = 0; p < L.parts(); ++p) {
    ASSERT_LE(L.part_vertex_begin(p), L.part_vertex_end(p));
    for (Index k = L.part_spring_begin(p); k < L.part_spring_end(p); ++k) {
      const Index s = L.order()[k];
      for (Index v : {g.i[s], g.j[s]}) {
        ASSERT_GE(v, L.part_vertex_begin(p));
        ASSERT_LT(v, L.part_vertex_end(p));
      }
    }
  }
  Index cross = 0;
  for (int c = 0; c < L.num_colours(); ++c) {
    std::set<Index> seen;
    for (Index k = L.colour_begin(c); k < L.colour_end(c); ++k) {
      const Index s = L.order()[k];
      ASSERT_TRUE(seen.insert(g.i[s]).second) << "colour " << c << " shares a vertex";
      ASSERT_TRUE(seen.insert(g.j[s]).second) << "colour " << c << " shares a vertex";
      ++cross;
    }
  }
  ASSERT_EQ(cross, L.num_cross());
  ASSERT_EQ(L.part_spring_end(L.parts() - 1) + cross, S);
}

// Traversal: every spring once; unsynchronised per-vertex counters end at the degrees.
void check_traversal(const Graph& g, const SpringLayout& L, int threads) {
  const Index S = static_cast<Index>(g.i.size());
  std::vector<int> visits(S, 0);
  std::vector<long long> deg(g.n, -7), sum(g.n, -7);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  for (int rep = 0; rep < 3; ++rep) {
    L.for_each(
        [&](Index v0, Index v1) {
          for (Index v = v0; v < v1; ++v) deg[v] = sum[v] = 0;
        },
        [&](Index s) {
          ++visits[s];
          ++deg[g.i[s]];
          ++deg[g.j[s]];
          sum[g.i[s]] += s;
          sum[g.j[s]] += s;
        });
  }
  // The range form visits the same springs (one more pass).
  omp_set_num_threads(threads);
  L.for_each_range(
      [&](Index, Index) {},
      [&](Index k0, Index k1) {
        ASSERT_LE(k0, k1);
        for (Index k = k0; k < k1; ++k) {
          const Index s = L.order()[k];
          ++visits[s];
          ++deg[g.i[s]];
          ++deg[g.j[s]];
          sum[g.i[s]] += s;
          sum[g.j[s]] += s;
        }
      });
  omp_set_num_threads(saved);
  std::vector<long long> d(g.n, 0), su(g.n, 0);
  for (Index s = 0; s < S; ++s) {
    ++d[g.i[s]];
    ++d[g.j[s]];
    su[g.i[s]] += s;
    su[g.j[s]] += s;
  }
  // 3 passes of for_each (init zeroes the counters each time), then one of for_each_range.
  for (Index s = 0; s < S; ++s) ASSERT_EQ(visits[s], 4);
  for (Index v = 0; v < g.n; ++v) {
    ASSERT_EQ(deg[v], 2 * d[v]) << v;
    ASSERT_EQ(sum[v], 2 * su[v]) << v;
  }
}

}  // namespace

TEST(SpringLayout, GridIsAlmostAllInterior) {
  const Graph g = grid_graph(64);
  for (int parts : {1, 2, 3, 8}) {
    SpringLayout L(g.n, g.i, g.j, parts);
    check_structure(g, L);
    EXPECT_LE(L.num_cross(), 12 * 64 * (parts - 1));  // a few rows' worth per cut
    EXPECT_TRUE(L.cross_serial());
    for (int t : {1, 2, 4}) check_traversal(g, L, t);
  }
  // Springs come sorted by lower endpoint from the builder: the layout keeps their order.
  SpringLayout L1(g.n, g.i, g.j, 1);
  EXPECT_TRUE(L1.identity());
}

TEST(SpringLayout, RandomGraphUsesColours) {
  for (unsigned seed : {1u}) {
    const Graph g = random_graph(5000, 40000, seed);  // almost every spring crosses a cut
    SpringLayout L(g.n, g.i, g.j, 2);
    check_structure(g, L);
    EXPECT_GT(L.num_cross(), SpringLayout::kSerialCross);
    EXPECT_FALSE(L.cross_serial());
    EXPECT_GT(L.num_colours(), 1);
    for (int t : {1, 2}) check_traversal(g, L, t);
  }
  // Small random graph: serial cross path.
  const Graph g = random_graph(1000, 6000, 9);
  SpringLayout L(g.n, g.i, g.j, 4);
  check_structure(g, L);
  check_traversal(g, L, 2);
}

TEST(SpringLayout, ReorderGivesIdentity) {
  Graph g = random_graph(300, 2000, 4);
  SpringSet s;
  for (std::size_t k = 0; k < g.i.size(); ++k) s.add(g.i[k], g.j[k], 1.0 + k, 2.0 * k, 0.0, SpringClass::Edge);
  SpringLayout L(g.n, s, 2);
  const std::vector<Index> order(L.order().begin(), L.order().end());
  EXPECT_FALSE(L.identity());
  L.reorder(s);
  EXPECT_TRUE(L.identity());
  for (std::size_t k = 0; k < order.size(); ++k) {
    EXPECT_EQ(s.i[k], g.i[order[k]]);
    EXPECT_EQ(s.j[k], g.j[order[k]]);
    EXPECT_EQ(s.rest_length[k], 1.0 + order[k]);
    EXPECT_EQ(L.order()[k], static_cast<Index>(k));
  }
  check_structure({g.n, s.i, s.j}, L);
  check_traversal({g.n, s.i, s.j}, L, 2);
}

TEST(SpringLayout, EdgeCasesAndErrors) {
  SpringLayout empty(10, std::vector<Index>{}, std::vector<Index>{}, 2);
  int calls = 0;
  empty.for_each([&](Index v0, Index v1) { calls += v1 - v0; }, [&](Index) { ++calls; });
  EXPECT_EQ(calls, 10);
  EXPECT_THROW(SpringLayout(3, std::vector<Index>{0}, std::vector<Index>{3}), std::invalid_argument);
  EXPECT_THROW(SpringLayout(3, std::vector<Index>{1}, std::vector<Index>{1}), std::invalid_argument);
  // More parts than vertices.
  const Graph g = random_graph(3, 5, 1);
  SpringLayout L(g.n, g.i, g.j, 16);
  check_structure(g, L);
  check_traversal(g, L, 2);
}

TEST(VertexIncidence, ListsEverySpringTwiceWithSigns) {
  const Graph g = random_graph(200, 1500, 3);
  VertexIncidence inc(g.n, g.i, g.j);
  ASSERT_EQ(inc.num_vertices(), g.n);
  std::vector<int> seen_i(g.i.size(), 0), seen_j(g.i.size(), 0);
  for (Index v = 0; v < g.n; ++v) {
    for (Index e = inc.offsets[v]; e < inc.offsets[v + 1]; ++e) {
      const Index s = inc.spring[e];
      if (e > inc.offsets[v]) {
        EXPECT_LE(inc.spring[e - 1], s);
      }
      if (inc.sign[e] > 0) {
        EXPECT_EQ(g.i[s], v);
        ++seen_i[s];
      } else {
        EXPECT_EQ(g.j[s], v);
        ++seen_j[s];
      }
    }
  }
  for (std::size_t s = 0; s < g.i.size(); ++s) {
    EXPECT_EQ(seen_i[s], 1);
    EXPECT_EQ(seen_j[s], 1);
  }
}
