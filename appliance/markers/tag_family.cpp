#include "appliance/markers/tag_family.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include <cstring>
#include <stdexcept>

namespace arnav::markers {
namespace {

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

constexpr FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
};

}  // namespace

std::vector<std::string> supported_tag_families() {
  std::vector<std::string> names;
  for (const auto& f : kFamilies) names.emplace_back(f.name);
  return names;
}

TagFamily::TagFamily(std::string_view name) : name_(name) {
  for (const auto& f : kFamilies) {
    if (name == f.name) {
      family_ = f.create();
      destroy_ = f.destroy;
      return;
    }
  }
  std::string known;
  for (const auto& f : kFamilies) known += std::string(known.empty() ? "" : ", ") + f.name;
  throw std::invalid_argument("unknown AprilTag family '" + std::string(name) + "' (supported: " + known + ")");
}

TagFamily::~TagFamily() {
  if (family_ != nullptr) destroy_(family_);
}

int TagFamily::code_count() const { return static_cast<int>(family_->ncodes); }
int TagFamily::width_at_border() const { return family_->width_at_border; }
int TagFamily::total_width() const { return family_->total_width; }

cv::Mat TagFamily::cells(int id) const {
  if (id < 0 || id >= code_count()) {
    throw std::out_of_range("tag id " + std::to_string(id) + " is outside family " + name_ + " (0.." +
                            std::to_string(code_count() - 1) + ")");
  }
  // apriltag_to_image draws the bit grid from the family's code word and bit layout.
  image_u8_t* im = apriltag_to_image(family_, id);
  cv::Mat out(im->height, im->width, CV_8UC1);
  for (int r = 0; r < im->height; ++r) std::memcpy(out.ptr(r), im->buf + r * im->stride, static_cast<size_t>(im->width));
  image_u8_destroy(im);
  return out;
}

}  // namespace arnav::markers
