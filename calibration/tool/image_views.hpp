#pragma once
// Board observations from an image folder or a live camera, with the reason for every
// image that could not be used (unreadable, another size, board not found).
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calibration/lib/board_layout.hpp"
#include "calibration/vision/target_detection.hpp"

namespace arnav::calib::tool {

struct ImageView {
  std::string name;              // file path or "camera frame N"
  BoardObservation observation;  // found == false: see observation.reason
};

// Image files (png, jpg, jpeg, bmp, tif, tiff) of a folder in name order. Throws
// CalibError when the folder cannot be read or holds no images.
std::vector<std::filesystem::path> list_images(const std::filesystem::path& folder);

// Detects the board in every image; image_size is set from the first readable image.
std::vector<ImageView> observe_images(const std::vector<std::filesystem::path>& images, const BoardLayout& layout,
                                      cv::Size& image_size);

// Grabs frames from camera `index` until `views` frames show the board (at most
// max_frames frames, one kept every `every` frames so the views differ).
std::vector<ImageView> observe_camera(int index, const BoardLayout& layout, int views, int max_frames, int every,
                                      cv::Size& image_size);

}  // namespace arnav::calib::tool
