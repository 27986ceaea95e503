#include "host/sim/fem/symmetric_pattern.hpp"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace arnav::host {

SymmetricPattern::SymmetricPattern(int num_vertices, const std::vector<std::vector<int>>& groups) {
  // Vertex adjacency (lower: neighbours >= vertex), then expanded to 3x3 DOF blocks.
  std::vector<std::vector<int>> lower(num_vertices);
  for (int v = 0; v < num_vertices; ++v) lower[v].push_back(v);
  for (const auto& g : groups)
    for (int a : g)
      for (int b : g)
        if (a > b) lower[b].push_back(a);
  std::vector<Eigen::Triplet<double>> entries;
  for (int v = 0; v < num_vertices; ++v) {
    auto& nb = lower[v];
    std::sort(nb.begin(), nb.end());
    nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
    for (int w : nb)
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r)
          if (w > v || r >= c) entries.emplace_back(3 * w + r, 3 * v + c, 0.0);
  }
  matrix_.resize(3 * num_vertices, 3 * num_vertices);
  matrix_.setFromTriplets(entries.begin(), entries.end());
  matrix_.makeCompressed();
  diagonal_.resize(3 * num_vertices);
  for (int d = 0; d < 3 * num_vertices; ++d) diagonal_[d] = index(d, d);
}

int SymmetricPattern::index(int row, int col) const {
  const int* inner = matrix_.innerIndexPtr();
  const int begin = matrix_.outerIndexPtr()[col], end = matrix_.outerIndexPtr()[col + 1];
  const int* it = std::lower_bound(inner + begin, inner + end, row);
  return (it != inner + end && *it == row) ? static_cast<int>(it - inner) : -1;
}

bool SymmetricPattern::covers(const std::vector<int>& vertices) const {
  for (int a : vertices)
    for (int b : vertices)
      if (a >= b && index(3 * a, 3 * b) < 0) return false;
  return true;
}

std::vector<int> SymmetricPattern::block_map(const std::vector<int>& v) const {
  const int n = static_cast<int>(v.size());
  std::vector<int> map;
  map.reserve(9 * n * (n + 1) / 2);
  for (int a = 0; a < n; ++a)
    for (int b = a; b < n; ++b)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          const int row = 3 * v[a] + r, col = 3 * v[b] + c;
          map.push_back(row >= col ? index(row, col) : (v[a] == v[b] ? -1 : index(col, row)));
        }
  return map;
}

SymmetricPattern SymmetricPattern::extended(int num_vertices, const std::vector<std::vector<int>>& groups,
                                           std::vector<int>& remap, const std::vector<std::pair<int, int>>& drop) const {
  const int n_old = static_cast<int>(matrix_.cols()) / 3;
  if (num_vertices < n_old) throw std::invalid_argument("SymmetricPattern::extended: fewer vertices than the pattern has");
  // Vertex pairs (column vertex b, row vertex a >= b) not in this pattern, sorted.
  std::vector<std::pair<int, int>> extra;
  for (const auto& g : groups)
    for (int a : g)
      for (int b : g) {
        if (a < 0 || b < 0 || a >= num_vertices || b >= num_vertices)
          throw std::invalid_argument("SymmetricPattern::extended: vertex index out of range");
        if (a >= b && (a >= n_old || index(3 * a, 3 * b) < 0)) extra.emplace_back(b, a);
      }
  for (int v = n_old; v < num_vertices; ++v) extra.emplace_back(v, v);
  std::sort(extra.begin(), extra.end());
  extra.erase(std::unique(extra.begin(), extra.end()), extra.end());
  const int* outer = matrix_.outerIndexPtr();
  const int* inner = matrix_.innerIndexPtr();
  const long long nnz = matrix_.nonZeros() + 9LL * static_cast<long long>(extra.size());  // upper bound
  std::vector<int> new_outer(3 * static_cast<std::size_t>(num_vertices) + 1, 0), new_inner;
  new_inner.reserve(static_cast<std::size_t>(nnz));
  remap.assign(static_cast<std::size_t>(matrix_.nonZeros()), -1);
  SymmetricPattern out;
  out.diagonal_.resize(3 * static_cast<std::size_t>(num_vertices));
  std::size_t e = 0, d = 0;  // next extra pair, next dropped pair
  enum Kind : char { kNew, kOld, kDropped };
  std::vector<std::pair<int, Kind>> rows;  // row vertices of the column block
  for (int b = 0; b < num_vertices; ++b) {
    // Merge of the old row vertices of column 3b (3 rows per vertex) with the extra ones.
    rows.clear();
    int k = b < n_old ? outer[3 * b] : 0;
    const int k_end = b < n_old ? outer[3 * b + 1] : 0;
    const auto old_row = [&](int w) {
      for (; d < drop.size() && drop[d] < std::make_pair(b, w); ++d) {
      }
      rows.emplace_back(w, d < drop.size() && drop[d] == std::make_pair(b, w) && w != b ? kDropped : kOld);
    };
    for (; e < extra.size() && extra[e].first == b; ++e) {
      for (; k < k_end && inner[k] / 3 < extra[e].second; k += 3) old_row(inner[k] / 3);
      rows.emplace_back(extra[e].second, kNew);
    }
    for (; k < k_end; k += 3) old_row(inner[k] / 3);
    for (int c = 0; c < 3; ++c) {
      const int col = 3 * b + c;
      int old_k = b < n_old ? outer[col] : 0;
      for (const auto& [w, kind] : rows)
        for (int r = (w == b ? c : 0); r < 3; ++r) {
          if (kind == kDropped) {
            remap[static_cast<std::size_t>(old_k++)] = -1;
            continue;
          }
          if (w == b && r == c) out.diagonal_[static_cast<std::size_t>(col)] = static_cast<int>(new_inner.size());
          if (kind == kOld) remap[static_cast<std::size_t>(old_k++)] = static_cast<int>(new_inner.size());
          new_inner.push_back(3 * w + r);
        }
      new_outer[static_cast<std::size_t>(col) + 1] = static_cast<int>(new_inner.size());
    }
  }
  const std::vector<double> zeros(new_inner.size(), 0.0);
  out.matrix_ = Eigen::Map<const SparseMatrixLower>(3 * num_vertices, 3 * num_vertices, static_cast<Eigen::Index>(new_inner.size()),
                                                    new_outer.data(), new_inner.data(), zeros.data());
  out.matrix_.makeCompressed();
  return out;
}

ElementPartition partition_elements(const Eigen::Matrix3Xd& vertices, const std::vector<std::vector<int>>& elements,
                                    int parts) {
  ElementPartition out;
  parts = std::max(1, parts);
  out.parts.resize(parts);
  const int ne = static_cast<int>(elements.size());
  if (parts == 1) {
    for (int e = 0; e < ne; ++e) out.parts[0].push_back(e);
    return out;
  }
  Eigen::Index axis;
  (vertices.rowwise().maxCoeff() - vertices.rowwise().minCoeff()).maxCoeff(&axis);
  std::vector<std::pair<double, int>> key(ne);
  for (int e = 0; e < ne; ++e) {
    double c = 0;
    for (int v : elements[e]) c += vertices(axis, v);
    key[e] = {c / static_cast<double>(elements[e].size()), e};
  }
  std::sort(key.begin(), key.end());
  std::vector<int> part_of(ne);
  for (int k = 0; k < ne; ++k) part_of[key[k].second] = static_cast<int>(static_cast<long long>(k) * parts / ne);
  // Vertex -> the single part touching it, or -2 when several do.
  std::vector<int> owner(vertices.cols(), -1);
  for (int e = 0; e < ne; ++e)
    for (int v : elements[e]) owner[v] = (owner[v] == -1 || owner[v] == part_of[e]) ? part_of[e] : -2;
  for (int e = 0; e < ne; ++e) {
    const bool interior = std::all_of(elements[e].begin(), elements[e].end(), [&](int v) { return owner[v] >= 0; });
    (interior ? out.parts[part_of[e]] : out.shared).push_back(e);
  }
  return out;
}

}  // namespace arnav::host
