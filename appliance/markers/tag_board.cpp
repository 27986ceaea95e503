#include "appliance/markers/tag_board.hpp"

#include <cmath>
#include <set>
#include <stdexcept>

namespace arnav::markers {

std::array<Eigen::Vector3d, 4> tag_corners_in_tag(double size_mm) {
  const double h = 0.5 * size_mm;
  return {Eigen::Vector3d(-h, -h, 0), Eigen::Vector3d(h, -h, 0), Eigen::Vector3d(h, h, 0), Eigen::Vector3d(-h, h, 0)};
}

std::array<Eigen::Vector3d, 4> tag_corners_in_board(const BoardTag& tag) {
  auto corners = tag_corners_in_tag(tag.size_mm);
  for (auto& p : corners) p = tag.X_BoardTag * p;
  return corners;
}

TagBoard single_tag_board(std::string name, std::string family, int id, double size_mm) {
  TagBoard board;
  board.name = std::move(name);
  board.family = std::move(family);
  board.tags.push_back(BoardTag{id, size_mm, Eigen::Isometry3d::Identity()});
  return board;
}

Eigen::AlignedBox2d paper_outline(const TagBoard& board, double margin_mm) {
  if (!board.paper_mm.isEmpty()) return board.paper_mm;
  Eigen::AlignedBox2d box;
  for (const auto& tag : board.tags) {
    for (const auto& p : tag_corners_in_board(tag)) box.extend(p.head<2>());
  }
  if (box.isEmpty()) return box;
  return Eigen::AlignedBox2d(box.min() - Eigen::Vector2d::Constant(margin_mm), box.max() + Eigen::Vector2d::Constant(margin_mm));
}

int front_side(const TagBoard& board) {
  if (board.tags.empty()) return 1;
  return board.tags.front().X_BoardTag.linear()(2, 2) > 0 ? 1 : -1;
}

void validate(const TagBoard& board) {
  if (board.tags.empty()) throw std::invalid_argument("board '" + board.name + "' has no tags");
  std::set<int> ids;
  for (const auto& tag : board.tags) {
    if (!(tag.size_mm > 0.0)) {
      throw std::invalid_argument("board '" + board.name + "': tag " + std::to_string(tag.id) + " has size " +
                                  std::to_string(tag.size_mm) + " mm (must be > 0)");
    }
    const Eigen::Matrix3d R = tag.X_BoardTag.linear();
    if (std::abs(std::abs(R(2, 2)) - 1.0) > 1e-9 || std::abs(tag.X_BoardTag.translation().z()) > 1e-9) {
      throw std::invalid_argument("board '" + board.name + "': tag " + std::to_string(tag.id) +
                                  " is not in the board's x-y plane (only planar boards are supported)");
    }
    if ((R(2, 2) > 0) != (board.tags.front().X_BoardTag.linear()(2, 2) > 0)) {
      throw std::invalid_argument("board '" + board.name + "': tag " + std::to_string(tag.id) +
                                  " faces the other side of the board than tag " + std::to_string(board.tags.front().id));
    }
    if (!ids.insert(tag.id).second) {
      throw std::invalid_argument("board '" + board.name + "': tag id " + std::to_string(tag.id) + " appears twice");
    }
  }
}

}  // namespace arnav::markers
