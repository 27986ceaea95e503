#pragma once
// Sparsity pattern of the FEM system matrix (3 DOF per vertex, lower triangle incl. the
// diagonal, compressed columns) and element -> nonzero index maps, so that the per-step
// assembly is a scatter into a fixed value array (no search, no allocation), and an
// element colouring so that the scatter runs in parallel without write conflicts.
#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <vector>

namespace arnav::host {

using SparseMatrixLower = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

class SymmetricPattern {
 public:
  // groups: vertex lists whose pairs couple (tets, beam super-elements, attachments).
  SymmetricPattern(int num_vertices, const std::vector<std::vector<int>>& groups);

  // A zero matrix with the pattern (lower triangle, compressed).
  const SparseMatrixLower& matrix() const { return matrix_; }
  // Index into matrix().valuePtr() of entry (row, col), row >= col; -1 if not in the pattern.
  int index(int row, int col) const;
  // True when every vertex pair of `vertices` is in the pattern.
  bool covers(const std::vector<int>& vertices) const;
  // Block map of an element with vertex list v (n vertices): for each local pair a <= b
  // (row-major over a, then b >= a) 9 indices of the 3x3 block (rows of a, cols of b),
  // entry (r, c) at [9*pair + 3*r + c]; transposed into the lower triangle when v[a] < v[b];
  // -1 for the upper half of diagonal blocks.
  std::vector<int> block_map(const std::vector<int>& vertices) const;
  // Index of the diagonal entry of each DOF.
  const std::vector<int>& diagonal() const { return diagonal_; }

 private:
  SparseMatrixLower matrix_;
  std::vector<int> diagonal_;
};

// Greedy colouring: elements of one colour share no vertex. Returns the element indices
// grouped by colour.
std::vector<std::vector<int>> color_elements(int num_vertices, const std::vector<std::vector<int>>& elements);

}  // namespace arnav::host
