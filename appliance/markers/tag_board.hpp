#pragma once
// The geometry of what the camera tracks: one tag or a rigid board of several tags.
// Frames: Tag (origin at the tag centre, x right and y up as the printed tag is seen
// from the front, z out of the paper towards the viewer) and Board (the board's own
// frame; each tag is placed by X_BoardTag). Units: millimetres.
// size_mm is the edge of the black border square (AprilTag's "tagsize"), not the printed
// outer edge (which includes the white ring).
#include <Eigen/Geometry>

#include <array>
#include <string>
#include <vector>

namespace arnav::markers {

struct BoardTag {
  int id = 0;
  double size_mm = 0.0;
  Eigen::Isometry3d X_BoardTag = Eigen::Isometry3d::Identity();
};

struct TagBoard {
  std::string name;              // tool name it is published under, e.g. "liver_marker"
  std::string family = "tag36h11";
  std::vector<BoardTag> tags;
  // Printed paper outline in the board's x-y plane (mm), used by the synthetic camera
  // to draw the white sheet the tags sit on. Empty box: a margin around the tags.
  Eigen::AlignedBox2d paper_mm;
};

// Corner k of a tag in the tag frame, in AprilTag's detection order (counter-clockwise
// in the image as seen from the front): (-h,-h), (h,-h), (h,h), (-h,h), h = size/2.
std::array<Eigen::Vector3d, 4> tag_corners_in_tag(double size_mm);
// The same corners in the board frame.
std::array<Eigen::Vector3d, 4> tag_corners_in_board(const BoardTag& tag);
// A board that holds a single tag at its origin.
TagBoard single_tag_board(std::string name, std::string family, int id, double size_mm);
// Paper outline: paper_mm if set, else the tags' bounding box grown by margin_mm.
Eigen::AlignedBox2d paper_outline(const TagBoard& board, double margin_mm);
// Throws std::invalid_argument naming the board when tags repeat an id, have a size <= 0,
// leave the board's x-y plane, or do not all face the same side.
void validate(const TagBoard& board);
// +1 when the printed tags face the board's +z (a y-up board), -1 when they face -z (a
// board frame with y down the sheet and z into it, as arnav-calib's layouts use).
int front_side(const TagBoard& board);

}  // namespace arnav::markers
