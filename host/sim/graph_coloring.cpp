#include "host/sim/graph_coloring.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace arnav::host {

template <std::size_t N>
Coloring greedy_vertex_coloring(const std::vector<std::array<int, N>>& elements, int num_vertices) {
  // used[v] is a bit set (in 64-bit words) of the colours already taken around vertex v.
  std::vector<std::vector<std::uint64_t>> used(static_cast<std::size_t>(num_vertices));
  std::vector<int> color(elements.size());
  int num_colors = 0;
  for (std::size_t e = 0; e < elements.size(); ++e) {
    std::vector<std::uint64_t> taken;
    for (int v : elements[e]) {
      if (v < 0 || v >= num_vertices) throw std::invalid_argument("greedy_vertex_coloring: vertex index out of range");
      const auto& u = used[static_cast<std::size_t>(v)];
      if (u.size() > taken.size()) taken.resize(u.size(), 0);
      for (std::size_t w = 0; w < u.size(); ++w) taken[w] |= u[w];
    }
    int c = 0;
    while (c / 64 < static_cast<int>(taken.size()) && (taken[static_cast<std::size_t>(c / 64)] >> (c % 64) & 1u)) ++c;
    color[e] = c;
    num_colors = std::max(num_colors, c + 1);
    for (int v : elements[e]) {
      auto& u = used[static_cast<std::size_t>(v)];
      if (u.size() <= static_cast<std::size_t>(c / 64)) u.resize(static_cast<std::size_t>(c / 64) + 1, 0);
      u[static_cast<std::size_t>(c / 64)] |= std::uint64_t{1} << (c % 64);
    }
  }
  Coloring out;
  out.color_offsets.assign(static_cast<std::size_t>(num_colors) + 1, 0);
  for (int c : color) ++out.color_offsets[static_cast<std::size_t>(c) + 1];
  for (int c = 0; c < num_colors; ++c) out.color_offsets[c + 1] += out.color_offsets[c];
  out.order.resize(elements.size());
  std::vector<int> fill(out.color_offsets.begin(), out.color_offsets.end() - 1);
  for (std::size_t e = 0; e < elements.size(); ++e) out.order[fill[color[e]]++] = static_cast<int>(e);
  return out;
}

template Coloring greedy_vertex_coloring<2>(const std::vector<std::array<int, 2>>&, int);
template Coloring greedy_vertex_coloring<4>(const std::vector<std::array<int, 4>>&, int);

}  // namespace arnav::host
