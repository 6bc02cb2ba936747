// The one greedy colouring routine for race-free parallel scatter: items (hinges, triangle
// chunks, ...) that touch vertices get colours so that two items of one colour share no vertex;
// a colour's items can then scatter into per-vertex arrays in parallel, colours one after the
// other. First-fit in item order: item i gets the smallest colour no earlier item on one of its
// vertices has. Built once at set-up (allocates), never in a step.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <vector>

#include "loom/common.hpp"

namespace loom {

struct Colouring {
  std::vector<int> colour;   ///< per item
  int count = 0;             ///< number of colours
  /// Items per colour as offsets: the items of colour c occupy [start[c], start[c + 1]) of the
  /// order sorted by colour (stable within a colour); size count + 1.
  std::vector<Index> start;
  /// The items sorted by colour, stable within a colour.
  std::vector<Index> order;
};

/// `vertices_of(i, visit)` calls visit(v) for every vertex v (0 <= v < vertices) of item i
/// (repeats are harmless).
template <class VerticesOf>
Colouring greedy_colouring(Index items, Index vertices, VerticesOf&& vertices_of) {
  Colouring out;
  out.colour.assign(static_cast<std::size_t>(items), 0);
  std::size_t words = 1;  // colour bits per vertex, 64 per word; grows when needed
  std::vector<std::uint64_t> used(static_cast<std::size_t>(vertices) * words, 0);
  std::vector<std::uint64_t> busy;
  for (Index i = 0; i < items; ++i) {
    busy.assign(words, 0);
    vertices_of(i, [&](Index v) {
      const std::uint64_t* u = &used[static_cast<std::size_t>(v) * words];
      for (std::size_t w = 0; w < words; ++w) busy[w] |= u[w];
    });
    int c = -1;
    for (std::size_t w = 0; w < words && c < 0; ++w)
      if (~busy[w]) c = static_cast<int>(64 * w) + std::countr_zero(~busy[w]);
    if (c < 0) {  // every colour so far is taken here: one more word per vertex
      std::vector<std::uint64_t> wider(static_cast<std::size_t>(vertices) * (words + 1), 0);
      for (Index v = 0; v < vertices; ++v)
        std::copy_n(&used[static_cast<std::size_t>(v) * words], words, &wider[static_cast<std::size_t>(v) * (words + 1)]);
      used.swap(wider);
      c = static_cast<int>(64 * words);
      ++words;
    }
    out.colour[static_cast<std::size_t>(i)] = c;
    out.count = std::max(out.count, c + 1);
    vertices_of(i, [&](Index v) { used[static_cast<std::size_t>(v) * words + c / 64] |= std::uint64_t(1) << (c % 64); });
  }
  out.start.assign(static_cast<std::size_t>(out.count) + 1, 0);
  for (int c : out.colour) ++out.start[static_cast<std::size_t>(c) + 1];
  for (int c = 0; c < out.count; ++c) out.start[c + 1] += out.start[c];
  out.order.resize(static_cast<std::size_t>(items));
  std::vector<Index> fill(out.start.begin(), out.start.end() - 1);
  for (Index i = 0; i < items; ++i) out.order[static_cast<std::size_t>(fill[out.colour[i]]++)] = i;
  return out;
}

}  // namespace loom
