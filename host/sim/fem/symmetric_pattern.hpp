#pragma once
// Sparsity pattern of the FEM system matrix (3 DOF per vertex, lower triangle incl. the
// diagonal, compressed columns) and element -> nonzero index maps, so that the per-step
// assembly is a scatter into a fixed value array (no search, no allocation), and an
// element partition so that the scatter runs in parallel without write conflicts.
#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <utility>
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

  // After a cut (CorotationalFem::apply_mesh_change): this pattern grown to num_vertices
  // (>= the current count; the new vertices' DOFs appended) with the pairs of `groups`
  // added and the vertex pairs `drop` ({column vertex b, row vertex a}, a > b, sorted;
  // pairs no element couples any more) removed. remap[k] is the new index of this
  // pattern's entry k (-1: dropped). One pass over the entries (a merge, no search or sort
  // of the old ones); the same layout as a pattern built from the remaining groups at once.
  SymmetricPattern extended(int num_vertices, const std::vector<std::vector<int>>& groups, std::vector<int>& remap,
                            const std::vector<std::pair<int, int>>& drop = {}) const;

 private:
  SymmetricPattern() = default;
  SparseMatrixLower matrix_;
  std::vector<int> diagonal_;
};

// Domain split for parallel assembly with a single synchronisation: elements are cut into
// `parts` slabs along the longest axis (by centroid); elements whose vertices are touched
// by one part only go to that part, the rest (the slab interfaces) to `shared`, which is
// assembled after the parallel region. (A colouring needs a barrier per colour, which on
// a loaded 2-core machine costs more than the assembly itself.)
struct ElementPartition {
  std::vector<std::vector<int>> parts;  // element ids per part, vertex-disjoint across parts
  std::vector<int> shared;              // element ids touching more than one part
};
ElementPartition partition_elements(const Eigen::Matrix3Xd& vertices, const std::vector<std::vector<int>>& elements,
                                    int parts);

}  // namespace arnav::host
