#pragma once
// Greedy colouring of elements that share vertices, so that the elements of one colour
// touch disjoint vertices and can be processed in parallel without locks (parallel
// Gauss-Seidel in XPBD).
#include <array>
#include <vector>

namespace arnav::host {

struct Coloring {
  std::vector<int> order;          // element indices sorted by colour
  std::vector<int> color_offsets;  // colour c holds order[color_offsets[c] .. color_offsets[c+1])
  int num_colors() const { return static_cast<int>(color_offsets.size()) - 1; }
};

// Elements are given by their vertex lists (N vertices each, N = 2 for springs, 4 for tets).
template <std::size_t N>
Coloring greedy_vertex_coloring(const std::vector<std::array<int, N>>& elements, int num_vertices);

}  // namespace arnav::host
