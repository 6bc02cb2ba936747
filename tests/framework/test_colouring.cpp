// The one greedy colouring routine (loom/colouring.hpp), checked against its definition on
// random items: no two items of one colour share a vertex, each item's colour is the smallest
// not taken by an earlier item sharing a vertex (first fit), and order/start list the items by
// colour, stably. Includes a vertex shared by 200 items (more than 64 colours, so the per-vertex
// bit set must grow).
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "loom/colouring.hpp"

namespace {

using loom::Index;

void check(const std::vector<std::vector<Index>>& items, Index vertices) {
  const Index n = static_cast<Index>(items.size());
  const auto col = loom::greedy_colouring(n, vertices, [&](Index i, auto&& visit) {
    for (Index v : items[i]) visit(v);
  });
  ASSERT_EQ(col.colour.size(), items.size());
  auto share = [&](Index a, Index b) {
    for (Index u : items[a])
      for (Index v : items[b])
        if (u == v) return true;
    return false;
  };
  for (Index i = 0; i < n; ++i) {
    std::set<int> earlier;  // colours of earlier items sharing a vertex with i
    for (Index j = 0; j < i; ++j)
      if (share(i, j)) {
        EXPECT_NE(col.colour[i], col.colour[j]) << i << " and " << j << " share a vertex";
        earlier.insert(col.colour[j]);
      }
    int first_free = 0;
    while (earlier.count(first_free)) ++first_free;
    EXPECT_EQ(col.colour[i], first_free) << "item " << i;
  }
  ASSERT_EQ(col.start.size(), static_cast<std::size_t>(col.count) + 1);
  EXPECT_EQ(col.start.back(), n);
  for (int c = 0; c < col.count; ++c)
    for (Index k = col.start[c]; k < col.start[c + 1]; ++k) {
      EXPECT_EQ(col.colour[col.order[k]], c);
      if (k > col.start[c]) {
        EXPECT_LT(col.order[k - 1], col.order[k]) << "not stable";
      }
    }
}

}  // namespace

TEST(Colouring, RandomTrianglesAndHinges) {
  std::mt19937 rng(7);
  for (int arity : {2, 3, 4}) {
    std::uniform_int_distribution<Index> v(0, 59);
    std::vector<std::vector<Index>> items(300);
    for (auto& it : items)
      for (int a = 0; a < arity; ++a) it.push_back(v(rng));
    check(items, 60);
  }
}

TEST(Colouring, MoreThan64ColoursAtOneVertex) {
  std::vector<std::vector<Index>> items;
  for (Index i = 0; i < 200; ++i) items.push_back({0, i + 1});  // a star: every item shares vertex 0
  check(items, 201);
  const auto col = loom::greedy_colouring(200, 201, [&](Index i, auto&& visit) {
    for (Index v : items[i]) visit(v);
  });
  EXPECT_EQ(col.count, 200);
}
