#pragma once
// AprilTag 3 tag families by name, owned RAII-style, and the cell grid of one code word
// (used by the synthetic camera to render real tags from the family data).
#include <opencv2/core.hpp>

#include <string>
#include <string_view>
#include <vector>

struct apriltag_family;

namespace arnav::markers {

// Names accepted by TagFamily (square families of AprilTag 3).
std::vector<std::string> supported_tag_families();

class TagFamily {
 public:
  // Throws std::invalid_argument naming the family and the supported ones.
  explicit TagFamily(std::string_view name);
  ~TagFamily();
  TagFamily(const TagFamily&) = delete;
  TagFamily& operator=(const TagFamily&) = delete;

  const std::string& name() const { return name_; }
  apriltag_family* get() const { return family_; }
  int code_count() const;
  // Cells across the black border square (the detected quad; "tagsize" spans these).
  int width_at_border() const;
  // Cells across the whole bitmap, including the white (or data) ring outside the border.
  int total_width() const;
  // total_width x total_width CV_8UC1, 0 = black cell, 255 = white cell, row 0 at the top
  // of the printed tag. Throws std::out_of_range for an id outside the family.
  cv::Mat cells(int id) const;

 private:
  std::string name_;
  apriltag_family* family_ = nullptr;
  void (*destroy_)(apriltag_family*) = nullptr;
};

}  // namespace arnav::markers
